"""Vessel in waves (smsfusion's ains_ahrs_imu.parquet): the project's navigator against smsfusion.

The OrcaFlex simulation of a station-keeping vessel (roll about +-3 deg, heave about +-1.9 m,
10.24 Hz IMU, GNSS position with 5 cm and compass with 0.1 deg white noise) is run through the
offline navigator (the ekf node's code) with position and compass-heading aiding, and in the SAME
run through smsfusion's own aided INS (``smsfusion.AidedINS``, a multiplicative EKF, fed position
and compass heading as its tests do). Prints roll, pitch, heading and position RMS errors after
the first 30 s, and separately for the first half (on which both filters were tuned) and the
second half.

Usage::

    .venv/bin/python bench/bench_vessel.py [--earth-adapter] [--no-smsfusion]

smsfusion is an optional dependency of this benchmark only
(``.venv/bin/pip install smsfusion==1.9.1``).
"""
from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np
import pandas as pd

from ins_gnss_ros.nav.conventions import quat_ned_frd_to_enu_flu
from ins_gnss_ros.nav.earth import earth_rate_enu, normal_gravity
from ins_gnss_ros.nav import ALIGNING, GnssFix, HeadingFix, Navigator, NavigatorConfig
from ins_gnss_ros.nav.rotations import quat_to_dcm
from ins_gnss_ros.nav.sensor_errors import BlockNoise, FilterNoise
from ins_gnss_ros.trial.evaluate import Trajectory, evaluate
from ins_gnss_ros.trial.vessel import load_vessel, local_ned_to_geodetic

DATA = Path(__file__).resolve().parents[1] / ".." / "shared" / "data" / "vessel_waves" \
    / "ains_ahrs_imu.parquet"

#: The simulation's gravity (standard gravity; test/trial/test_vessel.py checks it), m/s^2.
SIM_GRAVITY = 9.80665

#: Aiding noise as published with the data: GNSS 5 cm per axis, compass 0.1 deg.
GNSS_SIGMA = 0.05
COMPASS_SIGMA = np.radians(0.1)

#: Errors are evaluated after this settling time from the first sample, s.
WARMUP_S = 30.0

#: Noise model of the vessel's IMU, set on the first half of the run only. White noise from the
#: first half of measured minus true IMU output (Allan deviation at 1 s: gyro 3.2e-5 rad/s,
#: accelerometer 4.0-4.5e-4 m/s^2, i.e. 1.04e-4 rad/s and 1.3-1.5e-3 m/s^2 per 10.24 Hz sample);
#: the gyro Allan floor of about 5e-6 rad/s between 30 and 60 s gives the small bias random walk
#: (the first-half grid 0, 1e-12, 1e-11, 1e-10 rad^2/s^3 was best at 1e-12). Turn-on spreads:
#: gyro 1e-4 rad/s, which also covers the Earth rate this non-rotating simulation lacks (see
#: `earth_adapter`); accelerometer 2e-3 m/s^2, a marine MRU-class bias that also lets the
#: vertical bias take up the 0.0125 m/s^2 between WGS-84 normal gravity at the datum and the
#: simulation's standard gravity (5e-4 m/s^2 leaves 1.5 cm of vertical error on the first half).
#: A wide spread (0.02 m/s^2) raises roll and pitch RMS to 0.043 and 0.066 deg: at constant
#: heading a horizontal accelerometer bias and a tilt are indistinguishable, and the spread
#: decides which of the two takes the levelling error.
VESSEL_NOISE = FilterNoise(
    gyro_psd=3.25e-5 ** 2, accel_psd=4.2e-4 ** 2,
    blocks={"bg": BlockNoise(1e-4, psd=1e-12), "ba": BlockNoise(2e-3)})

#: smsfusion's AidedINS noise parameters tuned on the first half (grid over gyro N 3.3e-5 and
#: 5e-5 rad/s/sqrt(Hz), B 5e-6 ... 5e-5 rad/s, tau 50 and 500 s; its accelerometer-bias states
#: made no difference and stay off, its default); its defaults (SMS Motion gen. 2) run as well.
SMS_TUNED = ({"N": 4.2e-4, "B": 5e-4, "tau_cb": 50.0},
             {"N": 3.3e-5, "B": 5e-6, "tau_cb": 50.0})


