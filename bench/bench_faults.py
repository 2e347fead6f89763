"""Integrity of the running graph under every fault class (issue 9): prints the table.

Each case is a fault specification (:mod:`ins_gnss_ros.faults.spec`) replayed in-process
(``trial.replay.replay(..., faults=...)``) through the graph of :data:`PROFILE` over a simulated car
trial with truth. For every published ``nav/fix`` the error against the interpolated
``truth/state`` is compared with the fix's own covariance:

* wrong: the filter's last ``nav/status`` says NAVIGATING and some ENU error component exceeds
  ``K_SIGMA`` standard deviations of the published covariance (a confident wrong answer);
* beyond: the same bound exceeded in any mode (the covariance does not cover the error, even
  if the mode says not to trust the solution);
* lost: seconds of the trial after the first solution with no published solution (gaps longer
  than ``GAP_S``);
* recover: s from the end of the last fault window until the filter reports NAVIGATING again
  (0 when it never left it; ``-`` when it never came back);
* nav share: of the time after the first NAVIGATING status, the share spent NAVIGATING (the
  lowest of a class's cases); med sigma: the median published horizontal sigma, m;

Usage::

    .venv/bin/python bench/bench_faults.py [--duration 90] [--rate 50] [--out /tmp/bench_faults]

The same cases and check serve ``test/faults/test_graph_faults.py`` on a shorter trial.
"""
from __future__ import annotations

import argparse
import json
import tempfile
import time
from functools import partial
from pathlib import Path

import numpy as np
import yaml

from ins_gnss_ros import io as bagio
from ins_gnss_ros.nav.earth import radii

#: A published solution is wrong when an error component exceeds this many sigma.
K_SIGMA = 5.0
#: Output gaps longer than this count as lost solution time, s.
GAP_S = 1.0
#: A solution stamped this close outside the truth's span is compared with the truth's end
#: sample (a car moves centimetres meanwhile); one farther out is wrong by itself, s. An IMU
#: clock that drifted leaves its stamps milliseconds off after the driver re-synchronises it,
#: while the sensor clock's fit follows.
EDGE_S = 0.02
#: FilterStatus / InsState modes.
ALIGNING, NAVIGATING, DEAD_RECKONING = 0, 1, 2

#: Graph of the cases: imu_preprocessor (imu/data_raw at 50 Hz -> imu/delta) -> strapdown <-> ekf
#: on gnss/fix and gnss/vel, plus mag_compass on imu/mag (its heading is not used by the ekf
#: here). The simulated car carries its antenna 1.5 m above the IMU.
PROFILE = {
    "/**": {"ros__parameters": {"use_sim_time": False}},
    "imu_preprocessor": {"ros__parameters": {"rate_hz": 50.0, "nav_rate_hz": 50.0,
                                             "coning_method": "one_sample"}},
    "strapdown": {"ros__parameters": {"history_s": 5.0}},
    "ekf": {"ros__parameters": {"imu_grade": "mems_adis16405", "bias_model": "rw",
                                "layout": "15", "lever_arm": [0.0, 0.0, 1.5],
                                "use_heading": False}},
    "mag_compass": {"ros__parameters": {}},
}

