"""Real car drive (car_drive_0708): how much of the causal filter's outage drift any start could
avoid ("oracle" starts). An analysis of the filter core, not the product: this bench drives the
`Navigator` with its own measurements, IMU grid and noise floors (below; the product's figures
on this drive come from bench/bench_car_drive.py, the trial commands).

A run WITHOUT outages is smoothed (RTS). Per outage window the filter (same noise model, NHC,
IMU grid) is then started at the window start and coasts through it on the IMU and the
constraints alone, from

* the oracle start: the smoothed state, sensor-error estimates and covariance of that epoch,
  the best-informed start any causal filter with this IMU and measurement set could have (a
  bound on average over many windows, not per window: docs/results/ekf.md);
* the causal start: the forward state, estimates and covariance of the same no-outage run at
  the last epoch before the window's first withheld measurement (the velocity stamped at the
  window start is applied VEL_DELAY_S earlier): what the forward filter has there when it has
  recovered from its previous outage. For the first outage it is the forward filter's own
  state; only the phase of the constraint epochs differs (0.80 against 0.84 m on the drive).

Printed per protocol: the RMS and maximum over the windows of the largest horizontal error in
each (the forward filter's metric), and the same for the protocol shifted by every multiple of
--shift seconds within one period, then over all these windows together: with 11 windows the
metric depends a lot on where they fall (docs/results/ekf.md, section 1).

Usage::

    .venv/bin/python bench/bench_car_oracle.py [--protocol 15:45:40] [--half] [--shift 5]
"""
from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

from ins_gnss_ros.nav import GnssFix, GnssVelocity, Navigator, NavigatorConfig, point_track
from ins_gnss_ros.nav.sensor_errors import DEG, MICRO_G, BlockNoise, FilterNoise
from ins_gnss_ros.nav.smoother import rts_smooth
from ins_gnss_ros.nav.strapdown import NavState
from ins_gnss_ros.trial.car_drive import load_car_drive
from ins_gnss_ros.trial.evaluate import Trajectory, evaluate
from ins_gnss_ros.trial.outages import outage_windows, parse_outage_spec

DATA = Path(__file__).resolve().parents[1] / ".." / "shared" / "data" / "car_drive_0708"

#: Noise model of the drive's MEMS IMU, tuned on the first half of the drive only: white noise
#: of the order of the Allan deviation of the static start at 1 s (gyro ~1e-3 rad/s, accel
#: 0.01-0.05 m/s^2: engine and body vibration, far above the data sheet's 0.0038 deg/s/sqrt(Hz)
#: and 70 ug/sqrt(Hz)), gyro doubled by the tuning; bias random walks 10x the source's figures;
#: turn-on bias spreads cover the static-mean gyro output (up to 0.17 deg/s) and a 0.05 m/s^2
#: accelerometer offset (config/car.yaml carries the same figures to the product).
CAR_NOISE = FilterNoise(
    gyro_psd=2e-3 ** 2, accel_psd=1.2e-2 ** 2,
    blocks={"bg": BlockNoise(0.3 * DEG, psd=(3.8e-5 * DEG * 10) ** 2),
            "ba": BlockNoise(0.05, psd=(7 * MICRO_G * 10) ** 2),
            "sg": BlockNoise(0.01), "sa": BlockNoise(0.01)})

#: Non-holonomic constraint noise (lateral, vertical), m/s, tuned on the first half.
NHC_SIGMA = (0.2, 0.5)

#: The RTKLIB velocities of this solution lag its positions: the velocity stamped t matches the
#: position-derived velocity of t - 0.125 s (docs/results/ekf.md), so velocity measurements are
#: applied at that epoch.
VEL_DELAY_S = 0.125

#: Floors of the GNSS standard deviations (RTKLIB's own sigmas are optimistic at 1 cm), m, m/s.
POS_SIGMA_FLOOR = 0.03
VEL_SIGMA_FLOOR = 0.03

#: IMU sample interval, s.
IMU_DT = 0.01


def car_config(drive, nhc=NHC_SIGMA):
    """NavigatorConfig of the car drive: layout 15, the NHC noise (lateral, vertical) m/s."""
    return NavigatorConfig(noise=CAR_NOISE, layout="15", lever_arm_b=drive.antenna_lever_arm_flu,
                           nhc_sigma=tuple(nhc), sigma_pos0=0.1, sigma_vel0=0.05,
                           sigma_tilt0=np.deg2rad(2.0))


def uniform_imu_times(drive):
    """IMU sample times on the sensor's own uniform clock, GNSS time scale: the logger's
    millisecond stamps step by 8 to 11 ms around a steady 10.0026 ms and never stray 2 ms from
    a uniform grid, so the samples are spread uniformly between the first and last stamp (the
    product takes the jitter out causally instead: imu/sensor_clock.py)."""
    t = drive.imu_time_gnss
    return np.linspace(t[0], t[-1], len(t))


