"""Robustness matrix: simulated trials replayed with config/default.yaml alone, on the product path.

Each cell simulates a drive (``trial simulate``: IMU rate and grade, stamp jitter, GNSS rate,
with or without velocity and covariance), replays it through the node graph of
config/default.yaml (``trial replay``, in-process; a replay leaves the sensor-source nodes
out) and judges the outputs against the simulation's truth:

* alignment: time from the start until ``nav/status`` first says NAVIGATING, s;
* horizontal RMS of the corrected ``ins/state`` after alignment, and its ratio to the RMS of the
  raw ``gnss/fix`` about the truth (the issue's targets: <= 0.5, <= 0.8 with fixes only);
* ``nav/fix`` flagged valid (STATUS_FIX) before alignment, or beyond 5 sigma of its own
  horizontal covariance: must be zero;
* the rate of ``nav/fix`` after alignment, valid or not (the ekf's ``output_rate_hz``, 10 Hz);
* the yaw error of ``ins/state`` at the first NAVIGATING ``nav/status`` over that status's yaw
  sigma (att[2]): whether the alignment's heading is as good as it claims (about 1 RMS over
  seeds, ``--seeds``);
* the heading's RMS error and the mean attitude NEES (expect 3) after alignment, as
  ``trial evaluate --skip`` gives them from ``ins/state`` and ``nav/odom``: a heading run round
  or a tilt held with too small a sigma, which the position may hide.

A cell with ``previous_drive`` first replays an earlier drive of the same car (the same
``--mag-iron`` vehicle, the next seed) with the default profile saving the magnetometer's
online calibration (``mag_compass online_calibration.save_file``), and replays the cell with
config/default.yaml plus that file as ``calibration_file``: a robot that kept its calibration.

Usage::

    .venv/bin/python bench/bench_robustness.py            # the full matrix (~15 min)
    .venv/bin/python bench/bench_robustness.py --short    # three cells
    .venv/bin/python bench/bench_robustness.py --cells 9 --seeds 3 4 5 6 7   # over seeds
    (test/trial/test_robustness.py runs some of the cells, 60 s each, in CI)
"""
from __future__ import annotations

import argparse
import json
import subprocess
import sys
import tempfile
from dataclasses import dataclass
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
TRIAL = [sys.executable, "-m", "ins_gnss_ros.trial.cli"]
PROFILE = REPO / "config" / "default.yaml"
@dataclass(frozen=True)
class Cell:
    name: str
    simulate: tuple  # extra `trial simulate` arguments
    previous_drive: float = 0.0  # s of an earlier drive whose magnetometer calibration is kept
    scenario: str = "car"

    @property
    def antenna(self) -> tuple:
        """Where the simulation puts the GNSS antenna (its ``--antenna-lever-arm``), FLU m."""
        from ins_gnss_ros.trial.simulate import SimOptions

        if "--antenna-lever-arm" not in self.simulate:
            return SimOptions.antenna_lever_arm
        i = self.simulate.index("--antenna-lever-arm") + 1
        return tuple(float(x) for x in self.simulate[i:i + 3])


CELLS = [Cell(f"imu {rate:g} Hz, 2 ms jitter", ("--imu-rate", str(rate), "--imu-stamp-jitter",
                                               "0.002")) for rate in (30, 50, 100, 200, 400, 1000)]
CELLS += [Cell(f"grade {grade}", ("--imu-grade", grade)) for grade in
          ("consumer_mems", "mems_adis16405_datasheet", "tactical")]
