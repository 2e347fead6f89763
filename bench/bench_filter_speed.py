"""The filter core (`Navigator`) on the simulated car: throughput, and tight coupling with
synthetic satellites.

Both drive the `Navigator` with this bench's own measurements (no imu_preprocessor, no Aiding
front end, no bag): figures of the filter core, not of the product. The product's offline path
is timed by bench/bench_replay.py (``trial replay --offline``), its accuracy and NEES by
bench/bench_car_drive.py, bench_vessel.py and bench_nees.py.

Speed: IMU samples per CPU second of the navigator (compensation, mechanisation, covariance
propagation, GNSS position + velocity updates at 4 Hz, output records) on the simulated car of
seed 004 Lab 1 (sim/scenarios.car, ADIS16405-class MEMS from sim/imu_sim).

Tight coupling (--tight): loose GNSS for the first 60 s, then 60 s with pseudoranges and range
rates of only 3 or 2 satellites (tightly coupled, receiver clock states), against no GNSS at all
(pure inertial with the same start). The satellites are fixed synthetic ones 20,000 km away with
GNSS-like velocities (no ephemeris needed); the receiver clock runs 1 km off with a 0.5 m/s
drift; noise 1 m and 0.05 m/s.

Usage::

    .venv/bin/python bench/bench_filter_speed.py [--rate 200] [--duration 300] [--tight]
"""
from __future__ import annotations

import argparse
import time

import numpy as np

from ins_gnss_ros.nav.earth import ecef_to_enu_matrix, geodetic_to_ecef, radii
from ins_gnss_ros.nav.error_model import nav_error
from ins_gnss_ros.nav.lever_arm import lever_arm_position, lever_arm_velocity
from ins_gnss_ros.nav import GnssFix, GnssVelocity, Navigator, NavigatorConfig, \
    SatelliteRanges
from ins_gnss_ros.nav.sensor_errors import MEMS_ADIS16405, filter_noise
from ins_gnss_ros.nav.strapdown import NavState
from ins_gnss_ros.sim.imu_sim import ImuSpec, simulate_imu
from ins_gnss_ros.sim.scenarios import car

LEVER = np.array([0.5, 0.3, 1.2])
SIGMA_P, SIGMA_V = 0.3, 0.03


def gnss(traj, rng, rate_hz=4.0):
    """GNSS antenna fixes and velocities from the truth, with white noise."""
    step = int(round(1.0 / (traj.dt * rate_hz)))
    out = []
    for k in range(step, len(traj.t), step):
        lat, lon, h = lever_arm_position(traj.lat[k], traj.lon[k], traj.h[k], traj.q_nb[k], LEVER)
        rm, rn = radii(lat)
        e = SIGMA_P * rng.standard_normal(3)
        v = lever_arm_velocity(traj.v_enu[k], traj.q_nb[k], traj.omega_ib_b[k], LEVER, lat)
        out.append(GnssFix(traj.t[k], lat + e[1] / (rm + h), lon + e[0] / ((rn + h) * np.cos(lat)),
                           h + e[2], SIGMA_P ** 2 * np.eye(3)))
        out.append(GnssVelocity(traj.t[k], v + SIGMA_V * rng.standard_normal(3),
                                SIGMA_V ** 2 * np.eye(3)))
    return out


def config():
    return NavigatorConfig(noise=filter_noise(MEMS_ADIS16405, "rw"), layout="21",
                           lever_arm_b=LEVER, sigma_pos0=1.0, sigma_vel0=0.1,
                           sigma_tilt0=np.deg2rad(1.0), align_speed=1.0)


def run(imu, measurements, cfg):
    nav = Navigator(cfg)
    for m in measurements:
        nav.add_measurement(m)
    nav.add_imu(imu.t, imu.dtheta, imu.dv)
    nav.flush()
    return nav.output()


