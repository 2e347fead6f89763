"""Real car drive (bags/car_drive_0708): the product's drift in GNSS outages, forward and smoothed.

Per outage protocol (LEN:PERIOD:FIRST s, ``trial replay --outages``), the drive is solved three
ways with config/car.yaml, each by its trial command (bench/product_path.py):

* graph: ``trial replay bags/car_drive_0708 --config config/car.yaml --outages P`` (the
  in-process node graph imu_preprocessor -> strapdown <-> ekf);
* offline: the same with ``--offline`` (the imu_preprocessor and ekf cores without the graph);
* smooth: ``trial smooth bags/car_drive_0708 --config config/car.yaml --outages P`` (the
  offline forward pass and the RTS smoother);

and evaluated by ``trial evaluate OUT --truth-point 0 0.05 0 --truth-velocity-delay 0.125
--json`` (the RTK truth is the antenna's, 5 cm from base_link, and its velocities lag 0.125 s).
Printed per protocol and solution: the RMS and maximum over the outages of the largest
horizontal error inside each, each outage's, the horizontal RMS and the NEES of position and
velocity.

Usage::

    .venv/bin/python bench/bench_car_drive.py [--protocol 15:45:40 --protocol 60:180:40]
        [--modes graph offline smooth] [--work DIR]
"""
from __future__ import annotations

import argparse
import tempfile
from pathlib import Path

import product_path

BAG = "bags/car_drive_0708"
CONFIG = "config/car.yaml"
#: Where and when the RTK truth refers to (bags/README.md): the antenna, velocities 0.125 s late.
TRUTH = ("--truth-point", "0", "0.05", "0", "--truth-velocity-delay", "0.125")


def number(value):
    """A metric of trial evaluate --json: None (not computable) as NaN."""
    return float("nan") if value is None else value


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--protocol", action="append", default=None,
                        help="outage protocol LEN:PERIOD[:FIRST] s (default 15:45:40 and "
                             "60:180:40)")
    parser.add_argument("--modes", nargs="+", choices=sorted(product_path.MODES),
                        default=["graph", "offline", "smooth"])
    parser.add_argument("--work", type=Path, help="keep the solutions here (default: a "
                                                  "temporary folder)")
    args = parser.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        work = args.work or Path(tmp)
        work.mkdir(parents=True, exist_ok=True)
        for spec in args.protocol or ["15:45:40", "60:180:40"]:
            print(f"\nprotocol {spec}; evaluated by trial evaluate OUT {' '.join(TRUTH)}")
            print("| solution | outages | per-outage max horizontal RMS / max (m) | per outage (m) "
                  "| horizontal RMS (m) | NEES pos / vel |")
            print("|---|---:|---:|---|---:|---:|")
            for mode in args.modes:
                out = product_path.solve(mode, BAG, CONFIG,
                                         work / f"{mode}_{spec.replace(':', '_')}",
                                         "--outages", spec)
                m = product_path.evaluate(out, *TRUTH)
                per = " ".join(f"{o['max_horizontal_m']:.2f}" for o in m["outages"])
                print(f"| {mode} | {len(m['outages'])} | {m['outage_drift_rms_m']:.3f} / "
                      f"{m['outage_drift_max_m']:.3f} | {per} | {m['horizontal_rms_m']:.3f} | "
                      f"{number(m['nees_position_mean']):.2f} / "
                      f"{number(m['nees_velocity_mean']):.2f} |",
                      flush=True)
            print("commands: " + "; ".join(
                product_path.command_line(mode, BAG, CONFIG, "--outages", spec)
                for mode in args.modes))


if __name__ == "__main__":
    main()
