"""Error-free IMU increments of analytic motions, for testing mechanisation algorithms.

Every function returns exact integrals of the body angular rate (rad) and specific force (m/s)
over consecutive sensor intervals of length dt, body frame FLU, together with what is needed
to know the true motion.
"""
from __future__ import annotations

import numpy as np

from ..nav.earth import WGS84, Ellipsoid, earth_rate_enu, gravity_enu
from ..nav.rotations import quat_from_rotvec, quat_to_dcm


def stationary(lat: float, h: float, q_nb, dt: float, n: int, ell: Ellipsoid = WGS84):
    """A body at rest on the rotating Earth.

    Both the angular rate omega_ib = C_bn omega_ie and the specific force f = -C_bn g_n are
    constant in the body frame, so their integrals are exactly rate * dt.

    Returns
    -------
    dthetas, dvs : ndarray, shape (n, 3)
    """
    C_bn = quat_to_dcm(q_nb).T
    w_b = C_bn @ earth_rate_enu(lat, ell)
    f_b = -C_bn @ gravity_enu(lat, h, ell)
    return np.tile(w_b * dt, (n, 1)), np.tile(f_b * dt, (n, 1))


def coning_attitude(beta: float, omega: float, t):
    """True attitude (reference <- body) of classic coning: the rotation vector
    beta [0, cos(omega t), sin(omega t)] (Savage, "Strapdown Analytics", ch. 7)."""
    t = np.asarray(t, float)
    rv = beta * np.stack([np.zeros_like(t), np.cos(omega * t), np.sin(omega * t)], -1)
    return quat_from_rotvec(rv)


def coning(beta: float, omega: float, dt: float, n: int):
    """Gyro increments of classic coning (see :func:`coning_attitude`) from t = 0.

    The body rate is omega_b = Omega [-2 sin^2(beta/2), -sin(beta) sin(Omega t),
    sin(beta) cos(Omega t)], obtained from 2 q* dq/dt of the attitude above.

    Returns
    -------
    dthetas : ndarray, shape (n, 3)
    """
    t = dt * np.arange(n + 1)
    c, s = np.cos(omega * t), np.sin(omega * t)
    sb = np.sin(beta)
    return np.stack([np.full(n, -2.0 * omega * np.sin(0.5 * beta) ** 2 * dt),
                     sb * np.diff(c), sb * np.diff(s)], -1)


def sculling(beta: float, accel: float, omega: float, dt: float, n: int):
    """Increments of classic sculling: roll angle beta sin(Omega t) about x while the specific
    force in the body is accel sin(Omega t) along y.

    The true velocity in the reference frame after an integer number m of periods is
    [0, 0, accel J1(beta) m 2 pi / Omega] (the mean of sin x sin(beta sin x) is J1(beta)).

    Returns
    -------
    dthetas, dvs : ndarray, shape (n, 3)
    """
    t = dt * np.arange(n + 1)
    c, s = np.cos(omega * t), np.sin(omega * t)
    z = np.zeros(n)
    return (np.stack([beta * np.diff(s), z, z], -1),
            np.stack([z, -accel / omega * np.diff(c), z], -1))
