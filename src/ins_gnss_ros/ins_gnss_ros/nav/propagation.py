"""The filter's time update: IMU compensation, mechanisation and covariance propagation over a
segment of IMU samples, and the small extrapolation to a measurement epoch inside a sample."""
from __future__ import annotations

from dataclasses import replace

import numpy as np

from .earth import radii
from .increments import SensorErrors
from .strapdown import NavState, run


def extrapolate(state, dt, a_enu):
    """State moved by dt (s; normally a fraction of one IMU sample, or the change of the
    time-offset estimate) at constant acceleration a_enu (m/s^2): the measurement epoch."""
    if dt == 0.0:
        return state
    rm, rn = radii(state.lat)
    d = state.v_enu * dt + 0.5 * a_enu * dt * dt
    return replace(state, lat=state.lat + d[1] / (rm + state.h),
                   lon=state.lon + d[0] / ((rn + state.h) * np.cos(state.lat)),
                   h=state.h + d[2], v_enu=state.v_enu + a_enu * dt, t=state.t + dt)


def compensate(th, dv, dts, estimates):
    """Raw increments th (rad), dv (m/s), (N, 3) body FLU, of durations dts (N,) s, corrected
    by the running bias and scale-factor estimates (error_model.py blocks; the model of
    :class:`~ins_gnss_ros.nav.increments.SensorErrors`)."""
    return SensorErrors.of_estimates(estimates).compensate(th, dv, dts)


def propagate(s, rows, noise, cov_interval, gaps, space):
    """Mechanise one segment of IMU samples and propagate the covariance to its end.

    Parameters
    ----------
    s : RunState
        Updated in place (rewind.py): the solution, the segment's mean acceleration and rate,
        the filter (with F rebuilt every cov_interval from the segment's mean compensated
        rates; seed 004 section 2.5), the estimates that run on between updates, and the
        filter epoch.
    rows : tuple of ndarray
        (t, dtheta, dv, cth, cdv) of the samples (imu_buffer.py).
    noise : FilterNoise
    cov_interval : float
        s.
    gaps : BridgedGaps
    space : StateSpace

    Returns
    -------
    phi : (n, n) ndarray
        Transition matrix of the segment.
    """
    t, th, dv, cth, cdv = rows
    # The state time is the end of the last processed sample (filled in place: np.diff
    # with prepend and np.clip cost more than the arithmetic here).
    dts = np.empty(len(t))
    dts[0] = t[0] - s.nav.t
    np.subtract(t[1:], t[:-1], out=dts[1:])
    np.maximum(dts, 1e-6, out=dts)
    th, dv = compensate(th, dv, dts, s.estimates)
    rot = th + cth
    dvn = dv + cdv
    T = float(dts.sum())
    start = s.nav
    r = run(start, rot, dvn, T / len(t))
    s.nav = NavState(r["lat"][-1], r["lon"][-1], r["h"][-1], r["v_enu"][-1],
                     r["q_nb"][-1], float(t[-1]))
    s.a_enu = (s.nav.v_enu - start.v_enu) / T
    s.omega = th.sum(axis=0) / T
    s.omega_time = T
    f_b = dv.sum(axis=0) / T
    # F is rebuilt every cov_interval; shorter segments (cut by measurement epochs) reuse it.
    refresh = start.t - s.t_model >= cov_interval - 1e-9
    if refresh:
        s.t_model = start.t
    phi = s.ekf.predict(start, f_b, s.omega, T, refresh)
    if gaps.gaps:
        gaps.add_noise(s.ekf.P, space, start.t, s.nav.t, s.heading_known)
    for name in ("gmg", "gma"):
        if name in s.estimates:
            s.estimates[name] *= np.exp(-T / noise.blocks[name].tau)
    if "clock" in s.estimates:
        # The receiver clock runs on between updates: offset, drift and drift rate follow
        # the same model as their errors (seed 004 section 2.4; error_model.system_matrix).
        c = s.estimates["clock"]
        s.estimates["clock"] = np.array([c[0] + c[1] * T + 0.5 * c[2] * T * T,
                                         c[1] + c[2] * T, c[2]])
    s.t_epoch = s.nav.t
    return phi