def satellite_ranges(traj, rng, n_sats, t_start, rate_hz=4.0):
    """SatelliteRanges of n_sats synthetic satellites from t_start on (see the module docstring)."""
    r0 = geodetic_to_ecef(traj.lat[0], traj.lon[0], traj.h[0])
    c_en = ecef_to_enu_matrix(traj.lat[0], traj.lon[0])
    dirs = np.array([[0.3, 0.4, 0.87], [-0.7, 0.1, 0.7], [0.1, -0.8, 0.6]])[:n_sats]
    dirs /= np.linalg.norm(dirs, axis=1)[:, None]
    sat = r0 + 2.0e7 * dirs @ c_en
    sat_vel = np.array([[2500.0, -800.0, 1000.0], [-1500.0, 2000.0, 300.0],
                        [600.0, 1800.0, -2200.0]])[:n_sats]
    step = int(round(1.0 / (traj.dt * rate_hz)))
    out = []
    for k in range(step, len(traj.t), step):
        t = traj.t[k]
        if t < t_start:
            continue
        lat, lon, h = lever_arm_position(traj.lat[k], traj.lon[k], traj.h[k], traj.q_nb[k], LEVER)
        r = geodetic_to_ecef(lat, lon, h)
        v = ecef_to_enu_matrix(lat, lon).T @ lever_arm_velocity(
            traj.v_enu[k], traj.q_nb[k], traj.omega_ib_b[k], LEVER, lat)
        pos = sat + sat_vel * t
        d = pos - r
        rho = np.linalg.norm(d, axis=1)
        u = d / rho[:, None]
        clock, drift = 1000.0 + 0.5 * t, 0.5
        out.append(SatelliteRanges(
            t, pos, np.broadcast_to(sat_vel, pos.shape), np.zeros(n_sats), np.zeros(n_sats),
            rho + clock + rng.standard_normal(n_sats), 1.0,
            np.einsum("ij,ij->i", u, sat_vel - v) + drift + 0.05 * rng.standard_normal(n_sats),
            0.05 ** 2))
    return out


def tight_coupling(rate):
    """Horizontal error after 60 s with 3, 2 and 0 satellites (after 60 s of loose GNSS)."""
    traj = car(duration=120.0, seed=13, rate=rate, static=20.0).trajectory
    imu = simulate_imu(traj, ImuSpec(MEMS_ADIS16405, rate=rate), seed=13)
    loose = [m for m in gnss(traj, np.random.default_rng(13)) if m.t < 60.0]
    cfg = config()
    cfg.layout = ("pos", "vel", "att", "bg", "ba", "sg", "sa", "clock")
    rows = []
    for n_sats in (3, 2, 0):
        meas = loose + (satellite_ranges(traj, np.random.default_rng(14), n_sats, 60.0)
                        if n_sats else [])
        out = run(imu, meas, cfg)
        errs = []
        for k in np.flatnonzero(out.t > 60.0):
            i = int(round(out.t[k] / traj.dt))
            true = NavState(traj.lat[i], traj.lon[i], traj.h[i], traj.v_enu[i], traj.q_nb[i])
            dp = nav_error(out.state(k), true)[0]
            errs.append(np.hypot(dp[0], dp[1]))
        rows.append((n_sats, errs[-1], max(errs)))
    return rows


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--rate", type=float, default=200.0, help="IMU rate, Hz")
    parser.add_argument("--duration", type=float, default=300.0, help="s")
    parser.add_argument("--tight", action="store_true", help="3 and 2 satellites vs pure INS")
    args = parser.parse_args()
    if args.tight:
        for n_sats, end, peak in tight_coupling(100.0):
            label = f"{n_sats} satellites (tight)" if n_sats else "no GNSS (pure INS)"
            print(f"60 s after loose GNSS, {label}: horizontal error at the end {end:.1f} m, "
                  f"max {peak:.1f} m")
        return

    traj = car(duration=args.duration, seed=11, rate=args.rate, static=20.0).trajectory
    imu = simulate_imu(traj, ImuSpec(MEMS_ADIS16405, rate=args.rate), seed=11)
    meas = gnss(traj, np.random.default_rng(11))
    run(imu, meas[:40], config())  # compile the numba kernels outside the timing
    cpu, wall = time.process_time(), time.perf_counter()
    out = run(imu, meas, config())
    cpu, wall = time.process_time() - cpu, time.perf_counter() - wall
    n = len(imu.t)
    print(f"speed: {n} IMU samples at {args.rate:g} Hz, {len(meas)} GNSS measurements, "
          f"{len(out.t)} filter epochs: {cpu:.2f} s CPU ({n / cpu:.0f} samples per CPU s), "
          f"{wall:.2f} s wall ({n / wall:.0f} samples/s)")


if __name__ == "__main__":
    main()
