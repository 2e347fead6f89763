"""Simulated car: the product's NEES over Monte Carlo runs (a consistent filter gives 3).

Per seed, the trial commands (bench/product_path.py):

    trial simulate --scenario car --duration D --seed N --out BAG
    trial replay BAG --config config/sim_car_wheel.yaml [--offline] --out OUT
    trial evaluate OUT --skip S --json

``trial simulate``'s car: 30 s standstill, then town blocks, circles and figure-eights; its
default sensors (ADIS16405-class MEMS IMU at 200 Hz with turn-on, Gauss-Markov, scale,
non-orthogonality and g-sensitivity errors; GNSS fix 0.5 m horizontal / 1 m vertical and
velocity 0.05 m/s at 5 Hz, antenna 1.5 m above the IMU). config/sim_car_wheel.yaml is the
profile of that car (its IMU grade and antenna lever arm); its wheel odometry has no input here
(the bag has no wheel/odom). Printed: per seed and over the seeds (mean, min-max) the mean NEES
of position, velocity and attitude over the epochs after the first S s of the solution, and
the horizontal RMS.

Usage::

    .venv/bin/python bench/bench_nees.py [--seeds 20] [--first-seed 1] [--duration 120]
        [--skip 40] [--mode offline|graph] [--work DIR]
"""
from __future__ import annotations

import argparse
import tempfile
from pathlib import Path

import numpy as np

import product_path

CONFIG = "config/sim_car_wheel.yaml"
NEES = ("nees_position_mean", "nees_velocity_mean", "nees_attitude_mean")


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=int, default=20, help="Monte Carlo runs")
    parser.add_argument("--first-seed", type=int, default=1)
    parser.add_argument("--duration", type=float, default=120.0, help="s per run")
    parser.add_argument("--skip", type=float, default=40.0,
                        help="leave the first S s of each solution out (alignment)")
    parser.add_argument("--mode", choices=("offline", "graph"), default="offline")
    parser.add_argument("--work", type=Path, help="keep the bags and solutions here (default: "
                                                  "a temporary folder)")
    args = parser.parse_args()
    print(f"{args.seeds} runs of {args.duration:g} s, {args.mode}, "
          f"{product_path.command_line(args.mode, 'BAG', CONFIG)}; "
          f"trial evaluate OUT --skip {args.skip:g}")
    print("| seed | NEES position | velocity | attitude | horizontal RMS (m) |")
    print("|---:|---:|---:|---:|---:|")
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        work = args.work or Path(tmp)
        work.mkdir(parents=True, exist_ok=True)
        for seed in range(args.first_seed, args.first_seed + args.seeds):
            bag = work / f"car_{args.duration:g}s_seed{seed}"
            if not bag.exists():
                product_path.trial("simulate", "--scenario", "car", "--duration", args.duration,
                                   "--seed", seed, "--out", bag)
            out = product_path.solve(args.mode, bag, CONFIG, work / f"{args.mode}_seed{seed}")
            m = product_path.evaluate(out, "--skip", args.skip)
            rows.append([m[key] for key in NEES])
            print(f"| {seed} | " + " | ".join(f"{x:.2f}" for x in rows[-1])
                  + f" | {m['horizontal_rms_m']:.3f} |", flush=True)
    values = np.array(rows, dtype=float)
    print("| mean | " + " | ".join(f"**{x:.2f}**" for x in values.mean(axis=0)) + " | |")
    print("| min-max | " + " | ".join(f"{lo:.2f}-{hi:.2f}" for lo, hi in
                                       zip(values.min(axis=0), values.max(axis=0))) + " | |")


if __name__ == "__main__":
    main()