CELLS += [Cell("fix only 1 Hz", ("--gnss-rate", "1", "--no-gnss-vel")),
          Cell("fix only 5 Hz", ("--no-gnss-vel",)),
          Cell("fix only 5 Hz, no covariance", ("--no-gnss-vel", "--no-gnss-cov")),
          Cell("fix + velocity, no covariance", ("--no-gnss-cov",)),
          Cell("RTK 2 cm", ("--gnss-sigma-h", "0.02", "--gnss-sigma-v", "0.04")),
          Cell("IMU orientation (3 deg), fix only 5 Hz", ("--imu-orientation", "3",
                                                          "--no-gnss-vel")),
          Cell("rolling start, fix + velocity", ("--static", "0")),
          Cell("rolling start, fix only 5 Hz", ("--static", "0", "--no-gnss-vel")),
          Cell("rolling start, IMU orientation, fix only", ("--static", "0", "--no-gnss-vel",
                                                            "--imu-orientation", "3")),
          Cell("ground robot: 30 Hz IMU + orientation, 2.5 Hz fixes, no velocity or covariance",
               ("--imu-rate", "30", "--imu-stamp-jitter", "0.003", "--imu-orientation", "3",
                "--gnss-rate", "2.5", "--no-gnss-vel", "--no-gnss-cov", "--gnss-sigma-h", "1.0",
                "--gnss-sigma-v", "2.0")),
          Cell("magnetometer heading (uncalibrated car), fix only 5 Hz",
               ("--mag-iron", "1", "--no-gnss-vel")),
          Cell("magnetometer heading, stored calibration of an earlier 300 s drive, fix only 5 Hz",
               ("--mag-iron", "1", "--no-gnss-vel"), previous_drive=300.0),
          Cell("fix + velocity of a noisy receiver (0.3 m/s per axis)",
               ("--gnss-sigma-vel", "0.3")),
          Cell("fix + velocity of a noisy receiver (0.3 m/s per axis), no covariance",
               ("--gnss-sigma-vel", "0.3", "--no-gnss-cov")),
          Cell("fix + velocity of a noisy receiver (0.3 m/s per axis) reported as 0.03 m/s",
               ("--gnss-sigma-vel", "0.3", "--gnss-sigma-vel-reported", "0.03")),
          Cell("fix + velocity stamped on arrival, 50-150 ms late",
               ("--gnss-latency", "0.1", "--gnss-stamped-on-arrival")),
          Cell("fix only 5 Hz stamped on arrival, 50-150 ms late",
               ("--gnss-latency", "0.1", "--gnss-stamped-on-arrival", "--no-gnss-vel")),
          Cell("slow robot (0.5-1.5 m/s), 2.5 Hz fixes of 1 m without velocity or covariance, "
               "no heading source",
               ("--imu-grade", "mems_adis16405", "--gnss-rate", "2.5", "--no-gnss-vel",
                "--no-gnss-cov", "--gnss-sigma-h", "1.0", "--gnss-sigma-v", "2.0"),
               scenario="robot"),
          Cell("slow robot with a consumer MEMS unit (ICM-20948 class), 2.5 Hz fixes of 1 m "
               "without velocity or covariance, no heading source",
               ("--gnss-rate", "2.5", "--no-gnss-vel", "--no-gnss-cov", "--gnss-sigma-h", "1.0",
                "--gnss-sigma-v", "2.0"), scenario="robot"),
          # the lowest IMU rate the issue names, at the solution's own rate (10 Hz)
          Cell("imu 10 Hz, 2 ms jitter", ("--imu-rate", "10", "--imu-stamp-jitter", "0.002")),
          Cell("single-point fixes of 2 m whose driver reports 0.1 m (a placeholder), "
               "fix + velocity", ("--gnss-sigma-h", "2.0", "--gnss-sigma-v", "4.0",
                                  "--gnss-sigma-h-reported", "0.1")),
          Cell("rolling start, single-point fixes only of 2 m whose driver reports 0.1 m",
               ("--static", "0", "--no-gnss-vel", "--gnss-sigma-h", "2.0", "--gnss-sigma-v",
                "4.0", "--gnss-sigma-h-reported", "0.1")),
          # an INS that aligns on the move for seconds with a consumer unit's gyro biases
          Cell("rolling start, consumer MEMS unit, single-point fixes only of 2 m whose driver "
               "reports 0.1 m",
               ("--static", "0", "--imu-grade", "consumer_mems", "--no-gnss-vel",
                "--gnss-sigma-h", "2.0", "--gnss-sigma-v", "4.0", "--gnss-sigma-h-reported",
                "0.1")),
          Cell("slow robot started on the move, consumer MEMS unit, 2.5 Hz fixes of 1 m "
               "without velocity or covariance, no heading source",
               ("--static", "0", "--gnss-rate", "2.5", "--no-gnss-vel", "--no-gnss-cov",
                "--gnss-sigma-h", "1.0", "--gnss-sigma-v", "2.0"), scenario="robot"),
          # its heading held only by the course alignment's side slip (test_robustness.py
          # judges that heading; this matrix judges the position)
          Cell("slow robot started on the move, consumer MEMS unit, fix + velocity at 2.5 Hz, "
               "no heading source", ("--static", "0", "--gnss-rate", "2.5"), scenario="robot"),
          # a latency that varies from message to message as much as the receiver's whole
          # latency in cell 24 (72 ms standard deviation)
          Cell("fix + velocity stamped on arrival, 125-375 ms late",
               ("--gnss-latency", "0.25", "--gnss-stamped-on-arrival")),
          # the turn-on gyro biases of a consumer unit, never measured at rest, tilt the INS
          # while it aligns on the move
          Cell("rolling start, consumer MEMS unit, fix + velocity",
               ("--static", "0", "--imu-grade", "consumer_mems")),
          # the levelled x axis pitched with the road: the start's climb is the receiver's
          Cell("rolling start up an 8 % grade, fix + velocity",
               ("--static", "0", "--start-grade", "0.08")),
          # started in flight at 100-200 m/s: the INS standing at the start is far from the
          # course it aligns on
          Cell("aircraft started in flight, fix only 5 Hz", ("--no-gnss-vel",),
               scenario="aircraft"),
          # under way in waves: the IMU still by blocks between the waves
          Cell("vessel under way in waves, fix + velocity", (), scenario="sea"),
          # an installation nobody measured, which default.yaml cannot know: the IMU's position
          # is off by the antenna's offset (the ratio judges that, not the filter), and the
          # published covariance must say so
          Cell("antenna 0.8 m ahead of and 0.4 m left of the IMU, not given, fix + velocity",
               ("--antenna-lever-arm", "0.8", "0.4", "1.5")),
          # a consumer unit's gyro bias, which the turn check's raw increments keep, against
          # courses as clean as 1 Hz fixes make them
          Cell("consumer MEMS unit, fix + velocity 1 Hz", ("--imu-grade", "consumer_mems",
                                                          "--gnss-rate", "1"))]
