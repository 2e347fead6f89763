"""Real car drive (car_drive_0708): how much of the causal filter's outage drift any start could
avoid ("oracle" starts).

A run WITHOUT outages is smoothed (RTS). Per outage window the bench filter (bench_car_drive.py:
same noise model, NHC, IMU grid) is then started at the window start and coasts through it on
the IMU and the constraints alone, from

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

import numpy as np

from bench_car_drive import DATA, NHC_SIGMA, VEL_DELAY_S, car_config, drifts, run_drive, \
    uniform_imu_times
from ins_gnss_ros.nav import Navigator
from ins_gnss_ros.nav.smoother import rts_smooth
from ins_gnss_ros.nav.strapdown import NavState
from ins_gnss_ros.trial.car_drive import load_car_drive
from ins_gnss_ros.trial.outages import outage_windows, parse_outage_spec


#: IMU sample interval, s.
IMU_DT = 0.01


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
    lever = drive.antenna_lever_arm_flu
    rows = []
    for start, end in windows:
        window = np.array([[start, end]])
        k_oracle = int(np.searchsorted(smoothed.t, start, side="right")) - 1
        # A measurement is applied at the epoch of the last IMU sample before it.
        k_causal = int(np.searchsorted(aided.t, start - VEL_DELAY_S - IMU_DT, side="left")) - 1
        rows.append([drifts(coast(drive, config, track, k, end), drive, window, lever)[2][0]
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
    aided = run_drive(drive, config, np.empty((0, 2)), t_end if args.half else None)
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