def vessel_config(noise=VESSEL_NOISE):
    """NavigatorConfig of the vessel: layout 15, no antenna lever arm (the simulation's GNSS
    position is the IMU's), starting uncertainty of a first fix at sea."""
    return NavigatorConfig(noise=noise, layout="15", sigma_pos0=GNSS_SIGMA, sigma_vel0=0.5,
                           sigma_tilt0=np.radians(2.0))


def increments(samples, dt, rule="trapezoid"):
    """Increments over each sample interval (ending at the sample) from point samples of a rate.

    The simulation samples angular rate and specific force at the instants: the integral over
    [t_k-1, t_k] is the trapezoid of the two samples (error ~ dt^3 x second derivative). The
    "rectangle" rule (sample x interval) shifts the input by half a sample (49 ms), which with
    roll rates of 1 deg/s triples the roll error (docs/results/vessel.md).

    Parameters
    ----------
    samples : ndarray, shape (n, 3)
        Rates (rad/s or m/s^2).
    dt : float
        Sample interval, s.
    rule : {"trapezoid", "rectangle"}

    Returns
    -------
    ndarray, shape (n, 3)
        Increments (rad or m/s); the first covers the first interval at the first sample's rate.
    """
    if rule == "rectangle":
        return samples * dt
    previous = np.vstack([samples[:1], samples[:-1]])
    return 0.5 * (previous + samples) * dt


def earth_adapter(vessel):
    """Gyro and accelerometer samples as an IMU on the rotating WGS-84 Earth would give them.

    The simulation is in a non-rotating local frame with standard gravity; the navigator
    mechanises on the WGS-84 Earth at the datum. Adding the Earth rate resolved in body axes by
    the true attitude, C_bn omega_ie^n, and the difference between normal gravity at the datum and
    standard gravity, C_bn (0, 0, g_n - g_0), turns the samples into that IMU's (the transport
    rate, |v|/R < 1e-7 rad/s, is left out). An adapter of the simulation, not a tuning: the
    benchmark's default feeds the raw samples and lets the bias states absorb both (argued and
    measured in docs/results/vessel.md).

    Returns
    -------
    gyro_flu, accel_flu : ndarray, shape (n, 3)
        rad/s, m/s^2, body FLU.
    """
    c_nb = np.stack([quat_to_dcm(q) for q in vessel.truth.q_nb])
    lat, h = vessel.datum[0], vessel.datum[2]
    omega_b = np.einsum("nji,j->ni", c_nb, earth_rate_enu(lat))
    dg_b = np.einsum("nji,j->ni", c_nb, [0.0, 0.0, normal_gravity(lat, h) - SIM_GRAVITY])
    return vessel.gyro_flu + omega_b, vessel.accel_flu + dg_b


def run_navigator(vessel, config, gyro_flu=None, accel_flu=None, rule="trapezoid"):
    """Forward pass of the navigator with a GNSS fix and a compass heading at every sample
    (`rule`: see `increments`).

    Returns
    -------
    NavigatorOutput
    """
    gyro_flu = vessel.gyro_flu if gyro_flu is None else gyro_flu
    accel_flu = vessel.accel_flu if accel_flu is None else accel_flu
    t = vessel.time
    dt = float(np.median(np.diff(t)))
    nav = Navigator(config)
    cov = GNSS_SIGMA ** 2 * np.eye(3)
    g = vessel.gnss
    for k in range(len(t)):
        nav.add_measurement(HeadingFix(t[k], vessel.compass_azimuth[k], COMPASS_SIGMA ** 2))
        nav.add_measurement(GnssFix(t[k], g.lat[k], g.lon[k], g.height[k], cov))
    nav.add_imu(t, increments(gyro_flu, dt, rule), increments(accel_flu, dt, rule))
    nav.flush()
    return nav.output()


def navigator_trajectory(out):
    """Trajectory (with position and attitude covariances) of a navigator forward pass, from the
    first compass heading on (before it the yaw variance is held out of the filter)."""
    k = out.mode != ALIGNING
    pos, att = out.space["pos"], out.space["att"]
    return Trajectory(time=out.t[k], lat=out.lat[k], lon=out.lon[k], height=out.h[k],
                      vel_enu=out.v_enu[k], q_nb=out.q_nb[k], pos_cov_enu=out.P[k][:, pos, pos],
                      att_cov=out.P[k][:, att, att])


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


