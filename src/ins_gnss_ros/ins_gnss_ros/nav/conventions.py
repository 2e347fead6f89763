"""Frame and angle conventions: the ONE place where conventions are converted.

Project conventions
-------------------
* Navigation frame: ENU (x East, y North, z Up), REP-103.
* Body frame: FLU (x forward, y left, z up), ROS ``base_link``.
* Attitude: Hamilton quaternion [w, x, y, z], ``q_nb`` rotates FLU body vectors into ENU.
* Euler angles (ROS): C_nb = Rz(yaw) Ry(pitch) Rx(roll); yaw counter-clockwise from East,
  pitch positive nose DOWN (rotation about the left axis), roll positive right wing down.
* Azimuth / heading (seeds, ``ins_gnss_msgs/Heading``, compasses): clockwise from North in
  [0, 2 pi): azimuth = pi/2 - yaw, wrapped.

Seeds' conventions (seed 001 B2.10, seed 004 section 2.1)
---------------------------------------------------------
* Body "RFU": x to starboard (right), y forward, z up. FLU = (y_rfu, -x_rfu, z_rfu).
* Angles: heading K (psi) clockwise from North, pitch (theta) positive nose UP, roll (gamma)
  positive right wing DOWN, with C_n,rfu = R_up(-K) R_x(theta) R_y(gamma) (seed 001 B2.10, whose
  error formulas were checked numerically for exactly this factorisation).
* Equivalent ROS angles: yaw = pi/2 - K, pitch = -theta, roll = gamma, because
  R_up(-K) R_x(theta) R_y(gamma) M^T = Rz(pi/2 - K) Ry(-theta) Rx(gamma) with M = Rz(-pi/2) the
  RFU -> FLU axis permutation.

Aerospace / marine conventions (recorded data)
----------------------------------------------
* NED navigation frame (x North, y East, z Down) and FRD body (x forward, y right, z down), with
  C_ned,frd = Rz(yaw) Ry(pitch) Rx(roll): yaw clockwise from North, pitch nose up, roll right
  wing down (the vessel data set is NED with angles in degrees, the car data body is FRD).
* ENU = P NED with P = [[0,1,0],[1,0,0],[0,0,-1]] (a 180 deg turn about (N+E)/sqrt(2));
  FLU = F FRD with F = diag(1,-1,-1) (a 180 deg turn about x). Both are self-inverse, so
  C_enu,flu = P C_ned,frd F and the angles map as yaw_enu = pi/2 - yaw_ned, pitch_enu =
  -pitch_ned, roll_enu = roll_ned.

All angles are radians; the conversion to/from degrees belongs to the importers.
"""
from __future__ import annotations

import math

import numpy as np

from .rotations import quat_from_euler, quat_mul, quat_normalize, quat_to_euler

# 180 deg about (x + y)/sqrt(2): NED <-> ENU;  180 deg about x: FRD <-> FLU.
_Q_ENU_NED = np.array([0.0, np.sqrt(0.5), np.sqrt(0.5), 0.0])
_Q_FRD_FLU = np.array([0.0, 1.0, 0.0, 0.0])


def wrap_pi(angle):
    """Wrap angle(s) to [-pi, pi), rad."""
    if isinstance(angle, float):
        # One angle (every heading update): Python's float remainder is numpy's (fmod, then
        # the divisor's sign), without numpy's per-call cost on a scalar.
        return np.float64((angle + math.pi) % (2.0 * math.pi) - math.pi)
    return (np.asarray(angle) + np.pi) % (2.0 * np.pi) - np.pi


def wrap_2pi(angle):
    """Wrap angle(s) to [0, 2 pi), rad."""
    if isinstance(angle, float):
        return np.float64(angle % (2.0 * math.pi))  # one angle: as in wrap_pi
    return np.asarray(angle) % (2.0 * np.pi)


def azimuth_from_yaw(yaw):
    """Azimuth (clockwise from North, [0, 2 pi)) from ENU yaw (counter-clockwise from East)."""
    return wrap_2pi(0.5 * np.pi - (yaw if isinstance(yaw, float) else np.asarray(yaw)))


def yaw_from_azimuth(azimuth):
    """ENU yaw ([-pi, pi), counter-clockwise from East) from azimuth (clockwise from North)."""
    return wrap_pi(0.5 * np.pi - np.asarray(azimuth))


def rfu_to_flu(v):
    """Seeds' body vector(s) (x starboard, y forward, z up) to FLU, shape (..., 3)."""
    v = np.asarray(v, float)
    return np.stack([v[..., 1], -v[..., 0], v[..., 2]], -1)


def flu_to_rfu(v):
    """FLU body vector(s) to the seeds' RFU axes (x starboard, y forward, z up)."""
    v = np.asarray(v, float)
    return np.stack([-v[..., 1], v[..., 0], v[..., 2]], -1)


def quat_from_seed_angles(heading, pitch, roll):
    """q_nb (ENU <- FLU) from the seeds' heading (clockwise from North), pitch (nose up) and
    roll (right wing down), rad."""
    return quat_from_euler(roll, -np.asarray(pitch), 0.5 * np.pi - np.asarray(heading))


def seed_angles_from_quat(q_nb):
    """The seeds' (heading in [0, 2 pi), pitch nose up, roll right wing down), rad, of q_nb."""
    roll, pitch, yaw = quat_to_euler(q_nb)
    return azimuth_from_yaw(yaw), -pitch, roll


def ned_to_enu(v):
    """NED vector(s) to ENU (also ENU to NED: the permutation is its own inverse)."""
    v = np.asarray(v, float)
    return np.stack([v[..., 1], v[..., 0], -v[..., 2]], -1)


def frd_to_flu(v):
    """FRD body vector(s) to FLU (also FLU to FRD)."""
    v = np.asarray(v, float)
    return np.stack([v[..., 0], -v[..., 1], -v[..., 2]], -1)


enu_to_ned = ned_to_enu
flu_to_frd = frd_to_flu


def quat_ned_frd_to_enu_flu(q_ned_frd):
    """q_enu,flu = q_P ⊗ q_ned,frd ⊗ q_F (P, F the axis flips of the module docstring)."""
    return quat_normalize(quat_mul(quat_mul(_Q_ENU_NED, q_ned_frd), _Q_FRD_FLU))


def quat_enu_flu_to_ned_frd(q_enu_flu):
    """Inverse of :func:`quat_ned_frd_to_enu_flu` (both flips are self-inverse)."""
    return quat_ned_frd_to_enu_flu(q_enu_flu)


def euler_ned_to_enu(roll, pitch, yaw):
    """NED/FRD (roll, pitch, yaw) -> ENU/FLU ROS (roll, pitch, yaw), rad; yaw wrapped to
    [-pi, pi)."""
    return (np.asarray(roll, float), -np.asarray(pitch, float),
            wrap_pi(0.5 * np.pi - np.asarray(yaw)))


def euler_enu_to_ned(roll, pitch, yaw):
    """ENU/FLU ROS (roll, pitch, yaw) -> NED/FRD (roll, pitch, yaw), rad; yaw in [0, 2 pi)."""
    return (np.asarray(roll, float), -np.asarray(pitch, float),
            wrap_2pi(0.5 * np.pi - np.asarray(yaw)))