SHORT = [CELLS[0], CELLS[3], CELLS[10]]


def judge(bag: Path, out: Path, antenna=None) -> dict:
    """The cell's figures from the replay's output bag and the simulated bag's truth (the raw
    fixes' about the truth at ``antenna``, FLU m; default: the simulation's default place)."""
    from ins_gnss_ros import io
    from ins_gnss_ros.nav.earth import ecef_to_enu, geodetic_to_ecef
    from ins_gnss_ros.nav.conventions import wrap_pi
    from ins_gnss_ros.nav.lever_arm import lever_arm_position
    from ins_gnss_ros.nav.rotations import quat_to_euler
    from ins_gnss_ros.trial.simulate import SimOptions
    from ins_gnss_ros.trial.report import evaluate_run

    def stamps(msgs):
        return np.array([io.msg_stamp_ns(m.msg) for m in msgs]) * 1e-9

    truth = io.read_bag(bag, ["/truth/state"])
    t_truth = stamps(truth)
    lat0, lon0, h0 = truth[0].msg.latitude, truth[0].msg.longitude, truth[0].msg.altitude

    def enu(lat, lon, h):
        return ecef_to_enu(geodetic_to_ecef(np.asarray(lat), np.asarray(lon), np.asarray(h)),
                           lat0, lon0, h0)

    true_enu = enu([m.msg.latitude for m in truth], [m.msg.longitude for m in truth],
                   [m.msg.altitude for m in truth])

    def truth_at(t):
        return np.column_stack([np.interp(t, t_truth, true_enu[:, i]) for i in range(3)])

    # raw fixes about the truth at the antenna
    lever = np.asarray(SimOptions.antenna_lever_arm if antenna is None else antenna, float)
    q = np.array([[m.msg.orientation.w, m.msg.orientation.x, m.msg.orientation.y,
                   m.msg.orientation.z] for m in truth])
    fixes = io.read_bag(bag, ["/gnss/fix"])
    t_fix = stamps(fixes)
    lat_a, lon_a, h_a = lever_arm_position(
        np.array([m.msg.latitude for m in truth]), np.array([m.msg.longitude for m in truth]),
        np.array([m.msg.altitude for m in truth]), q, lever)
    ant = enu(lat_a, lon_a, h_a)
    fix_enu = enu(np.radians([m.msg.latitude for m in fixes]),
                  np.radians([m.msg.longitude for m in fixes]), [m.msg.altitude for m in fixes])
    ant_at = np.column_stack([np.interp(t_fix, t_truth, ant[:, i]) for i in range(2)])
    raw_rms = float(np.sqrt(np.mean(np.sum((fix_enu[:, :2] - ant_at) ** 2, axis=1))))

    outputs = io.read_bag(out / "bag", ["/nav/status", "/ins/state", "/nav/fix"])
    status = [m for m in outputs if m.topic == "/nav/status"]
    # NAVIGATING from nav/status (1 Hz) or a valid nav/fix (10 Hz), whichever says it first
    navigating = [io.msg_stamp_ns(m.msg) * 1e-9 for m in status if m.msg.mode == 1] + \
        [io.msg_stamp_ns(m.msg) * 1e-9 for m in outputs
         if m.topic == "/nav/fix" and m.msg.status.status >= 0]
    t_start = t_truth[0]
    t_align = min(navigating, default=np.inf)
    states = [m for m in outputs if m.topic == "/ins/state" and m.msg.correction_sequence > 0]
    t_state = stamps(states)
    after = t_state >= t_align
    rms = np.nan
    if after.any():
        est = enu([m.msg.latitude for m in states], [m.msg.longitude for m in states],
                  [m.msg.altitude for m in states])[after]
        err = est[:, :2] - truth_at(t_state[after])[:, :2]
        rms = float(np.sqrt(np.mean(np.sum(err ** 2, axis=1))))
    solution = [io.msg_stamp_ns(m.msg) * 1e-9 for m in outputs if m.topic == "/nav/fix"]
    fix_rate = sum(t >= t_align for t in solution) / (t_truth[-1] - t_align)
    valid = [m for m in outputs if m.topic == "/nav/fix" and m.msg.status.status >= 0]
    early = sum(io.msg_stamp_ns(m.msg) * 1e-9 < t_align for m in valid)
    beyond = 0
    for m in valid:
        t = io.msg_stamp_ns(m.msg) * 1e-9
        e = enu(np.radians(m.msg.latitude), np.radians(m.msg.longitude), m.msg.altitude)[:2] \
            - truth_at(np.array([t]))[0, :2]
        cov = np.reshape(m.msg.position_covariance, (3, 3))[:2, :2]
        beyond += float(e @ np.linalg.solve(cov, e)) > 25.0  # Mahalanobis distance > 5
    yaw_sigmas = np.nan
    first = next((m.msg for m in status if m.msg.mode == 1 and "att[2]" in m.msg.state_names),
                 None)
    if first is not None and len(states):
        t = io.msg_stamp_ns(first) * 1e-9
        o = states[int(np.argmin(np.abs(t_state - t)))].msg.orientation
        true_yaw = np.interp(t, t_truth, np.unwrap([quat_to_euler(r)[2] for r in q]))
        sigma = first.state_std[list(first.state_names).index("att[2]")]
        yaw_sigmas = float(wrap_pi(quat_to_euler(np.array([o.w, o.x, o.y, o.z]))[2]
                                   - true_yaw)) / sigma
    heading_rms = attitude_nees = np.nan
    if after.any():
        _, metrics = evaluate_run(out, bag, plots=False, skip_s=t_align - t_state[0])
        heading_rms = metrics["heading_rms_deg"]
        attitude_nees = metrics["nees_attitude_mean"]
    return {"align_s": t_align - t_start, "rms_m": rms, "raw_m": raw_rms,
            "ratio": rms / raw_rms, "valid_early": early, "valid_beyond_5_sigma": beyond,
            "valid_fixes": len(valid), "fix_rate_hz": fix_rate, "yaw_error_sigmas": yaw_sigmas,
            "heading_rms_deg": heading_rms, "attitude_nees": attitude_nees}


