"""Real-time factor of the trial replay (docs/results/replay.md).

A 600 s car trial with a 200 Hz IMU and 5 Hz GNSS fix + velocity is simulated (not timed), then
replayed as fast as possible

* through the strapdown node alone (``imu/delta`` bag), in-process on the bus;
* through the full graph (``imu/data_raw`` bag: imu_preprocessor -> strapdown <-> ekf),
  in-process, every output serialised into the output bag;
* through the offline filter path (``trial replay --offline``: the navigator, no ROS graph),

and the wall time of each replay, bag reading and writing included, is compared with the 600 s
of the trial. Targets: >= 10x for the graph, >= 100x for the offline path.

    .venv/bin/python bench/bench_replay.py [--duration 600] [--keep DIR] [--offline-only|--graph-only]

``--offline-only`` times the offline path alone (after an untimed offline replay of a 10 s
trial, which loads the numba kernels as the graph replays do before it in the full bench): the
quick A/B of filter-code changes, alternating two source trees on PYTHONPATH.
``--graph-only`` does the same for the full graph (warmed up on a 5 s trial).
"""
from __future__ import annotations

import argparse
import tempfile
import time
from pathlib import Path

STRAPDOWN = """\
strapdown:
  ros__parameters:
    init.latitude_deg: 0.0
"""
FULL_GRAPH = STRAPDOWN + """\
imu_preprocessor:
  ros__parameters:
    rate_hz: 200.0
    nav_rate_hz: 100.0
ekf:
  ros__parameters:
    imu_grade: mems_adis16405
    lever_arm: [0.0, 0.0, 1.5]
"""


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--duration", type=float, default=600.0, help="trial length, s")
    parser.add_argument("--keep", default=None, help="work folder to keep (default: temporary)")
    only = parser.add_mutually_exclusive_group()
    only.add_argument("--offline-only", action="store_true",
                      help="time only the offline filter path (warmed up on a 10 s trial)")
    only.add_argument("--graph-only", action="store_true",
                      help="time only the full graph (warmed up on a 5 s trial)")
    args = parser.parse_args()

    from ins_gnss_ros import io as bagio
    from ins_gnss_ros.io import cdr
    from ins_gnss_ros.trial.offline import replay_offline
    from ins_gnss_ros.trial.replay import replay
    from ins_gnss_ros.trial.simulate import SimOptions, simulate

    work = Path(args.keep or tempfile.mkdtemp(prefix="bench_replay_"))
    work.mkdir(parents=True, exist_ok=True)
    strapdown, full = work / "strapdown.yaml", work / "full.yaml"
    strapdown.write_text(STRAPDOWN)
    full.write_text(FULL_GRAPH)
    t = time.perf_counter()
    # The imu/delta trial (strapdown alone, offline path); --graph-only needs only imu/data_raw.
    bag = None if args.graph_only else simulate("car", args.duration, 1, work / "car",
                                                SimOptions(imu_topic="delta"))
    offline = ("offline filter path (imu_preprocessor and ekf cores)", replay_offline, bag, full,
               "offline", {}, 100.0)

    def full_graph(raw):
        return ("full graph imu_preprocessor+strapdown+ekf, in-process", replay, raw, full,
                "full", {"init_from_truth": True}, 10.0)

    if args.offline_only:
        # Loads the numba kernels (compiled machine code from the cache), untimed.
        replay_offline(simulate("car", 10.0, 1, work / "car_warmup", SimOptions(imu_topic="delta")),
                       full, work / "warmup")
        runs = (offline,)
    elif args.graph_only:
        # Loads the numba kernels and the message modules, untimed.
        replay(simulate("car", 5.0, 1, work / "car_raw_warmup"), full, work / "warmup",
               init_from_truth=True)
        runs = (full_graph(simulate("car", args.duration, 1, work / "car_raw")),)
    else:
        raw = simulate("car", args.duration, 1, work / "car_raw")
        print(f"simulated {args.duration:.0f} s car trial twice (200 Hz imu/delta, imu/data_raw; "
              f"5 Hz GNSS) in {time.perf_counter() - t:.1f} s: "
              f"{sum(1 for _ in bagio.iter_bag(bag))} messages each")
        t = time.perf_counter()
        n = len(bagio.read_bag(bag))
        read = time.perf_counter() - t
        print(f"read + decode the bag alone: {read:.1f} s ({n / read:,.0f} msg/s)")
        t = time.perf_counter()
        rows = bagio.read_raw(bag)
        cdr.decode_columns("ins_gnss_msgs/msg/ImuDelta", [r.data for r in rows if r.topic == "/imu/delta"])
        read = time.perf_counter() - t
        print(f"read undecoded + bulk-decode imu/delta (the offline path's reading): {read:.1f} s "
              f"({len(rows) / read:,.0f} msg/s)")
        runs = (("strapdown node alone, in-process", replay, bag, strapdown, "strapdown",
                 {"init_from_truth": True}, 10.0),
                full_graph(raw),
                offline)
    for name, function, trial, profile, folder, kwargs, target in runs:
        out = work / folder
        t, cpu = time.perf_counter(), time.process_time()
        function(trial, profile, out, **kwargs)
        wall, cpu = time.perf_counter() - t, time.process_time() - cpu
        outputs = sum(1 for _ in bagio.iter_bag(out / "bag"))
        # CPU time too: on the shared machine the wall time depends on the other jobs.
        print(f"{name}: {wall:.1f} s wall ({cpu:.1f} s CPU) for {args.duration:.0f} s of trial = "
              f"{args.duration / wall:.1f}x real time ({args.duration / cpu:.1f}x per CPU "
              f"second; target >= {target:g}x), {outputs} output messages")

if __name__ == "__main__":
    main()
