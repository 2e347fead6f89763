"""The filter's time update: IMU compensation, mechanisation and covariance propagation over a
segment of IMU samples, and the small extrapolation to a measurement epoch inside a sample."""
from __future__ import annotations

import numpy as np

from . import _kernels
from .earth import WGS84
from .error_model import MISALIGN_COLUMNS
from .increments import SensorErrors
from .rotations import quat_to_dcm
from .strapdown import NavState

#: Memory of a manoeuvre's rotation, s (:func:`turn_noise`): a 90 deg turn of a car or a robot
#: takes 3-10 s, and by the next one the aiding has measured what the last did.
TURN_TIME = 10.0

#: The z accelerometer's cross-axis terms of a layout without "nz" (_kernels.mech_segment;
#: writeable, as the estimates are: a read-only array would compile the kernel once more).
NO_CROSS_Z = np.zeros(2)


def extrapolate(state, dt, a_enu):
    """State moved by dt (s; normally a fraction of one IMU sample, or the change of the
    time-offset estimate) at constant acceleration a_enu (m/s^2): the measurement epoch."""
    if dt == 0.0:
        return state
    v = np.empty(3)
    # Compiled: called for every measurement, where the numpy arithmetic on 3-vectors cost
    # several times the kernel's call.
    lat, lon, h = _kernels.extrapolate(float(state.lat), float(state.lon), float(state.h),
                                       state.v_enu, a_enu, float(dt), WGS84.a, WGS84.e2, v)
    return NavState.taking(lat, lon, h, v, state.q_nb.copy(), state.t + dt)


def propagate(s, rows, noise, cov_interval, gaps, space, track):
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
    track : (m, 10) ndarray
        Gets the solution (lat, lon, h, v_enu, q_nb) after each of the segment's first m
        samples (the record's states at the samples, Recorder.samples; m = 0: none).

    Returns
    -------
    phi : (n, n) ndarray
        Transition matrix of the segment.
    """
    t, th, dv, cth, cdv = rows
    start = s.nav
    ekf = s.ekf
    # F is rebuilt every cov_interval; shorter segments (cut by measurement epochs) reuse it.
    refresh = start.t - s.t_model >= cov_interval - 1e-9
    if refresh:
        s.t_model = start.t
    F, Q, rebuild = ekf.model(start, refresh)
    # The samples' steps (the state time is the end of the last processed sample) and their
    # sum, compensation with the running estimates, coning terms, mechanisation, the model at
    # the segment's start and its Picard step in one compiled call (a chain of numpy calls on
    # 20-sample arrays, and their glue, cost more than it).
    errors = SensorErrors.of_estimates(s.estimates)
    v, q, s.a_enu, s.omega = np.empty(3), np.empty(4), np.empty(3), np.empty(3)
    lat, lon, h, T, phi, P = _kernels.time_update(
        float(start.lat), float(start.lon), float(start.h), start.v_enu, start.q_nb,
        float(start.t), t, th, dv, cth, cdv, errors.gyro_bias, errors.gyro_scale,
        errors.accel_bias, errors.accel_scale, s.estimates.get("nz", NO_CROSS_Z),
        WGS84.kernel_params, v, q, s.a_enu, s.omega, F, rebuild, ekf.space.layout.sensor_plan,
        MISALIGN_COLUMNS, np.ascontiguousarray(ekf.P, float), Q, int(ekf.order), track)
    ekf.predicted(F, phi, P)
    s.nav = NavState.taking(lat, lon, h, v, q, float(t[-1]))
    s.omega_time = T
    turn_noise(s, noise, space)
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


def turn_noise(s, noise, space):
    """Attitude variance of a turn from the gyros' scale-factor and cross-axis errors the state
    does not hold (no "sg" / "ng" block), added to ``s.ekf.P`` for the segment just propagated.

    A constant error matrix (scale sigma on its diagonal, cross-axis sigma off it) turns the
    attitude by its product with the rotation Theta: on body axis i by a variance of
    sigma_s^2 Theta_i^2 + sigma_m^2 (Theta_j^2 + Theta_k^2), growing with the square of the
    turn, not with its duration (a white noise would spread it over the turn's time and give a
    slow turn little). It is added as the manoeuvre's rotation (``s.turn``, forgotten over
    TURN_TIME) grows, not as it shrinks: a vessel rolling to and fro gains only what each swing
    adds. A consumer unit's 1.5 % scale and 2 % cross-axis make 1.4-1.8 deg in a 90 deg turn:
    left out, such a unit's car published 205 of its 535 fixes degraded (not valid), and its
    robot's roll ran 2.6 deg off with a sigma of 0.3 (docs/results/product_path.md,
    "2026-12-06 (session 30)").
    """
    sigma_s = 0.0 if "sg" in space else noise.blocks["sg"].sigma0
    sigma_m = 0.0 if "ng" in space else noise.blocks["ng"].sigma0
    if sigma_s == 0.0 and sigma_m == 0.0:
        return
    before = s.turn * np.exp(-s.omega_time / TURN_TIME)
    s.turn = before + s.omega * s.omega_time
    grown = np.maximum(s.turn * s.turn - before * before, 0.0)
    var_b = sigma_s ** 2 * grown + sigma_m ** 2 * (grown.sum() - grown)
    C = quat_to_dcm(s.nav.q_nb)
    var_n = (C * var_b) @ C.T
    if not s.heading_known:
        var_n[2, :] = var_n[:, 2] = 0.0  # the yaw stays out of the filter until its alignment
    att = space["att"]
    s.ekf.P[att, att] += var_n
