"""Vessel in waves (bags/vessel_waves, smsfusion's ains_ahrs_imu.parquet): the product against
smsfusion.

The OrcaFlex simulation of a station-keeping vessel (roll about +-3 deg, heave about +-1.9 m,
10.24 Hz IMU, GNSS position with 5 cm and compass with 0.1 deg white noise at every sample).

Ours is the product (bench/product_path.py): ``trial replay bags/vessel_waves --config
config/sea_demo.yaml`` through the in-process node graph and with ``--offline``, each also
evaluated by ``trial evaluate OUT --skip 30 --json`` (its line printed). smsfusion's own aided
INS (``smsfusion.AidedINS``, a multiplicative EKF) runs over the parquet file the bag was
imported from, fed position and compass heading at every sample as its tests do. Every
solution is compared with the bag's truth by the evaluation of ``trial evaluate``
(trial/report.load_run, trial/evaluate.evaluate) over the same windows of the truth's time:
after the first 30 s, the first half (on which both filters were tuned) and the second half.

Usage::

    .venv/bin/python bench/bench_vessel.py [--no-smsfusion] [--work DIR]

smsfusion is an optional dependency of this benchmark only
(``.venv/bin/pip install smsfusion==1.9.1``).
"""
from __future__ import annotations

import argparse
import tempfile
from pathlib import Path

import numpy as np
import pandas as pd

import product_path
from ins_gnss_ros.nav.conventions import quat_ned_frd_to_enu_flu
from ins_gnss_ros.trial.evaluate import Trajectory, evaluate
from ins_gnss_ros.trial.report import load_run
from ins_gnss_ros.trial.vessel import local_ned_to_geodetic

DATA = Path(__file__).resolve().parents[1] / ".." / "shared" / "data" / "vessel_waves" \
    / "ains_ahrs_imu.parquet"
BAG = "bags/vessel_waves"
CONFIG = "config/sea_demo.yaml"

#: The simulation's gravity (standard gravity; test/trial/test_vessel.py checks it), m/s^2.
SIM_GRAVITY = 9.80665

#: Aiding noise as published with the data: GNSS 5 cm per axis, compass 0.1 deg.
GNSS_SIGMA = 0.05
COMPASS_SIGMA = np.radians(0.1)

#: Errors are evaluated after this settling time from the first sample, s.
WARMUP_S = 30.0

#: smsfusion's AidedINS noise parameters tuned on the first half (grid over gyro N 3.3e-5 and
#: 5e-5 rad/s/sqrt(Hz), B 5e-6 ... 5e-5 rad/s, tau 50 and 500 s; its accelerometer-bias states
#: made no difference and stay off, its default); its defaults (SMS Motion gen. 2) run as well.
SMS_TUNED = ({"N": 4.2e-4, "B": 5e-4, "tau_cb": 50.0},
             {"N": 3.3e-5, "B": 5e-6, "tau_cb": 50.0})


def smsfusion_inputs(path):
    """The parquet file's IMU, position and compass columns in smsfusion's conventions (NED,
    FRD, deg/s) as arrays, with the sample rate and the aiding variances it is fed."""
    frame = pd.read_parquet(path)
    return {"time": frame.index.to_numpy(float),
            "fs": 1.0 / float(np.median(np.diff(frame.index.to_numpy(float)))),
            "acc": frame[["Ax_meas", "Ay_meas", "Az_meas"]].to_numpy(float),
            "gyro": frame[["Gx_meas", "Gy_meas", "Gz_meas"]].to_numpy(float),
            "pos": frame[["X_meas", "Y_meas", "Z_meas"]].to_numpy(float),
            "head": frame["Gamma_meas"].to_numpy(float),
            "pos_var": GNSS_SIGMA ** 2 * np.ones(3),
            "head_var": float(np.degrees(COMPASS_SIGMA) ** 2)}


def smsfusion_filter(inputs, err_acc=None, err_gyro=None):
    """smsfusion's AidedINS for `inputs` (smsfusion_inputs), cold-started as in its
    documentation (levelling from the first accelerometer sample, heading from the first compass
    reading, position from the first fix); err_acc, err_gyro: its noise parameters, None for
    its defaults (SMS Motion gen. 2)."""
    import smsfusion as sf

    x0 = np.zeros(16)
    x0[0:3] = inputs["pos"][0]
    x0[6:10] = sf.quaternion_from_euler([0.0, 0.0, inputs["head"][0]], degrees=True)
    # Error state [dp, dv, da, dbg] (accelerometer bias ignored, smsfusion's default).
    p0 = np.diag([GNSS_SIGMA ** 2] * 3 + [0.5 ** 2] * 3 + [np.radians(2.0) ** 2] * 3 + [1e-6] * 3)
    kwargs = {} if err_acc is None else {"err_acc": err_acc, "err_gyro": err_gyro}
    return sf.AidedINS(inputs["fs"], x0, p0, g=SIM_GRAVITY, cold_start=True, **kwargs)


def smsfusion_update(ains, inputs, k):
    """smsfusion's update at sample k: the IMU sample with position and compass aiding (the
    published noise)."""
    ains.update(inputs["acc"][k], inputs["gyro"][k], degrees=True, pos=inputs["pos"][k],
                pos_var=inputs["pos_var"], head=inputs["head"][k], head_var=inputs["head_var"],
                head_degrees=True)