def cases(duration: float) -> dict[str, list[dict]]:
    """Fault class -> list of fault lists (one replay each), windows scaled to ``duration`` s.

    Faults start after the filter is navigating (``a``) and end well before the trial does,
    so recovery can be seen.
    """
    a, d = 0.3 * duration, 0.1 * duration
    imu, fix, vel = "imu/data_raw", "gnss/fix", "gnss/vel"

    def f(kind, topic=None, start=a, duration=d, **params):
        entry = {"kind": kind, "start": start, "duration": duration, **params}
        if topic is not None:
            entry["topic"] = topic
        return entry

    return {
        "drop": [[f("drop", imu, probability=0.3)], [f("drop", "gnss/*", probability=0.5)],
                 [f("drop", imu, duration=0.5)]],
        "delay": [[f("delay", fix, delay_s=0.5)], [f("delay", "gnss/*", delay_s=5.0)]],
        "duplicate": [[f("duplicate", imu)], [f("duplicate", "gnss/*", copies=3)]],
        "reorder": [[f("reorder", imu, window=5)], [f("reorder", "gnss/*", window=4)]],
        "freeze": [[f("freeze", imu, duration=2.0)], [f("freeze", fix)]],
        "step": [[f("step", imu, field="angular_velocity.z", value=1e-2)],
                 [f("step", fix, field="latitude", value=2e-4)],
                 [f("step", vel, field="twist.twist.linear.x", value=2.0)]],
        "ramp": [[f("ramp", imu, field="linear_acceleration.x", rate=1e-2)],
                 [f("ramp", fix, field="altitude", rate=2.0)]],
        "nan": [[f("nan", imu, field="angular_velocity.x", probability=0.1)],
                [f("nan", fix, field="latitude")], [f("nan", vel, field="twist.covariance")]],
        "inf": [[f("inf", imu, field="linear_acceleration.z", probability=0.1)],
                [f("inf", fix, field="position_covariance", negative=True)]],
        "absurd": [[f("absurd", imu, field="angular_velocity.y", probability=0.05)],
                   [f("absurd", fix, field="altitude", value=1e7)],
                   [f("absurd", vel, field="twist.twist.linear.y", value=1e4)]],
        "clock_jump": [[f("clock_jump", "gnss/*", offset_s=1.0)],
                       [f("clock_jump", "gnss/*", offset_s=-1.0)],
                       [f("clock_jump", imu, offset_s=0.5)]],
        # an IMU running 0.2 % off its nominal rate, counted at that rate, until the driver
        # re-synchronises its count to the host clock (the stamps back by the drift)
        "clock_drift": [[f("clock_drift", imu, duration=3 * d, ppm=2000.0)]],
        "loop": [[f("loop", "*", start=0.5 * duration, duration=0.2 * duration)]],
        "gnss_outage": [[f("gnss_outage", duration=3.0)], [f("gnss_outage", duration=3 * d)]],
        "magnetic_disturbance": [[f("magnetic_disturbance", field_t=[2e-5, -1e-5, 0.0])],
                                 [f("magnetic_disturbance", field_t=[0.0, 5e-5, 0.0], ramp_s=d)]],
        "position_jump": [[f("position_jump", north_m=50.0)],
                          [f("position_jump", east_m=20.0, ramp_s=d)],
                          [f("position_jump", up_m=-30.0)]],
    }


def simulate_car(out: Path, duration: float, rate: float, seed: int = 5) -> Path:
    """The car scenario with a 3 s stop at the start (the filter aligns within seconds)."""
    from ins_gnss_ros.sim import scenarios
    from ins_gnss_ros.trial.simulate import SimOptions, simulate

    original = scenarios.SCENARIOS["car"]
    scenarios.SCENARIOS["car"] = partial(original, static=3.0)
    try:
        return simulate("car", duration, seed, out, SimOptions(
            imu_topic="data_raw", imu_rate=rate, mag_rate=10.0, truth_rate=10.0))
    finally:
        scenarios.SCENARIOS["car"] = original


def write_profile(path: Path) -> Path:
    path.write_text(yaml.safe_dump(PROFILE, sort_keys=False))
    return path


def run_case(bag: Path, profile: Path, faults: list[dict], out: Path) -> dict:
    """Replay ``bag`` with ``faults``; returns replay.json."""
    from ins_gnss_ros.trial.replay import replay

    spec = out.with_suffix(".faults.yaml")
    spec.write_text(yaml.safe_dump({"seed": 1, "faults": faults}))
    return replay(bag, profile, out, init_from_truth=True, faults=spec)


