"""Lever-arm transfer of the INS solution from the IMU to another point of the rigid body
(GNSS antenna, speed log), Groves, "Principles of GNSS, Inertial and Multisensor Integrated
Navigation", 2nd ed., ch. 2 and 14 (seed 004 section 2.2 uses the same
transfer for the antenna).

Lever arm l_b: position of the point relative to the IMU navigation centre, FLU body frame, m.
"""
from __future__ import annotations

import numpy as np

from . import _kernels
from .earth import WGS84, Ellipsoid, ecef_to_enu_matrix, ecef_to_geodetic, geodetic_to_ecef
from .rotations import quat_rotate


def lever_arm_position(lat, lon, h, q_nb, l_b, ell: Ellipsoid = WGS84):
    """Geodetic position of the point at lever arm l_b.

    r_point = r_imu + C_nb l_b, added exactly in ECEF (no small-offset approximation, so it is
    also valid for long baselines and near the poles).

    Parameters
    ----------
    lat, lon, h : float or ndarray, shape (...)
        IMU position (rad, rad, m).
    q_nb : array_like, shape (..., 4)
        Attitude ENU <- FLU.
    l_b : array_like, shape (3,) or (..., 3)
        Lever arm in FLU, m.

    Returns
    -------
    lat, lon, h : float or ndarray
        Position of the point (rad, rad, m).
    """
    d_enu = quat_rotate(q_nb, l_b)
    # v_ecef = C_en^T v_enu, one matrix per position.
    d_ecef = np.einsum("...ji,...j->...i", ecef_to_enu_matrix(lat, lon), d_enu)
    return ecef_to_geodetic(geodetic_to_ecef(lat, lon, h, ell) + d_ecef, ell)


def lever_arm_velocity(v_enu, q_nb, omega_ib_b, l_b, lat, ell: Ellipsoid = WGS84):
    """Earth-relative velocity (ENU) of the point at lever arm l_b.

    v_point = v_imu + C_nb (omega_ib x l_b) - omega_ie x (C_nb l_b)   (Groves ch. 2),
    i.e. C_nb (omega_eb x l_b): only the body's rotation relative to the Earth moves the point
    relative to the IMU; the transport rate does not enter.

    Parameters
    ----------
    v_enu : array_like, shape (..., 3)
        IMU velocity relative to the Earth, ENU, m/s.
    q_nb : array_like, shape (..., 4)
        Attitude ENU <- FLU.
    omega_ib_b : array_like, shape (..., 3)
        Body angular rate relative to inertial space (gyro output), FLU, rad/s.
    l_b : array_like, shape (3,) or (..., 3)
        Lever arm, FLU, m.
    lat : float or ndarray
        Latitude, rad (for the Earth rate).

    Returns
    -------
    ndarray, shape (..., 3)
    """
    return _kernels.lever_arm_velocity(v_enu, q_nb, omega_ib_b, l_b, lat, ell.omega)


def point_velocity(v_enu, q_nb, omega_ib_b, l_b, lat, ell: Ellipsoid = WGS84):
    """:func:`lever_arm_velocity` of one point: v_enu, omega_ib_b, l_b float arrays (3,), q_nb
    (4,), lat a float (the navigator's solution; at every fix, without the broadcasting)."""
    out = np.empty(3)
    _kernels.point_velocity(v_enu, q_nb, omega_ib_b, l_b, float(lat), ell.omega, out)
    return out


def lever_arm_velocity_jacobians(q_nb, omega_ib_b, l_b, lat, ell: Ellipsoid = WGS84):
    """Derivatives of :func:`lever_arm_velocity` for the error-state measurement models.

    With the attitude error phi (C_computed = (I - [phi x]) C) and the residual gyro error
    d_omega: d v_point = [C (omega_ib x l) x] phi - [omega_ie x][(C l) x] phi - C [l x] d_omega
    (Groves, eq. 14.122 for ENU; from d(C x) = [(C x) x] phi).

    Parameters
    ----------
    q_nb : array_like, shape (4,)
    omega_ib_b, l_b : array_like, shape (3,)
    lat : float

    Returns
    -------
    d_att, d_gyro : (3, 3) ndarray
        d v_point / d phi and d v_point / d omega.
    """
    q_nb, omega_ib_b, l_b = (np.ascontiguousarray(a, dtype=float)
                             for a in (q_nb, omega_ib_b, l_b))
    return _kernels.lever_arm_velocity_jacobians(q_nb, omega_ib_b, l_b, float(lat), ell.omega)