def run_smsfusion(path, err_acc=None, err_gyro=None):
    """smsfusion's AidedINS over the parquet file (smsfusion_filter, smsfusion_update) with
    position and compass aiding at every sample. The filter state after each update is the
    estimate at that sample.

    Parameters
    ----------
    path : Path
    err_acc, err_gyro : dict or None
        smsfusion noise parameters; None for its defaults (SMS Motion gen. 2).

    Returns
    -------
    Trajectory
        ENU/FLU, placed at the datum the bag was imported at (trial/vessel.py), time in s after
        the first sample: the time axis of `load_run` (the bag's first truth epoch is the
        file's first sample).
    """
    inputs = smsfusion_inputs(path)
    ains = smsfusion_filter(inputs, err_acc, err_gyro)
    n = len(inputs["time"])
    p_out, q_out = np.empty((n, 3)), np.empty((n, 4))
    for k in range(n):
        smsfusion_update(ains, inputs, k)
        p_out[k] = ains.position()
        q_out[k] = ains.quaternion()
    lat, lon, h = local_ned_to_geodetic(p_out)
    return Trajectory(time=inputs["time"] - inputs["time"][0], lat=lat, lon=lon, height=h,
                      q_nb=quat_ned_frd_to_enu_flu(q_out))


def shifted(trajectory, dt):
    """The trajectory stamped dt earlier: smsfusion's tests compare its output half a sample
    late (their "half-sample shift" for the lag of its Euler integration)."""
    return Trajectory(**{**vars(trajectory), "time": trajectory.time - dt})


def error_rms(errors, start, end):
    """RMS of an `ErrorSeries` over epochs in [start, end]: roll, pitch, heading (deg),
    position east, north, up and 3-D (m), and the mean attitude NEES (NaN without covariance)."""
    m = (errors.time >= start) & (errors.time <= end)

    def rms(x):
        return float(np.sqrt(np.mean(x[m] ** 2)))

    euler = np.degrees(errors.euler)
    pos = errors.pos_enu
    return {"roll": rms(euler[:, 0]), "pitch": rms(euler[:, 1]), "heading": rms(euler[:, 2]),
            "east": rms(pos[:, 0]), "north": rms(pos[:, 1]), "up": rms(pos[:, 2]),
            "pos3d": float(np.sqrt(np.mean(np.sum(pos[m] ** 2, axis=1)))),
            "nees_att": np.nan if errors.nees_att is None
            else float(np.nanmean(errors.nees_att[m]))}


def windows(time):
    """Evaluation windows of a truth time axis: after the warm-up, first half (tuning), second
    half."""
    t0, t1 = float(time[0]), float(time[-1])
    mid = 0.5 * (t0 + t1)
    return {"after 30 s": (t0 + WARMUP_S, t1), "first half (tuned)": (t0 + WARMUP_S, mid),
            "second half": (mid, t1)}


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--no-smsfusion", action="store_true")
    parser.add_argument("--work", type=Path, help="keep the replays here (default: a temporary "
                                                  "folder)")
    args = parser.parse_args()
    runs = {}
    with tempfile.TemporaryDirectory() as tmp:
        work = args.work or Path(tmp)
        work.mkdir(parents=True, exist_ok=True)
        for mode in ("graph", "offline"):
            out = product_path.solve(mode, BAG, CONFIG, work / mode)
            m = product_path.evaluate(out, "--skip", f"{WARMUP_S:g}")
            print(f"{product_path.command_line(mode, BAG, CONFIG)}; trial evaluate OUT --skip "
                  f"{WARMUP_S:g}: roll {m['roll_rms_deg']:.4f}, pitch {m['pitch_rms_deg']:.4f}, "
                  f"heading {m['heading_rms_deg']:.4f} deg, position 3-D "
                  f"{np.hypot(m['horizontal_rms_m'], m['vertical_rms_m']):.4f} m RMS; NEES "
                  f"position {m['nees_position_mean']:.2f}, velocity "
                  f"{m['nees_velocity_mean']:.2f}, attitude {m['nees_attitude_mean']:.2f}")
            run = load_run(out)
            truth = run.truth
            runs[f"ours, {mode}"] = run.estimate, run.published
    if not args.no_smsfusion:
        if not DATA.is_file():
            raise SystemExit(f"smsfusion's input not found: {DATA}")
        from importlib.metadata import version
        dt = float(np.median(np.diff(truth.time)))
        for name, params in (("defaults", (None, None)), ("tuned", SMS_TUNED)):
            est = run_smsfusion(DATA, *params)
            runs[f"smsfusion {version('smsfusion')} {name}"] = est, None
            runs[f"smsfusion {name}, half-sample shift"] = shifted(est, 0.5 * dt), None
    print()
    print("Target (issue 5): roll 0.036, pitch 0.020, heading 0.013 deg RMS, position 0.05 m "
          "RMS, after 30 s")
    errors = {name: evaluate(est, truth, published=published).errors
              for name, (est, published) in runs.items()}
    for window, (start, end) in windows(truth.time).items():
        print(f"\n### {window}: t = {start - truth.time[0]:.0f} ... {end - truth.time[0]:.0f} s")
        print("| filter | roll deg | pitch deg | heading deg | east m | north m | up m | 3-D m "
              "| att NEES |")
        print("|---|---:|---:|---:|---:|---:|---:|---:|---:|")
        for name, err in errors.items():
            r = error_rms(err, start, end)
            print(f"| {name} | {r['roll']:.4f} | {r['pitch']:.4f} | {r['heading']:.4f} | "
                  f"{r['east']:.4f} | {r['north']:.4f} | {r['up']:.4f} | {r['pos3d']:.4f} | "
                  f"{r['nees_att']:.2f} |")


if __name__ == "__main__":
    main()