def run_smsfusion(path, datum, err_acc=None, err_gyro=None):
    """smsfusion's AidedINS over the parquet file (smsfusion_filter, smsfusion_update) with
    position and compass aiding at every sample. The filter state after each update is the
    estimate at that sample.

    Parameters
    ----------
    path : Path
    datum : tuple
        Geodetic origin used to place the output (as `load_vessel`).
    err_acc, err_gyro : dict or None
        smsfusion noise parameters; None for its defaults (SMS Motion gen. 2).

    Returns
    -------
    Trajectory
        Time as in the file, ENU/FLU.
    """
    inputs = smsfusion_inputs(path)
    ains = smsfusion_filter(inputs, err_acc, err_gyro)
    n = len(inputs["time"])
    p_out, q_out = np.empty((n, 3)), np.empty((n, 4))
    for k in range(n):
        smsfusion_update(ains, inputs, k)
        p_out[k] = ains.position()
        q_out[k] = ains.quaternion()
    lat, lon, h = local_ned_to_geodetic(p_out, datum)
    return Trajectory(time=inputs["time"], lat=lat, lon=lon, height=h,
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
            "nees_att": np.nan if errors.nees_att is None else float(np.mean(errors.nees_att[m]))}


def windows(time):
    """Evaluation windows: after the warm-up, first half (tuning), second half."""
    t0, t1 = float(time[0]), float(time[-1])
    mid = 0.5 * (t0 + t1)
    return {"after 30 s": (t0 + WARMUP_S, t1), "first half (tuned)": (t0 + WARMUP_S, mid),
            "second half": (mid, t1)}


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--earth-adapter", action="store_true",
                        help="also run the navigator on samples with Earth rate and WGS-84 "
                             "gravity added (earth_adapter)")
    parser.add_argument("--rectangle", action="store_true",
                        help="also run the navigator on sample x interval increments")
    parser.add_argument("--accel-bias-sigma", type=float, nargs="*", default=[],
                        help="also run the navigator with these accelerometer turn-on bias "
                             "spreads, m/s^2")
    parser.add_argument("--no-smsfusion", action="store_true")
    args = parser.parse_args()
    if not DATA.is_file():
        raise SystemExit(f"data set not found: {DATA}")
    vessel = load_vessel(DATA)
    dt = float(np.median(np.diff(vessel.time)))
    runs = {}
    cpu = time.process_time()
    runs["navigator"] = navigator_trajectory(run_navigator(vessel, vessel_config()))
    print(f"navigator: {len(vessel.time)} IMU samples, {2 * len(vessel.time)} aiding "
          f"measurements, {time.process_time() - cpu:.1f} s CPU")
    if args.earth_adapter:
        runs["navigator + Earth adapter"] = navigator_trajectory(
            run_navigator(vessel, vessel_config(), *earth_adapter(vessel)))
    if args.rectangle:
        runs["navigator, rectangle increments"] = navigator_trajectory(
            run_navigator(vessel, vessel_config(), rule="rectangle"))
    for sigma in args.accel_bias_sigma:
        blocks = {**VESSEL_NOISE.blocks, "ba": BlockNoise(sigma)}
        noise = FilterNoise(VESSEL_NOISE.gyro_psd, VESSEL_NOISE.accel_psd, blocks)
        runs[f"navigator, accel bias spread {sigma:g}"] = navigator_trajectory(
            run_navigator(vessel, vessel_config(noise)))
    if not args.no_smsfusion:
        from importlib.metadata import version
        for name, params in (("defaults", (None, None)), ("tuned", SMS_TUNED)):
            cpu = time.process_time()
            est = run_smsfusion(DATA, vessel.datum, *params)
            print(f"smsfusion {version('smsfusion')} AidedINS ({name}): "
                  f"{time.process_time() - cpu:.1f} s CPU")
            runs[f"smsfusion {name}"] = est
            runs[f"smsfusion {name}, half-sample shift"] = shifted(est, 0.5 * dt)
    print()
    print("Target (issue 5): roll 0.036, pitch 0.020, heading 0.013 deg RMS, position 0.05 m "
          "RMS, after 30 s")
    errors = {name: evaluate(est, vessel.truth).errors for name, est in runs.items()}
    for window, (start, end) in windows(vessel.time).items():
        print(f"\n### {window}: t = {start - vessel.time[0]:.0f} ... {end - vessel.time[0]:.0f} s")
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
