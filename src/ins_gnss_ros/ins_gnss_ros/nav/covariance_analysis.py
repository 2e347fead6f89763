"""Covariance analysis of free-inertial error growth, and its Monte Carlo check.

* :func:`propagate_covariance` propagates P with the linear error model along a reference
  trajectory (seed 001, Babich: "stochastic analysis of SINS errors on arbitrary motions"),
  one Picard step of equal order for Ψ_k and Q_k per IMU interval (eq. 4.5).
* :func:`monte_carlo` runs the full non-linear mechanisation (nav/strapdown.py) with random
  initial navigation errors and sensor errors drawn by
  :class:`~ins_gnss_ros.nav.sensor_errors.ImuErrorSimulator`, and returns the navigation
  errors of every run against the unperturbed reference run (seed 001 §6.11 does the same
  with the linear model; here the truth is non-linear).

Both take the same ideal increments, so the reference run of these increments is the truth
and the mechanisation's algorithmic error cancels.
"""

import numpy as np

from .discretize import DEFAULT_ORDER, picard_predict
from .earth import WGS84
from .error_model import nav_error, noise_input, system_matrix
from .sensor_errors import ImuErrorSimulator
from .strapdown import NavState, apply_correction, run


def _state(out, k):
    return NavState(out["lat"][k], out["lon"][k], out["h"][k], out["v_enu"][k],
                    out["q_nb"][k], out["t"][k])


def propagate_covariance(layout, state0, dthetas, dvs, dt, noise, P0, record=None,
                         order=DEFAULT_ORDER, ell=WGS84):
    """Covariance of the error state along the trajectory of the given increments.

    Parameters
    ----------
    layout : StateLayout
    state0 : NavState
        True initial state.
    dthetas, dvs : array_like, shape (N, 3)
        Ideal increments [rad], [m/s] in body axes.
    dt : float
        Increment interval [s].
    noise : FilterNoise
    P0 : (n, n) array_like
        Initial covariance.
    record : sequence of int, optional
        Step indices (0..N) at which to keep P; default every step.
    order : int
        Picard order ν of Φ_k and Q_k.

    Returns
    -------
    (len(record), n, n) ndarray
    """
    ref = run(state0, dthetas, dvs, dt, ell)
    n_steps = len(dthetas)
    record = range(n_steps + 1) if record is None else record
    wanted = set(record)
    w_b = np.asarray(dthetas) / dt
    f_b = np.asarray(dvs) / dt
    P = np.array(P0, dtype=float)
    out = {0: P.copy()} if 0 in wanted else {}
    state = _state(ref, 0)
    F = system_matrix(layout, state, f_b[0], w_b[0], ell)
    for k in range(n_steps):
        nxt = _state(ref, k + 1)
        F_next = system_matrix(layout, nxt, f_b[k], w_b[k], ell)
        # F at the middle of the interval (mean of its ends): second-order accurate in dt.
        F_mid = 0.5 * (F + F_next)
        G, Qc = noise_input(layout, state, noise)
        P = picard_predict(P, F_mid, G @ Qc @ G.T, dt, order)
        state, F = nxt, F_next
        if k + 1 in wanted:
            out[k + 1] = P.copy()
    return np.array([out[k] for k in record])


def monte_carlo(state0, dthetas, dvs, dt, grade, n_runs, rng, sigma_pos, sigma_vel,
                sigma_att, record, ell=WGS84):
    """Navigation errors of non-linear runs with random initial and sensor errors.

    Parameters
    ----------
    state0, dthetas, dvs, dt : as in :func:`propagate_covariance`
    grade : ImuGrade
        Sensor error budget (all processes of :mod:`ins_gnss_ros.nav.sensor_errors`).
    n_runs : int
    rng : numpy.random.Generator
    sigma_pos, sigma_vel, sigma_att : float or array_like (3,)
        Initial ENU position [m], velocity [m/s] and attitude-error φ [rad] 1σ.
    record : sequence of int
        Step indices (0..N) at which to return the errors.

    Returns
    -------
    (n_runs, len(record), 9) ndarray
        [δp (m), δv (m/s), φ (rad)] of each run, as defined in
        :mod:`ins_gnss_ros.nav.error_model`.
    """
    ref = run(state0, dthetas, dvs, dt, ell)
    truth = [_state(ref, k) for k in record]
    sim = ImuErrorSimulator(grade, dt, rng, n_runs)
    dth_m, dv_m = sim.corrupt(dthetas, dvs)
    x0 = rng.standard_normal((n_runs, 9)) * np.concatenate(
        [np.broadcast_to(sigma_pos, 3), np.broadcast_to(sigma_vel, 3),
         np.broadcast_to(sigma_att, 3)])
    errors = np.empty((n_runs, len(record), 9))
    for r in range(n_runs):
        # Injecting an error is removing its negative (apply_correction's convention).
        start = apply_correction(state0, -x0[r, :3], -x0[r, 3:6], -x0[r, 6:], ell)
        out = run(start, dth_m[r], dv_m[r], dt, ell)
        for i, k in enumerate(record):
            errors[r, i] = np.concatenate(nav_error(_state(out, k), truth[i], ell))
    return errors
