"""Tight versus loose coupling versus pure inertial on the simulated car with 2 to 10 satellites.

Trial (seed 004 Lab 1, the constellation ablation of section 2.13): sim/scenarios.car at 100 Hz
with an ADIS16405-class MEMS IMU from sim/imu_sim; raw GNSS (GPS L1 C/A + Galileo E1 code,
Doppler, multipath, TCXO receiver clock, Klobuchar and Saastamoinen delays) from the project's
simulator on real broadcast orbits (gnss/simulator.py + gnss/ephemeris_data), antenna lever arm
(0.5, 0.3, 1.2) m. Open sky until `--open` s, then the simulator keeps only the N highest
satellites for `--window` s (its shading window).

Navigator: layout "24" (pos, vel, att, gyro/accel bias, scale factors, receiver clock), MEMS
noise model, no non-holonomic constraint (the comparison isolates GNSS). Processed as the ekf
node would: IMU streamed up to each GNSS epoch, then the measurement built from the raw epoch
and the navigator's own state at that epoch (:func:`ins_gnss_ros.gnss.ranges.satellite_ranges`).

* loose: SPP position + Doppler velocity (gnss/spp.py) at every epoch it solves (4 satellites of
  one system, 5 of two, at least): nothing in the windows with fewer.
* tight: loose until `--switch` s (the start and the heading alignment from motion need a fix
  and a velocity), then pseudoranges + range rates only.
* pure INS: loose until the window starts, then nothing.

With --nhc every case also gets the non-holonomic constraint of a wheeled vehicle (lateral
0.2 m/s, vertical 0.5 m/s, every 0.1 s): "pure INS" then means INS + NHC.

With --independent the simulator's ionosphere, troposphere, orbits and clocks differ from the
broadcast models the receiver side corrects with (gnss/broadcast_residuals.py: Klobuchar
removes half the ionosphere, 5 cm zenith troposphere, 1 m SISRE per satellite); the filter's
ranges are configured as without (it does not know them).

Horizontal error of the IMU position against the truth, over the window: RMS, max, at the end.

Usage::

    .venv/bin/python bench/bench_tight.py [--seeds 3] [--sats 0 6 4 3 2] [--window 300] [--nhc]
        [--independent]
"""
from __future__ import annotations

import argparse
import math
import time

import numpy as np

from ins_gnss_ros.gnss import ephemeris_data
from ins_gnss_ros.gnss.broadcast_residuals import BroadcastResiduals
from ins_gnss_ros.gnss.ranges import RangeConfig, satellite_ranges
from ins_gnss_ros.gnss.simulator import GnssSimulator, SimulatorConfig, solve_fix
from ins_gnss_ros.nav.error_model import nav_error
from ins_gnss_ros.nav import GnssFix, GnssVelocity, Navigator, NavigatorConfig
from ins_gnss_ros.nav.sensor_errors import MEMS_ADIS16405, filter_noise
from ins_gnss_ros.nav.strapdown import NavState
from ins_gnss_ros.sim.imu_sim import ImuSpec, simulate_imu
from ins_gnss_ros.sim.scenarios import ShadingWindow, car

LEVER = (0.5, 0.3, 1.2)
IMU_RATE = 100.0
#: Code noise of the simulator's defaults (0.3 + 0.3/sin E) with its multipath (1 m
#: exp(-E / 20 deg)) folded into the a^2 + b^2/sin^2 E form; Doppler as simulated.
RANGES = dict(code_sigma=(0.3, 0.32), doppler_sigma=(0.02, 0.02))


def navigator_config(nhc):
    return NavigatorConfig(noise=filter_noise(MEMS_ADIS16405, "rw"), layout="24",
                           lever_arm_b=np.array(LEVER), sigma_pos0=3.0, sigma_vel0=0.2,
                           sigma_tilt0=np.deg2rad(1.0), align_speed=1.0,
                           nhc_sigma=(0.2, 0.5) if nhc else None)


def simulate(seed, n_sats, t_open, window, gnss_rate, residuals=None):
    """Truth, IMU, simulator and its epochs; n_sats 0 = open sky throughout; ``residuals``
    (BroadcastResiduals) set the simulator's truth apart from the broadcast models."""
    traj = car(duration=t_open + window, seed=seed, rate=IMU_RATE, static=30.0).trajectory
    imu = simulate_imu(traj, ImuSpec(MEMS_ADIS16405, rate=IMU_RATE), seed=seed)
    shading = (ShadingWindow(t_open, t_open + window, n_sats),) if n_sats else ()
    sim = GnssSimulator(ephemeris_data.load(traj.lon[0]),
                        SimulatorConfig(lever_arms=(LEVER,), shading=shading, seed=seed,
                                        residuals=residuals))
    epochs = [e[0] for e in sim.run(traj, gnss_rate)]
    return traj, imu, sim, epochs


def loose(epoch, sim, x0):
    """GnssFix + GnssVelocity from the SPP of a simulated epoch ([] when it does not solve)."""
    fix = solve_fix(epoch, sim, x0)
    if fix is None:
        return [], x0
    out = [GnssFix(epoch.t, fix.lat, fix.lon, fix.h, fix.covariance_enu)]
    if np.all(np.isfinite(fix.vel_enu)):
        out.append(GnssVelocity(epoch.t, fix.vel_enu, fix.vel_covariance_enu))
    return out, fix.xyz


