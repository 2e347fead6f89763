"""Post-processing (issue 20): ``trial smooth`` on simulated SAR flights (seed 003).

Two measurements, both through the ``trial`` commands users run:

* ``--sar``: a 600 s flight (navigation-grade IMU at 200 Hz, 5 Hz GNSS 0.1-0.3 s late), smoothed
  with the SAR antenna as ``--point``; ``trial evaluate --point --aperture 1 10`` of the smoothed
  run and of the forward filter (``trial replay --offline``), per seed.
* ``--long``: a 2 h flight smoothed; wall and CPU time (real-time factor) and the peak resident
  memory of the ``trial smooth`` process.

Usage::

    .venv/bin/python bench/bench_smooth.py [--sar] [--long] [--seeds 0 1 2] [--work DIR]
"""
from __future__ import annotations

import argparse
import json
import os
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
TRIAL = str(ROOT / ".venv" / "bin" / "trial")
PROFILE = str(ROOT / "config" / "aircraft_sar.yaml")
#: The SAR antenna phase centre relative to the IMU (base_link FLU), m: the sensor block sits
#: next to it (seed 003), here 0.5 m ahead and 1 m below.
APC = ("0.5", "0", "-1")
#: Alignment and convergence in flight, left out of the statistics, s.
SKIP_S = "30"


def trial(*args):
    """Run a trial command; returns its stdout."""
    return subprocess.run([TRIAL, *args], check=True, capture_output=True, text=True).stdout


def simulate(work, duration, seed):
    bag = work / f"aircraft_{duration:g}s_seed{seed}"
    if not bag.exists():
        trial("simulate", "--scenario", "aircraft", "--duration", str(duration), "--seed",
              str(seed), "--gnss-latency", "0.2", "--out", str(bag))
    return bag


def evaluate(out, *extra):
    return json.loads(trial("evaluate", str(out), "--json", "--no-plots", "--skip", SKIP_S,
                            *extra))


def sar(work, seeds):
    print("SAR flight, 600 s, antenna at", ",".join(APC), "(relative error: linear trend "
          "removed per window)")
    print("seed | solution | horizontal RMS m | vertical RMS m | 1 s RMS mm | 10 s RMS mm")
    for seed in seeds:
        bag = simulate(work, 600.0, seed)
        smoothed, forward = work / f"smooth{seed}", work / f"forward{seed}"
        for path in (smoothed, forward):
            shutil.rmtree(path, ignore_errors=True)
        trial("smooth", str(bag), "--config", PROFILE, "--out", str(smoothed), "--point",
              ",".join(APC))
        trial("replay", str(bag), "--config", PROFILE, "--offline", "--out", str(forward))
        for name, out in (("smoothed", smoothed), ("forward", forward)):
            absolute = evaluate(out)
            at_apc = evaluate(out, "--point", *APC, "--aperture", "1", "10")
            rel = {a["window_s"]: a["rms_m"] * 1e3 for a in at_apc["aperture"]}
            print(f"{seed} | {name} | {absolute['horizontal_rms_m']:.3f} | "
                  f"{absolute['vertical_rms_m']:.3f} | {rel[1.0]:.3f} | {rel[10.0]:.2f}")


def long_run(work):
    duration = 7200.0
    tic = time.perf_counter()
    bag = simulate(work, duration, 0)
    print(f"2 h flight simulated in {time.perf_counter() - tic:.0f} s")
    out = work / "smooth_long"
    shutil.rmtree(out, ignore_errors=True)
    tic = time.perf_counter()
    child = subprocess.Popen([TRIAL, "smooth", str(bag), "--config", PROFILE, "--out",
                              str(out)], stdout=subprocess.DEVNULL)
    _, status, usage = os.wait4(child.pid, 0)  # the child's own peak RSS and CPU time
    wall = time.perf_counter() - tic
    if status:
        raise SystemExit(f"trial smooth failed with status {status}")
    cpu = usage.ru_utime + usage.ru_stime
    timing = json.loads((out / "smooth.json").read_text())["timing_s"]
    epochs = json.loads((out / "replay.json").read_text())["messages"]["/nav/odom"]["out"]
    print(f"trial smooth of {duration:g} s at 200 Hz: wall {wall:.0f} s ({duration / wall:.0f}x "
          f"real time), CPU {cpu:.0f} s ({duration / cpu:.0f}x), peak RSS "
          f"{usage.ru_maxrss / 2**20:.2f} GiB; {epochs} filter epochs; phases "
          + ", ".join(f"{k} {v:.0f} s" for k, v in timing.items()))
    print(f"load average at the end: {os.getloadavg()[0]:.1f} (2 cores)")


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--sar", action="store_true")
    parser.add_argument("--long", action="store_true")
    parser.add_argument("--seeds", type=int, nargs="+", default=[0, 1, 2])
    parser.add_argument("--work", default=None, help="folder for the bags and runs (kept)")
    args = parser.parse_args()
    work = Path(args.work or tempfile.mkdtemp(prefix="bench_smooth_"))
    work.mkdir(parents=True, exist_ok=True)
    if args.sar or not args.long:
        sar(work, args.seeds)
    if args.long:
        long_run(work)
    print(f"runs in {work}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