def _simulate_and_replay(cell: Cell, bag: Path, out: Path, duration: float, seed: int,
                         profile: Path) -> None:
    subprocess.run(TRIAL + ["simulate", "--scenario", cell.scenario, "--duration", str(duration),
                            "--seed", str(seed), *cell.simulate, "--out", str(bag)],
                   check=True, cwd=REPO, capture_output=True)
    subprocess.run(TRIAL + ["replay", str(bag), "--config", str(profile), "--out", str(out)],
                   check=True, cwd=REPO, capture_output=True)


def _with_mag_compass(tmp: Path, name: str, **params) -> Path:
    """config/default.yaml with these mag_compass parameters, as a new file in tmp."""
    import yaml

    profile = yaml.safe_load(PROFILE.read_text())
    profile["mag_compass"]["ros__parameters"].update(params)
    path = tmp / name
    path.write_text(yaml.safe_dump(profile, sort_keys=False))
    return path


def run_cell(cell: Cell, tmp: Path, duration: float, seed: int) -> dict:
    tag = "".join(c if c.isalnum() else "_" for c in cell.name) + f"_{seed}"
    bag, out = tmp / f"{tag}_bag", tmp / f"{tag}_out"
    profile = PROFILE
    if cell.previous_drive:
        stored = tmp / f"{tag}_calibration.yaml"
        _simulate_and_replay(cell, tmp / f"{tag}_previous_bag", tmp / f"{tag}_previous_out",
                             cell.previous_drive, seed + 1,
                             _with_mag_compass(tmp, f"{tag}_save.yaml", **{
                                 "online_calibration.save_file": str(stored)}))
        profile = _with_mag_compass(tmp, f"{tag}_stored.yaml", calibration_file=str(stored))
    _simulate_and_replay(cell, bag, out, duration, seed, profile)
    return judge(bag, out, cell.antenna)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--short", action="store_true", help="three cells only")
    parser.add_argument("--duration", type=float, default=120.0, help="s per trial")
    parser.add_argument("--seed", type=int, default=3)
    parser.add_argument("--seeds", type=int, nargs="+", default=None,
                        help="run each cell on these seeds (instead of --seed)")
    parser.add_argument("--cells", type=int, nargs="*", default=None,
                        help="indices into CELLS (default: all, or the short set)")
    parser.add_argument("--json", action="store_true", help="one JSON object per cell")
    args = parser.parse_args(argv)
    cells = [CELLS[i] for i in args.cells] if args.cells else SHORT if args.short else CELLS
    seeds = args.seeds or [args.seed]
    if args.json:
        with tempfile.TemporaryDirectory() as tmp:
            tmp = Path(tmp)
            for cell in cells:
                for seed in seeds:
                    result = run_cell(cell, tmp, args.duration, seed)
                    print(json.dumps({"cell": cell.name, "seed": seed,
                                      **{k: float(v) for k, v in result.items()}}), flush=True)
        return 0
    print("| cell | seed | aligned after (s) | horizontal RMS after (m) | raw fixes (m) | ratio | "
          "valid before alignment | valid beyond 5 sigma | nav/fix after alignment (Hz) | "
          "yaw error / sigma at alignment | heading RMS after (deg) | attitude NEES after "
          "(expect 3) |")
    print("|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|")
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        for cell in cells:
            for seed in seeds:
                r = run_cell(cell, tmp, args.duration, seed)
                print(f"| {cell.name} | {seed} | {r['align_s']:.1f} | {r['rms_m']:.2f} | "
                      f"{r['raw_m']:.2f} | {r['ratio']:.2f} | {r['valid_early']} | "
                      f"{r['valid_beyond_5_sigma']} of {r['valid_fixes']} | "
                      f"{r['fix_rate_hz']:.1f} | {r['yaw_error_sigmas']:+.2f} | "
                      f"{r['heading_rms_deg']:.2f} | {r['attitude_nees']:.1f} |", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