def run(mode, imu, sim, epochs, t_switch, t_open, nhc=False):
    """Stream one case through the navigator; returns (output, [(t, satellites used)])."""
    nav = Navigator(navigator_config(nhc))
    rc = RangeConfig(klobuchar=sim.broadcast.klobuchar, **RANGES)
    x0, i, used = None, 0, []
    for ep in epochs:
        j = int(np.searchsorted(imu.t, ep.t, side="right"))
        if j > i:
            nav.add_imu(imu.t[i:j], imu.dtheta[i:j], imu.dv[i:j])
            i = j
        if mode == "ins" and ep.t >= t_open:
            continue
        if mode == "tight" and ep.t >= t_switch:
            m = satellite_ranges(ep.raw, sim.ephemerides, ep.t, nav.state_at(ep.t), LEVER, rc)
            if m is not None:
                nav.add_measurement(m)
                used.append((ep.t, len(m.pseudorange)))
            continue
        meas, x0 = loose(ep, sim, x0)
        for m in meas:
            nav.add_measurement(m)
    if i < len(imu.t):
        nav.add_imu(imu.t[i:], imu.dtheta[i:], imu.dv[i:])
    nav.flush()
    return nav.output(), used


def horizontal_errors(out, traj, t0, t1):
    """Horizontal IMU position error [m] at the output epochs in [t0, t1), on a 1 s grid."""
    k = np.flatnonzero((out.t >= t0) & (out.t < t1))
    err = np.empty(len(k))
    for n, kk in enumerate(k):
        i = int(round(out.t[kk] * IMU_RATE))
        true = NavState(traj.lat[i], traj.lon[i], traj.h[i], traj.v_enu[i], traj.q_nb[i])
        dp = nav_error(out.state(kk), true)[0]
        err[n] = math.hypot(dp[0], dp[1])
    return np.interp(np.arange(t0, t1), out.t[k], err)


def ratio_holds_from(tight, ins, factor=5.0):
    """Seconds into the window (1 s grid) from which factor x tight <= pure-INS error holds at
    every later epoch (the window length: not at the end)."""
    bad = np.flatnonzero(tight * factor > ins)
    return 0.0 if len(bad) == 0 else float(bad[-1] + 1)


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=int, default=3, help="trials (scenario seeds 1..N)")
    parser.add_argument("--sats", type=int, nargs="+", default=[0, 6, 4, 3, 2],
                        help="satellites kept in the window (0: open sky)")
    parser.add_argument("--open", type=float, default=180.0, help="open sky before, s")
    parser.add_argument("--switch", type=float, default=120.0, help="tight from, s")
    parser.add_argument("--window", type=float, default=300.0, help="window length, s")
    parser.add_argument("--rate", type=float, default=1.0, help="GNSS rate, Hz")
    parser.add_argument("--nhc", action="store_true",
                        help="non-holonomic constraint (0.2, 0.5) m/s in every case")
    parser.add_argument("--independent", action="store_true",
                        help="simulated truth apart from the broadcast models by real residuals")
    args = parser.parse_args()
    residuals = BroadcastResiduals() if args.independent else None
    t0, t1 = args.open, args.open + args.window
    print(f"window {t0:g}-{t1:g} s, GNSS {args.rate:g} Hz, NHC {'on' if args.nhc else 'off'}, "
          f"broadcast residuals {residuals}, horizontal error RMS / max / end (m)")
    rows = {}
    for seed in range(1, args.seeds + 1):
        ins_err = None
        for n in args.sats:
            wall = time.perf_counter()
            traj, imu, sim, epochs = simulate(seed, n, t0, args.window, args.rate, residuals)
            res = {}
            for mode in ("loose", "tight") + (("ins",) if ins_err is None else ()):
                out, used = run(mode, imu, sim, epochs, args.switch, t0, args.nhc)
                res[mode] = horizontal_errors(out, traj, t0, t1)
                if mode == "tight":
                    k = [n_used for t, n_used in used if t0 <= t < t1]
                    res["sats"] = (min(k), max(k)) if k else (0, 0)
            ins_err = res.get("ins", ins_err)
            res["ins"] = ins_err
            rows.setdefault(n, []).append(res)
            label = f"{n} satellites" if n else "open sky"
            line = " | ".join(f"{m} {np.sqrt(np.mean(e ** 2)):8.2f} {e.max():8.2f} {e[-1]:8.2f}"
                              for m, e in ((m, res[m]) for m in ("loose", "tight", "ins")))
            res["hold"] = hold = ratio_holds_from(res["tight"], res["ins"])
            print(f"seed {seed} {label:>13} (tight used {res['sats'][0]}-{res['sats'][1]}): "
                  f"{line} | tight x5 < INS from +{hold:g} s  [{time.perf_counter() - wall:.0f} s]",
                  flush=True)
    print("\nsummary over seeds: tight max error, pure-INS max / tight max (min over seeds), "
          "pure-INS RMS / tight RMS (min over seeds), loose max (max over seeds), "
          "5x holds from (latest over seeds)")
    for n, res in rows.items():
        label = f"{n} satellites" if n else "open sky"
        t_max = max(r["tight"].max() for r in res)
        ratio_max = min(r["ins"].max() / r["tight"].max() for r in res)
        ratio_rms = min(np.sqrt(np.mean(r["ins"] ** 2) / np.mean(r["tight"] ** 2)) for r in res)
        l_max = max(r["loose"].max() for r in res)
        hold = max(r["hold"] for r in res)
        print(f"{label:>13}: tight max {t_max:8.2f} m, INS/tight max {ratio_max:7.1f}x, "
              f"RMS {ratio_rms:7.1f}x, loose max {l_max:9.2f} m, 5x from +{hold:g} s")


if __name__ == "__main__":
    main()
