"""Do the bundled trials still give the same outputs, message by message?

Replays the three bundled trials and a short simulated drive through the node graph (and the
recorded trials through ``--offline``) and compares every output bag with the same runs kept
from an earlier tree (``trial compare``: decoded messages, /diagnostics left out). For a
change that must not alter behaviour (a restructuring, a speed-up): record before, check after.

Usage::

    .venv/bin/python bench/bench_identity.py --record DIR     # on the old tree
    .venv/bin/python bench/bench_identity.py --check DIR      # on the new tree
"""
from __future__ import annotations

import argparse
import subprocess
import sys
import tempfile
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
TRIAL = [sys.executable, "-m", "ins_gnss_ros.trial.cli"]

#: name -> (bag, profile, extra replay arguments). The simulated bag is made at run time.
RUNS = {
    "car": ("bags/car_drive_0708", "config/car.yaml", ["--outages", "15:45:40"]),
    "car_offline": ("bags/car_drive_0708", "config/car.yaml", ["--outages", "15:45:40",
                                                               "--offline"]),
    "vessel": ("bags/vessel_waves", "config/sea_demo.yaml", ["--outages", "10:60:60"]),
    "vessel_offline": ("bags/vessel_waves", "config/sea_demo.yaml", ["--offline"]),
    "walk": ("bags/walk_0827", "config/default.yaml", []),
    "walk_tight": ("bags/walk_0827", "config/walk.yaml", ["--satellites", "3:20:40:30"]),
    "sim_car": ("SIM", "config/default.yaml", ["--outages", "10:30:20"]),
}


def run_all(out: Path) -> None:
    out.mkdir(parents=True)
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        sim = tmp / "sim_car"
        subprocess.run(TRIAL + ["simulate", "--scenario", "car", "--duration", "60", "--seed",
                                "3", "--out", str(sim)], check=True, cwd=REPO)
        for name, (bag, config, extra) in RUNS.items():
            bag = str(sim) if bag == "SIM" else bag
            print(f"{name}: replay {bag} --config {config} {' '.join(extra)}", flush=True)
            subprocess.run(TRIAL + ["replay", bag, "--config", config, "--out",
                                    str(out / name), "--no-progress"] + extra,
                           check=True, cwd=REPO, stdout=subprocess.DEVNULL)


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    group = parser.add_mutually_exclusive_group(required=True)
    group.add_argument("--record", type=Path, help="new folder for the reference runs")
    group.add_argument("--check", type=Path, help="folder of reference runs to compare with")
    args = parser.parse_args()
    if args.record:
        run_all(args.record)
        return 0
    from ins_gnss_ros.trial.compare import compare

    with tempfile.TemporaryDirectory() as tmp:
        now = Path(tmp) / "now"
        run_all(now)
        same = True
        for name in RUNS:
            result = compare(args.check / name, now / name)
            print(f"== {name}")
            print("\n".join(result.lines()))
            same &= result.identical
    print("ALL IDENTICAL" if same else "SOME DIFFER")
    return 0 if same else 1


if __name__ == "__main__":
    sys.exit(main())
