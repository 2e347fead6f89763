"""Real car drive (car_drive_0708): causal EKF and RTS smoother drift in simulated GNSS outages.

RTK-fixed positions (and the RTKLIB velocities of the same epochs) are the GNSS input at 4 Hz and
the truth; GNSS is withheld in the windows of an outage protocol (LEN:PERIOD:FIRST, first outage
FIRST s after the first GNSS epoch, none starting within the last 30 s). Prints, per protocol,
the RMS and maximum over outages of the largest horizontal error inside each window, for the
forward filter and for the smoother.

Usage::

    .venv/bin/python bench/bench_car_drive.py [--protocol 15:45:40 --protocol 60:180:40]
        [--half] [--layout 15] [--no-nhc | --nhc-sigma 0.2 0.5]
"""
from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np

from ins_gnss_ros.nav.ekf import ExtraState
from ins_gnss_ros.nav import GnssFix, GnssVelocity, Navigator, NavigatorConfig, \
    point_track
from ins_gnss_ros.nav.sensor_errors import DEG, MICRO_G, BlockNoise, FilterNoise
from ins_gnss_ros.nav.smoother import rts_smooth
from ins_gnss_ros.trial.car_drive import load_car_drive
from ins_gnss_ros.trial.evaluate import Trajectory, evaluate
from ins_gnss_ros.trial.outages import gnss_mask, outage_windows

DATA = Path(__file__).resolve().parents[1] / ".." / "shared" / "data" / "car_drive_0708"

#: Noise model of the drive's MEMS IMU, tuned on the first half of the drive only (--half):
#: white noise of the order of the Allan deviation of the static start at 1 s (gyro ~1e-3
#: rad/s, accel 0.01-0.05 m/s^2: engine and body vibration, far above the data sheet's
#: 0.0038 deg/s/sqrt(Hz) and 70 ug/sqrt(Hz)), gyro doubled by the tuning; bias random walks 10x
#: the source's figures; turn-on bias spreads cover the static-mean gyro output (up to
#: 0.17 deg/s) and a 0.05 m/s^2 accelerometer offset.
CAR_NOISE = FilterNoise(
    gyro_psd=2e-3 ** 2, accel_psd=1.2e-2 ** 2,
    blocks={"bg": BlockNoise(0.3 * DEG, psd=(3.8e-5 * DEG * 10) ** 2),
            "ba": BlockNoise(0.05, psd=(7 * MICRO_G * 10) ** 2),
            "sg": BlockNoise(0.01), "sa": BlockNoise(0.01)})

#: Non-holonomic constraint noise (lateral, vertical), m/s, tuned on the first half. A vertical
#: 0.1 m/s helps 15 s outages on average and hurts 60 s ones badly (docs/results/ekf.md).
NHC_SIGMA = (0.2, 0.5)

#: The RTKLIB velocities of this solution lag its positions: the velocity stamped t matches the
#: position-derived velocity of t - 0.125 s (least squares over the first half of the drive,
#: docs/results/ekf.md), so velocity measurements are applied at that epoch.
VEL_DELAY_S = 0.125

#: Floors of the GNSS standard deviations (RTKLIB's own sigmas are optimistic at 1 cm), m, m/s.
POS_SIGMA_FLOOR = 0.03
VEL_SIGMA_FLOOR = 0.03


def car_config(drive, layout="15", nhc=NHC_SIGMA, td=False):
    """NavigatorConfig of the car drive; `nhc`: the NHC noise (lateral, vertical) m/s, or None."""
    extras = {"td": ExtraState(1, 0.05, 1e-8)} if td else {}
    return NavigatorConfig(noise=CAR_NOISE, layout=layout, lever_arm_b=drive.antenna_lever_arm_flu,
                           extras=extras, nhc_sigma=None if nhc is None else tuple(nhc),
                           sigma_pos0=0.1, sigma_vel0=0.05, sigma_tilt0=np.deg2rad(2.0))


def gnss_measurements(drive, keep):
    """GnssFix and GnssVelocity of the fixed epochs where `keep` is true."""
    tr = drive.truth
    out = []
    for k in np.flatnonzero(keep):
        pc = tr.pos_cov_enu[k] + POS_SIGMA_FLOOR ** 2 * np.eye(3)
        vc = VEL_SIGMA_FLOOR ** 2 * np.eye(3)
        out.append(GnssFix(tr.time[k], tr.lat[k], tr.lon[k], tr.height[k], pc))
        out.append(GnssVelocity(tr.time[k] - VEL_DELAY_S, tr.vel_enu[k], vc))
    return out