def integrity(outputs: Path, bag: Path, fault_end_ns: int | None = None) -> dict:
    """Compare every ``nav/fix`` in the bag ``outputs`` with the truth of ``bag`` (module doc)."""
    truth = bagio.read_bag(bag, ["truth/state"])
    tt = np.array([m.t_ns for m in truth])
    tl = np.array([[m.msg.latitude, m.msg.longitude, m.msg.altitude] for m in truth])
    fixes = bagio.read_bag(outputs, ["nav/fix"])
    status = bagio.read_bag(outputs, ["nav/status"])
    st_t = np.array([bagio.msg_stamp_ns(m.msg) for m in status], np.int64)
    st_mode = np.array([m.msg.mode for m in status])
    st_wall = np.array([m.t_ns for m in status], np.int64)  # as logged, in the order published
    t_fix = np.array([bagio.msg_stamp_ns(m.msg) for m in fixes], np.int64)
    errors, sigmas, modes = [], [], []
    for m, t in zip(fixes, t_fix):
        i = np.searchsorted(st_t, t, "right") - 1
        modes.append(st_mode[i] if i >= 0 else ALIGNING)
        if not tt[0] - EDGE_S * 1e9 <= t <= tt[-1] + EDGE_S * 1e9:
            errors.append(np.full(3, np.inf))  # a stamp outside the trial is wrong by itself
            sigmas.append(np.ones(3))
            continue
        lat, lon, h = (np.interp(t, tt, tl[:, k]) for k in range(3))
        rm, rn = radii(lat)
        errors.append([(np.radians(m.msg.longitude) - lon) * (rn + h) * np.cos(lat),
                       (np.radians(m.msg.latitude) - lat) * (rm + h), m.msg.altitude - h])
        cov = np.reshape(m.msg.position_covariance, (3, 3))
        sigmas.append(np.sqrt(np.clip(np.diag(cov), 0.0, None)))
    errors, sigmas, modes = np.array(errors).reshape(-1, 3), np.array(sigmas).reshape(-1, 3), \
        np.array(modes)
    with np.errstate(invalid="ignore", divide="ignore"):
        ratio = np.max(np.abs(errors) / sigmas, axis=1) if len(errors) else np.zeros(0)
    ratio = np.where(np.isnan(ratio), np.inf, ratio)
    navigating = modes == NAVIGATING
    wrong = navigating & (ratio > K_SIGMA)
    beyond = (modes != ALIGNING) & (ratio > K_SIGMA)
    stamps = np.sort(t_fix)
    gaps = np.diff(np.concatenate([stamps, [tt[-1]]])) * 1e-9 if len(stamps) else [
        (tt[-1] - tt[0]) * 1e-9]
    lost = float(np.sum([g for g in gaps if g > GAP_S]))
    # Share of the time after the first NAVIGATING status spent NAVIGATING (each status holds
    # until the next), and the median published horizontal sigma: a blown-up covariance or a
    # dropped mode must not pass for robustness.
    order = np.argsort(st_t, kind="stable")
    t_sorted, m_sorted = st_t[order], st_mode[order]
    first = np.flatnonzero(m_sorted == NAVIGATING)
    share = None
    if len(first):
        t_span = np.diff(np.concatenate([t_sorted[first[0]:], [tt[-1]]])).astype(float)
        share = float(np.sum(t_span[m_sorted[first[0]:] == NAVIGATING]) / max(t_span.sum(), 1.0))
    sigma_h = np.hypot(sigmas[:, 0], sigmas[:, 1]) if len(sigmas) else np.zeros(0)
    recover = None
    if fault_end_ns is not None:
        after = np.nonzero((st_t >= fault_end_ns) & (st_mode == NAVIGATING))[0]
        if len(after):
            recover = (st_t[after[0]] - fault_end_ns) * 1e-9
    return {"published": int(len(fixes)), "navigating": int(navigating.sum()),
            "wrong": int(wrong.sum()), "beyond": int(beyond.sum()), "lost_s": lost,
            "recover_s": recover,
            "max_ratio_navigating": float(np.max(ratio[navigating], initial=0.0)),
            "navigating_share": share, "sigma_h": sigma_h,
            "modes": {int(k): int(v) for k, v in zip(*np.unique(st_mode, return_counts=True))},
            "t0_ns": int(tt[0]),
            "status_t_ns": st_t, "status_mode": st_mode, "status_order_ns": st_wall,
            "ratio": ratio, "fix_t_ns": t_fix, "fix_modes": modes}