def aided_run(drive, config, t_end=None):
    """Forward pass over the drive with every RTK-fixed epoch as a fix and a velocity (up to
    t_end); returns the output."""
    t = uniform_imu_times(drive)
    stop = len(t) if t_end is None else int(np.searchsorted(t, t_end))
    dt = np.diff(t[:stop], prepend=t[0] - np.median(np.diff(t[:100])))
    tr = drive.truth
    nav = Navigator(config)
    for k in np.flatnonzero(tr.time <= (np.inf if t_end is None else t_end)):
        nav.add_measurement(GnssFix(tr.time[k], tr.lat[k], tr.lon[k], tr.height[k],
                                    tr.pos_cov_enu[k] + POS_SIGMA_FLOOR ** 2 * np.eye(3)))
        nav.add_measurement(GnssVelocity(tr.time[k] - VEL_DELAY_S, tr.vel_enu[k],
                                         VEL_SIGMA_FLOOR ** 2 * np.eye(3)))
    nav.add_imu(t[:stop], drive.gyro_flu[:stop] * dt[:, None], drive.accel_flu[:stop] * dt[:, None])
    nav.flush()
    return nav.output()


def window_max(out, drive, window):
    """Largest horizontal error of the antenna inside `window` (start, end) of a forward pass."""
    lat, lon, h = point_track(out, drive.antenna_lever_arm_flu)
    est = Trajectory(time=out.t, lat=lat, lon=lon, height=h)
    return evaluate(est, drive.truth, np.array([window])).outages[0].max_horizontal_m


class StartedNavigator(Navigator):
    """A Navigator that starts navigating (heading known) from a given state, sensor-error
    estimates and covariance instead of levelling and aligning on the data."""

    def __init__(self, config, state, estimates, P0):
        super().__init__(config)
        # The start counts as aided: DEAD_RECKONING follows after dr_timeout, as it would.
        self.start_from(state, estimates, P0)


def coast(drive, config, track, k, t_end):
    """Forward pass from epoch k of `track` (a NavigatorOutput or SmoothedOutput: state,
    estimates, covariance) to t_end on the IMU and the constraints of `config`."""
    state = NavState(track.lat[k], track.lon[k], track.h[k], track.v_enu[k], track.q_nb[k],
                     track.t[k])
    estimates = {name: values[k] for name, values in track.estimates.items()}
    nav = StartedNavigator(config, state, estimates, track.P[k])
    t = uniform_imu_times(drive)
    i, j = np.searchsorted(t, [state.t, t_end], side="right")
    dt = np.diff(t[i - 1:j])
    nav.add_imu(t[i:j], drive.gyro_flu[i:j] * dt[:, None], drive.accel_flu[i:j] * dt[:, None])
    nav.flush()
    return nav.output()


def window_errors(drive, config, aided, smoothed, windows):
    """Per window: largest horizontal antenna error from the oracle and from the causal start."""
    rows = []
    for start, end in windows:
        k_oracle = int(np.searchsorted(smoothed.t, start, side="right")) - 1
        # A measurement is applied at the epoch of the last IMU sample before it.
        k_causal = int(np.searchsorted(aided.t, start - VEL_DELAY_S - IMU_DT, side="left")) - 1
        rows.append([window_max(coast(drive, config, track, k, end), drive, (start, end))
                     for track, k in ((smoothed, k_oracle), (aided, k_causal))])
    return np.array(rows)


def rms_max(values):
    return np.sqrt(np.mean(values ** 2)), np.max(values)


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--protocol", action="append", default=None)
    parser.add_argument("--half", action="store_true", help="first half of the drive only")
    parser.add_argument("--shift", type=float, default=5.0,
                        help="step of the protocol shifts, s (0: the protocol only)")
    parser.add_argument("--nhc-sigma", type=float, nargs=2, default=NHC_SIGMA,
                        metavar=("LATERAL", "VERTICAL"), help="NHC noise, m/s")
    args = parser.parse_args()
    drive = load_car_drive(DATA)
    config = car_config(drive, nhc=args.nhc_sigma)
    t0, t1 = drive.truth.time[0], drive.truth.time[-1]
    t_end = 0.5 * (t0 + t1) if args.half else t1
    aided = aided_run(drive, config, t_end if args.half else None)
    smoothed = rts_smooth(aided)
    print(f"NHC sigma {config.nhc_sigma} m/s{', first half' if args.half else ''}")
    for spec in args.protocol or ["15:45:40"]:
        protocol = parse_outage_spec(spec)
        shifts = np.arange(0.0, protocol.period, args.shift) if args.shift > 0.0 else [0.0]
        pooled = []
        for shift in shifts:
            shifted = parse_outage_spec(f"{protocol.length}:{protocol.period}:"
                                        f"{protocol.first + shift}")
            per = window_errors(drive, config, aided, smoothed,
                                outage_windows(shifted, t0, t_end))
            pooled.append(per)
            print(f"protocol {shifted} ({len(per)} outages): max-horizontal-error-per-outage "
                  "RMS / max, oracle start %.2f / %.2f m, causal start %.2f / %.2f m"
                  % (*rms_max(per[:, 0]), *rms_max(per[:, 1])))
            if shift == 0.0:
                for col, name in ((0, "oracle"), (1, "causal")):
                    print(f"  per outage, {name} start: "
                          + " ".join(f"{x:.2f}" for x in per[:, col]))
        if len(pooled) > 1:
            pooled = np.vstack(pooled)
            print(f"all {len(pooled)} windows of the {len(shifts)} shifts: oracle start "
                  "%.2f / %.2f m, causal start %.2f / %.2f m"
                  % (*rms_max(pooled[:, 0]), *rms_max(pooled[:, 1])))


if __name__ == "__main__":
    main()