def uniform_imu_times(drive):
    """IMU sample times on the sensor's own uniform clock, GNSS time scale.

    The logger's millisecond stamps step by 8 to 11 ms around a steady 10.0026 ms (they never
    stray more than 2 ms from a uniform grid over the 549 s, so no sample is lost): the sensor
    samples uniformly and the stamps carry the logger's jitter. Weighting each rate by its
    jittered interval would add about 1e-4 rad of heading noise per sample in turns; the
    samples are instead spread uniformly between the first and last stamp.
    """
    t = drive.imu_time_gnss
    return np.linspace(t[0], t[-1], len(t))


def run_drive(drive, config, windows, t_end=None):
    """Forward pass over the drive with GNSS withheld in `windows`; returns the output."""
    t = uniform_imu_times(drive)
    stop = len(t) if t_end is None else int(np.searchsorted(t, t_end))
    dt = np.diff(t[:stop], prepend=t[0] - np.median(np.diff(t[:100])))
    keep = gnss_mask(drive.truth.time, windows)
    if t_end is not None:
        keep &= drive.truth.time <= t_end
    nav = Navigator(config)
    for m in gnss_measurements(drive, keep):
        nav.add_measurement(m)
    nav.add_imu(t[:stop], drive.gyro_flu[:stop] * dt[:, None], drive.accel_flu[:stop] * dt[:, None])
    nav.flush()
    return nav.output()


def antenna_trajectory(out, lever, lat=None, lon=None, h=None, q=None):
    """Trajectory of the antenna from a forward (or smoothed) pass."""
    la, lo, hh = point_track(out, lever, lat, lon, h, q)
    return Trajectory(time=out.t, lat=la, lon=lo, height=hh)


def drifts(out, drive, windows, lever, smoothed=None):
    """(RMS, max) over windows of the maximum horizontal error inside each, and per-window maxima."""
    if smoothed is None:
        est = antenna_trajectory(out, lever)
    else:
        est = antenna_trajectory(out, lever, smoothed.lat, smoothed.lon, smoothed.h,
                                 smoothed.q_nb)
    ev = evaluate(est, drive.truth, windows)
    rms, peak = ev.outage_drift()
    return rms, peak, [o.max_horizontal_m for o in ev.outages], ev


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--protocol", action="append", default=None)
    parser.add_argument("--half", action="store_true", help="first half of the drive only")
    parser.add_argument("--layout", default="15")
    parser.add_argument("--no-nhc", action="store_true")
    parser.add_argument("--nhc-sigma", type=float, nargs=2, default=NHC_SIGMA,
                        metavar=("LATERAL", "VERTICAL"), help="NHC noise, m/s")
    parser.add_argument("--td", action="store_true", help="estimate an IMU-GNSS time offset")
    args = parser.parse_args()
    if not DATA.is_dir():
        raise SystemExit(f"data set not found: {DATA}")
    drive = load_car_drive(DATA)
    lever = drive.antenna_lever_arm_flu
    config = car_config(drive, args.layout, None if args.no_nhc else args.nhc_sigma, args.td)
    t0, t1 = drive.truth.time[0], drive.truth.time[-1]
    t_end = 0.5 * (t0 + t1) if args.half else None
    for spec in args.protocol or ["15:45:40", "60:180:40"]:
        windows = outage_windows(spec, t0, t1 if t_end is None else t_end)
        tic = time.perf_counter()
        cpu = time.process_time()
        out = run_drive(drive, config, windows, t_end)
        elapsed = time.perf_counter() - tic
        cpu = time.process_time() - cpu
        n_imu = int(np.sum(uniform_imu_times(drive) <= (t_end or np.inf)))
        rms, peak, per, ev = drifts(out, drive, windows, lever)
        sm = rts_smooth(out)
        srms, speak, sper, _ = drifts(out, drive, windows, lever, sm)
        nan = not np.all(np.isfinite(out.lat))
        rejected = sum(not u.accepted for u in out.updates)
        print(f"protocol {spec}: {len(windows)} outages, layout {args.layout}, "
              f"nhc {config.nhc_sigma}, td {args.td}{', first half' if args.half else ''}")
        print(f"  forward : max-horizontal-error-per-outage RMS {rms:.2f} m, max {peak:.2f} m, "
              f"NaN {nan}")
        print(f"  smoother: RMS {srms:.2f} m, max {speak:.2f} m")
        print("  per outage forward : " + " ".join(f"{x:.2f}" for x in per))
        print("  per outage smoother: " + " ".join(f"{x:.2f}" for x in sper))
        print(f"  aided horizontal RMS {ev.stats['horizontal_m'].rms:.3f} m; "
              f"updates rejected {rejected} of {len(out.updates)}; "
              f"{n_imu} IMU samples in {elapsed:.1f} s wall, {cpu:.1f} s CPU "
              f"({n_imu / cpu:.0f} samples per CPU second)")
        if args.td:
            print(f"  estimated time offset {out.estimates['td'][-1, 0] * 1e3:.1f} ms")


if __name__ == "__main__":
    main()