def diagnostics_messages(outputs: Path) -> set[str]:
    """Every counted event key and level message the nodes put on /diagnostics (bag folder)."""
    seen = set()
    for m in bagio.read_bag(outputs, ["diagnostics"]):
        for s in m.msg.status:
            seen.add(s.message)
            seen.update(kv.key for kv in s.values)
    return seen


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--duration", type=float, default=90.0)
    parser.add_argument("--rate", type=float, default=50.0, help="IMU rate, Hz")
    parser.add_argument("--out", default=None)
    parser.add_argument("--classes", nargs="+", default=None, help="only these fault classes")
    args = parser.parse_args()
    root = Path(args.out or tempfile.mkdtemp(prefix="bench_faults_"))
    root.mkdir(parents=True, exist_ok=True)
    bag = simulate_car(root / "car", args.duration, args.rate)
    profile = write_profile(root / "profile.yaml")
    t_bag0 = bagio.read_bag(bag, ["truth/state"])[0].t_ns
    graph = ", ".join(name for name in PROFILE if name != "/**")
    print(f"trial: car {args.duration:g} s, IMU {args.rate:g} Hz, graph {graph}; wrong ="
          f" NAVIGATING and error > {K_SIGMA:g} sigma of the published nav/fix covariance")
    print(f"{'fault class':20s} {'cases':>5s} {'published':>9s} {'navigating':>10s} "
          f"{'wrong':>5s} {'beyond':>6s} {'lost s':>6s} {'recover s':>10s} {'max e/sigma':>11s} "
          f"{'nav share':>9s} {'med sigma m':>11s} {'crash':>5s}  modes")
    rows = {}
    for name, runs in [("none", [[]])] + list(cases(args.duration).items()):
        if args.classes and name not in args.classes:
            continue
        total = {"published": 0, "navigating": 0, "wrong": 0, "beyond": 0, "lost_s": 0.0,
                 "recover": [], "share": [], "sigma_h": [],
                 "max": 0.0, "modes": set(), "crashed": 0}
        t_run = time.perf_counter()
        for i, faults in enumerate(runs):
            out = root / f"{name}_{i}"
            try:
                run_case(bag, profile, faults, out)
            except Exception as err:  # noqa: BLE001 - a node that raises is a result here
                total["crashed"] += 1
                print(f"  {name}[{i}] crashed: {type(err).__name__}: {bagio.first_line(err)}")
                continue
            end = max((f["start"] + f.get("duration", 0.0) for f in faults), default=None)
            r = integrity(out / "bag", bag, None if end is None else t_bag0 + int(end * 1e9))
            for key in ("published", "navigating", "wrong", "beyond"):
                total[key] += r[key]
            total["lost_s"] += r["lost_s"]
            total["recover"].append(r["recover_s"])
            total["max"] = max(total["max"], r["max_ratio_navigating"])
            total["share"].append(0.0 if r["navigating_share"] is None else r["navigating_share"])
            total["sigma_h"].extend(r["sigma_h"].tolist())
            total["modes"].update(r["modes"])
        rec = [x for x in total["recover"] if x is not None]
        rec_text = ("-" if not rec else f"{max(rec):.1f}") + (
            " never" if len(rec) < len(total["recover"]) and name != "none" else "")
        print(f"{name:20s} {len(runs):5d} {total['published']:9d} {total['navigating']:10d} "
              f"{total['wrong']:5d} {total['beyond']:6d} {total['lost_s']:6.1f} {rec_text:>10s}"
              f" {total['max']:11.2f}"
              f" {min(total['share'], default=0.0):9.2f}"
              f" {np.median(total['sigma_h']) if total['sigma_h'] else np.nan:11.2f}"
              f" {total['crashed']:5d}"
              f"  {sorted(total['modes'])}  ({time.perf_counter() - t_run:.0f} s)", flush=True)
        total["sigma_h"] = float(np.median(total["sigma_h"])) if total["sigma_h"] else None
        rows[name] = {k: (sorted(v) if isinstance(v, set) else v) for k, v in total.items()}
    (root / "faults_table.json").write_text(json.dumps(rows, indent=2))
    print(f"runs in {root}")


if __name__ == "__main__":
    main()
