"""Per-sample speed of the filter loop on the vessel in waves: ours against smsfusion's AidedINS.

Both filters run over the same 3,686 samples of the vessel in waves (10.24 Hz; the data of
bench/bench_vessel.py and of bags/vessel_waves), in one process, in turn A B A B ... (`--repeats`
times each), and the median samples per second of each and their ratio are printed.

A, smsfusion (1.9.1, an optional dependency of the benchmarks): ``AidedINS.update`` over every
sample of the parquet file with position and compass-heading aiding at EVERY sample
(bench_vessel.smsfusion_update); the columns are arrays before the timing, and nothing is read
back from the filter inside it.

B, ours, as the product runs it: the front end the ekf node and ``trial replay --offline``
share, ``nav/aiding.Aiding`` around a ``nav/navigator.Navigator`` configured by
config/sea_demo.yaml's ``ekf`` section with ``record=True`` (the offline path's per-epoch
record), fed the calls the offline path (trial/offline.py) makes for bags/vessel_waves: an IMU
increment per sample (``imu/data_raw`` through the profile's imu_preprocessor, taken before the
timing) and a gnss/fix and a gnss/heading at the rates the bag has them (here every sample, so
the aiding is that of A), then ``flush``. Outside the timing: reading and decoding the bag,
the message translation (nodes/ekf_inputs.py) and the imu_preprocessor (they give the recorded
calls), and writing the outputs.

Usage::

    .venv/bin/python bench/bench_filter_loop.py [--repeats 5] [--profile FILE]

``--profile FILE`` runs B once more under cProfile and writes its statistics (pstats) to FILE.
"""
from __future__ import annotations

import argparse
import time
from collections import Counter
from pathlib import Path

import numpy as np

from bench_vessel import DATA, smsfusion_filter, smsfusion_inputs, smsfusion_update

REPO = Path(__file__).resolve().parents[1]
BAG = REPO / "bags" / "vessel_waves"
PROFILE = REPO / "config" / "sea_demo.yaml"


class _Calls:
    """Stands in for the Aiding front end while the bag is read: keeps each call (method name
    and arguments) to play it into a real one later."""

    def __init__(self):
        self.calls = []
        self.datum = None

    def __getattr__(self, name):
        def call(*args, **kwargs):
            self.calls.append((name, args, kwargs))
            return True  # taken: what EkfInputs remembers of a fix does not reach the filter
        return call


def recorded_calls(bag, profile_path):
    """The front end's calls of `trial replay --offline` over a bag, and the ekf parameters."""
    from ins_gnss_ros.imu.preprocessor_params import preprocessor_from_params
    from ins_gnss_ros.trial.inputs import input_rows
    from ins_gnss_ros.trial.offline import _Feeder, offline_parameters
    from ins_gnss_ros.trial.profile import load_profile

    pre_p, ekf_p, _ = offline_parameters(load_profile(profile_path))
    calls, events = _Calls(), Counter()
    feed = _Feeder(calls, preprocessor_from_params(pre_p), pre_p, ekf_p, events)
    for row in input_rows(bag):
        feed.row(row, bag)
    return calls.calls, ekf_p


def run_ours(calls, ekf_p):
    """The Aiding front end and a Navigator over the recorded calls; returns the navigator."""
    from ins_gnss_ros.nav import Navigator
    from ins_gnss_ros.nav.aiding import Aiding, AidingPolicy
    from ins_gnss_ros.nav.filter_config import navigator_config

    navigator = Navigator(navigator_config(ekf_p, record=True))
    aiding = Aiding(navigator, AidingPolicy.from_params(ekf_p), lambda text, log=True: None)
    for name, args, kwargs in calls:
        getattr(aiding, name)(*args, **kwargs)
    navigator.flush()
    return navigator


def run_smsfusion(inputs):
    ains = smsfusion_filter(inputs)
    for k in range(len(inputs["time"])):
        smsfusion_update(ains, inputs, k)
    return ains


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=5)
    parser.add_argument("--profile", type=Path, help="write B's cProfile statistics here")
    args = parser.parse_args()
    from importlib.metadata import version

    inputs = smsfusion_inputs(DATA)
    calls, ekf_p = recorded_calls(BAG, PROFILE)
    n_sms = len(inputs["time"])
    n_ours = sum(name == "increment" for name, _, _ in calls)
    aiding_calls = Counter(name for name, _, _ in calls if name != "increment")
    print(f"smsfusion {version('smsfusion')}: {n_sms} samples, position and heading at each; "
          f"ours: {n_ours} increments, aiding calls {dict(aiding_calls)}")
    # Warm-up of both (numba's cache load, first-call set-up), not timed.
    run_smsfusion(inputs)
    epochs = len(run_ours(calls, ekf_p).output().t)
    rates = {"smsfusion": [], "ours": []}
    for _ in range(args.repeats):
        for name, work, n in (("smsfusion", lambda: run_smsfusion(inputs), n_sms),
                              ("ours", lambda: run_ours(calls, ekf_p), n_ours)):
            t0 = time.perf_counter()
            work()
            rates[name].append(n / (time.perf_counter() - t0))
    for name, r in rates.items():
        print(f"{name}: median {np.median(r):,.0f} samples/s (runs: "
              f"{', '.join(f'{x:,.0f}' for x in r)})")
    ratio = np.array(rates["ours"]) / np.array(rates["smsfusion"])
    print(f"ours / smsfusion per sample (pairs, median): {np.median(ratio):.2f} "
          f"(min {ratio.min():.2f}, max {ratio.max():.2f}); ours recorded {epochs} epochs")
    if args.profile:
        import cProfile

        cProfile.runctx("run_ours(calls, ekf_p)", globals(), locals(), str(args.profile))
        print(f"cProfile statistics of one run of ours: {args.profile}")


if __name__ == "__main__":
    main()
