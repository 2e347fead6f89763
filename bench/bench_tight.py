"""Tight coupling with N satellites against pure inertial on the simulated car, through the product.

Per seed, the trial commands (bench/product_path.py), nothing of the bench's own:

    trial simulate --scenario car --antennas 1 --imu-rate 100 --gnss-rate 1 --duration D
        --seed N --out BAG
    trial replay BAG --config TIGHT --satellites N:LEN:100000:OPEN --out OUT   (each N)
    trial replay BAG --config TIGHT --outages LEN:100000:OPEN --out OUT        (pure INS)
    trial evaluate OUT --json

``trial simulate --antennas 1``: the car (30 s standstill, town blocks, circles and
figure-eights), ADIS16405-class MEMS IMU, and what the gnss_simulator node publishes for one
antenna 1.5 m above the IMU: raw GPS L1 C/A + Galileo E1 code and Doppler on real broadcast
orbits (multipath, TCXO receiver clock, Klobuchar and Saastamoinen delays), ephemerides, and
its own single-point fix and velocity. ``--satellites N:...``: in one window of LEN s from OPEN
s only the N highest satellites stay in gnss/observations and gnss/fix / gnss/vel are withheld
(N larger than the sky: every satellite stays, the fix goes); ``--outages``: nothing at all.

TIGHT is config/sim_car_wheel.yaml (the simulated car's IMU grade and antenna) with the ekf
tightly coupled, written into the work folder: layout 24 (receiver clock states), ``coupling:
tight`` (it aligns on gnss/fix + gnss/vel, then takes pseudoranges and Dopplers only), the
simulator's noise as ``tight.code_sigma_m`` (0.3, 0.32: its code noise with the multipath
folded in) and ``tight.doppler_sigma_hz`` (0.02, 0.02), and the broadcast ionosphere of the
stored ephemeris set the simulator flies (``tight.klobuchar``: gnss/ephemeris does not carry
it). The profile learns the non-holonomic constraint as every car profile does
(``nonholonomic.learn``); ``--no-constraint`` switches that off, so that GNSS alone holds the
solution. ``--independent`` simulates with ``trial simulate --broadcast-residuals``: the
simulated ionosphere, troposphere, orbits and clocks differ from the broadcast models the
receiver side corrects with (gnss/broadcast_residuals.py: Klobuchar removes half the
ionosphere, 5 cm zenith troposphere, 1 m SISRE per satellite); the profile does not know them.

Printed per seed and N: the largest horizontal error of base_link inside the window and at its
end (trial evaluate's outage figures), and pure INS over tight for the largest error.

Usage::

    .venv/bin/python bench/bench_tight.py [--seeds 3] [--sats 99 6 4 3 2] [--open 180]
        [--window 300] [--no-constraint] [--independent] [--work DIR]
"""
from __future__ import annotations

import argparse
import tempfile
from pathlib import Path

import yaml

import product_path

BASE_PROFILE = product_path.REPO / "config" / "sim_car_wheel.yaml"
#: Longer than any trial: one window per run.
PERIOD_S = 100000


def tight_profile(path: Path, constraint: bool) -> Path:
    """BASE_PROFILE with the tightly coupled ekf (see the module docstring), written to path."""
    from ins_gnss_ros.gnss import ephemeris_data

    alpha, beta = ephemeris_data.load().klobuchar
    profile = yaml.safe_load(BASE_PROFILE.read_text())
    profile["ekf"]["ros__parameters"].update({
        "layout": "24", "coupling": "tight", "tight.code_sigma_m": [0.3, 0.32],
        "tight.doppler_sigma_hz": [0.02, 0.02],
        "tight.klobuchar": [float(x) for x in (*alpha, *beta)],
        "nonholonomic.learn": constraint})
    path.write_text(yaml.safe_dump(profile, sort_keys=False))
    return path


def window_errors(out) -> tuple[float, float]:
    """(largest, end) horizontal error inside the run's one window, m."""
    window = product_path.evaluate(out)["outages"][0]
    return window["max_horizontal_m"], window["end_horizontal_m"]


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=int, default=3, help="trials (scenario seeds 1..N)")
    parser.add_argument("--sats", type=int, nargs="+", default=[99, 6, 4, 3, 2],
                        help="satellites kept in the window (more than in view: all)")
    parser.add_argument("--open", type=float, default=180.0, help="open sky before, s")
    parser.add_argument("--window", type=float, default=300.0, help="window length, s")
    parser.add_argument("--no-constraint", action="store_true",
                        help="nonholonomic.learn false: GNSS alone holds the solution")
    parser.add_argument("--independent", action="store_true",
                        help="simulated truth apart from the broadcast models by real residuals")
    parser.add_argument("--work", type=Path, help="keep the bags and solutions here (default: "
                                                  "a temporary folder)")
    args = parser.parse_args()
    window = f"{args.window:g}:{PERIOD_S}:{args.open:g}"
    with tempfile.TemporaryDirectory() as tmp:
        work = args.work or Path(tmp)
        work.mkdir(parents=True, exist_ok=True)
        profile = tight_profile(work / "tight.yaml", not args.no_constraint)
        print(f"window {window} (LEN:PERIOD:FIRST s), profile {BASE_PROFILE.name} tightly "
              f"coupled, learned non-holonomic constraint "
              f"{'off' if args.no_constraint else 'on'}, broadcast residuals "
              f"{'on' if args.independent else 'off'}; horizontal error in the window, "
              "largest / at its end (m)")
        print("| seed | satellites | tight | pure INS | INS / tight (largest) |")
        print("|---:|---:|---:|---:|---:|")
        ratios = {}
        for seed in range(1, args.seeds + 1):
            bag = work / f"car_seed{seed}{'_independent' if args.independent else ''}"
            if not bag.exists():
                product_path.trial("simulate", "--scenario", "car", "--antennas", 1,
                                   "--imu-rate", 100, "--gnss-rate", 1, "--duration",
                                   args.open + args.window, "--seed", seed, "--out", bag,
                                   *(("--broadcast-residuals",) if args.independent else ()))
            ins = window_errors(product_path.solve("graph", bag, profile, work / f"ins{seed}",
                                                   "--outages", window))
            for n in args.sats:
                tight = window_errors(product_path.solve(
                    "graph", bag, profile, work / f"sats{n}_{seed}", "--satellites",
                    f"{n}:{window}"))
                ratios.setdefault(n, []).append(ins[0] / tight[0])
                print(f"| {seed} | {n} | {tight[0]:.2f} / {tight[1]:.2f} | "
                      f"{ins[0]:.2f} / {ins[1]:.2f} | {ratios[n][-1]:.1f}x |", flush=True)
    print("\nworst seed, pure INS / tight on the largest error: " + ", ".join(
        f"{n} satellites {min(r):.1f}x" for n, r in ratios.items()))


if __name__ == "__main__":
    main()
