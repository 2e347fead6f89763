"""Rotations: quaternions, direction cosine matrices, rotation vectors and Euler angles.

Conventions (fixed for the whole project, see also :mod:`ins_gnss_ros.nav.conventions`):

* Quaternions are Hamilton, scalar first: q = [w, x, y, z]. A quaternion ``q_ab`` (or DCM
  ``C_ab``) rotates vectors resolved in frame b into frame a: v_a = q_ab ⊗ v_b ⊗ q_ab*
  = C_ab v_b. Composition: q_ac = q_ab ⊗ q_bc.
* A rotation vector rv (axis times angle, rad) corresponds to q = [cos(|rv|/2),
  sin(|rv|/2) rv/|rv|] (Savage, "Strapdown Analytics", ch. 3).
* Euler angles are ROS-style: C = Rz(yaw) Ry(pitch) Rx(roll), each an active right-handed
  rotation; for C_nb with ENU/FLU this is yaw counter-clockwise from East, pitch nose-down
  positive about the FLU y (left) axis, roll right-wing-down positive about x (forward).

All functions accept stacked inputs with leading dimensions (..., 4), (..., 3) or (..., 3, 3).
"""
from __future__ import annotations

import numpy as np

_SMALL_ANGLE = 1e-4  # rad; below this the series of sin(x/2)/x are exact to double precision


def _components(a):
    """Components along the last axis: Python floats for a single vector, arrays for a stack.

    The per-epoch filter code calls the functions below for single vectors, where arithmetic
    on 0-d arrays costs several times that on floats (same IEEE results).
    """
    return a.tolist() if a.ndim == 1 else [a[..., i] for i in range(a.shape[-1])]


def skew(v) -> np.ndarray:
    """Skew-symmetric cross-product matrix [v×], so that skew(a) @ b = a × b.

    Parameters
    ----------
    v : array_like, shape (..., 3)

    Returns
    -------
    ndarray, shape (..., 3, 3)
    """
    v = np.asarray(v, float)
    x, y, w = _components(v)
    # Filled in place: called for single vectors at every filter epoch, where nested
    # np.stack calls cost several times the arithmetic.
    out = np.zeros(v.shape[:-1] + (3, 3))
    out[..., 0, 1], out[..., 0, 2] = -w, y
    out[..., 1, 0], out[..., 1, 2] = w, -x
    out[..., 2, 0], out[..., 2, 1] = -y, x
    return out


def cross(a, b) -> np.ndarray:
    """Cross product a × b of 3-vectors, shape (..., 3) with broadcasting.

    The same component formula as np.cross, without its axis handling, which dominates the
    cost for the single vectors of the per-epoch filter code.
    """
    a = np.asarray(a, float)
    b = np.asarray(b, float)
    a0, a1, a2 = _components(a)
    b0, b1, b2 = _components(b)
    out = np.empty(np.broadcast_shapes(a.shape, b.shape))
    out[..., 0] = a1 * b2 - a2 * b1
    out[..., 1] = a2 * b0 - a0 * b2
    out[..., 2] = a0 * b1 - a1 * b0
    return out


def quat_mul(p, q) -> np.ndarray:
    """Hamilton product p ⊗ q of scalar-first quaternions, shape (..., 4)."""
    p = np.asarray(p, float)
    q = np.asarray(q, float)
    pw, px, py, pz = p[..., 0], p[..., 1], p[..., 2], p[..., 3]
    qw, qx, qy, qz = q[..., 0], q[..., 1], q[..., 2], q[..., 3]
    return np.stack([pw * qw - px * qx - py * qy - pz * qz,
                     pw * qx + px * qw + py * qz - pz * qy,
                     pw * qy - px * qz + py * qw + pz * qx,
                     pw * qz + px * qy - py * qx + pz * qw], -1)


def quat_conj(q) -> np.ndarray:
    """Conjugate [w, -x, -y, -z] (the inverse of a unit quaternion)."""
    q = np.array(q, float)
    q[..., 1:] *= -1.0
    return q


def quat_normalize(q) -> np.ndarray:
    """Scale to unit norm and choose the representative with w >= 0 (q and -q are the same
    rotation; a canonical sign makes comparisons and rotation vectors unambiguous)."""
    q = np.asarray(q, float)
    q = q / np.linalg.norm(q, axis=-1, keepdims=True)
    return np.where(q[..., :1] < 0.0, -q, q)


def quat_rotate(q, v) -> np.ndarray:
    """Rotate vector(s) v by unit quaternion q: q ⊗ [0, v] ⊗ q*, shape (..., 3).

    Uses the expanded form v + 2w (u × v) + 2 u × (u × v), u = vector part, which costs
    two cross products instead of two quaternion products.
    """
    q = np.asarray(q, float)
    v = np.asarray(v, float)
    u = q[..., 1:]
    t = 2.0 * cross(u, v)
    return v + q[..., :1] * t + cross(u, t)


def quat_from_rotvec(rv) -> np.ndarray:
    """Quaternion of a rotation vector (axis × angle, rad), exact.

    For |rv| < 1e-4 rad the Taylor series sin(x/2)/x = 1/2 - x^2/48 + x^4/3840 and
    cos(x/2) = 1 - x^2/8 + x^4/384 avoid dividing by a vanishing angle.

    Parameters
    ----------
    rv : array_like, shape (..., 3)

    Returns
    -------
    ndarray, shape (..., 4)
    """
    rv = np.asarray(rv, float)
    a2 = np.sum(rv * rv, axis=-1)
    a = np.sqrt(a2)
    small = a < _SMALL_ANGLE
    a_safe = np.where(small, 1.0, a)
    k = np.where(small, 0.5 - a2 / 48.0 + a2 * a2 / 3840.0, np.sin(0.5 * a_safe) / a_safe)
    w = np.where(small, 1.0 - a2 / 8.0 + a2 * a2 / 384.0, np.cos(0.5 * a_safe))
    return np.concatenate([w[..., None], k[..., None] * rv], axis=-1)


def quat_to_rotvec(q) -> np.ndarray:
    """Rotation vector (rad) of a unit quaternion, with angle in [0, pi].

    angle = 2 atan2(|u|, w) after choosing w >= 0; for |u| small the ratio angle/|u| is
    expanded as 2/w (1 - |u|^2/(3 w^2)), accurate to O(|u|^4).
    """
    q = quat_normalize(q)
    w = q[..., 0]
    u = q[..., 1:]
    n = np.linalg.norm(u, axis=-1)
    small = n < _SMALL_ANGLE
    n_safe = np.where(small, 1.0, n)
    scale = np.where(small, 2.0 / w * (1.0 - n * n / (3.0 * w * w)),
                     2.0 * np.arctan2(n_safe, w) / n_safe)
    return scale[..., None] * u


def quat_to_dcm(q) -> np.ndarray:
    """Direction cosine matrix of a unit quaternion: C v = q ⊗ v ⊗ q* (Savage ch. 3).

    Returns
    -------
    ndarray, shape (..., 3, 3)
    """
    q = np.asarray(q, float)
    w, x, y, z = _components(q)
    C = np.empty(q.shape[:-1] + (3, 3))  # filled in place, as in skew()
    C[..., 0, 0] = w * w + x * x - y * y - z * z
    C[..., 0, 1] = 2 * (x * y - w * z)
    C[..., 0, 2] = 2 * (x * z + w * y)
    C[..., 1, 0] = 2 * (x * y + w * z)
    C[..., 1, 1] = w * w - x * x + y * y - z * z
    C[..., 1, 2] = 2 * (y * z - w * x)
    C[..., 2, 0] = 2 * (x * z - w * y)
    C[..., 2, 1] = 2 * (y * z + w * x)
    C[..., 2, 2] = w * w - x * x - y * y + z * z
    return C


def dcm_to_quat(C) -> np.ndarray:
    """Unit quaternion (w >= 0) of a rotation matrix, Shepperd's method.

    The component with the largest magnitude is computed from the trace/diagonal first and the
    others from off-diagonal sums, so that no division by a near-zero number occurs
    (Savage ch. 3).
    """
    C = np.asarray(C, float)
    shape = C.shape[:-2]
    C = C.reshape(-1, 3, 3)
    tr = np.trace(C, axis1=-2, axis2=-1)
    diag = np.stack([tr, C[:, 0, 0], C[:, 1, 1], C[:, 2, 2]], -1)
    # 4 q_i^2 = 1 + 2 C_ii - tr  (i = x, y, z),  4 w^2 = 1 + tr
    cand = np.stack([1.0 + tr, 1.0 + 2 * diag[:, 1] - tr, 1.0 + 2 * diag[:, 2] - tr,
                     1.0 + 2 * diag[:, 3] - tr], -1)
    i = np.argmax(cand, axis=-1)
    out = np.empty((C.shape[0], 4))
    s = 2.0 * np.sqrt(cand[np.arange(C.shape[0]), i])  # = 4 |q_i|
    d21, d02, d10 = C[:, 2, 1] - C[:, 1, 2], C[:, 0, 2] - C[:, 2, 0], C[:, 1, 0] - C[:, 0, 1]
    s01, s02, s12 = C[:, 0, 1] + C[:, 1, 0], C[:, 0, 2] + C[:, 2, 0], C[:, 1, 2] + C[:, 2, 1]
    rows = {
        0: np.stack([s / 4, d21 / s, d02 / s, d10 / s], -1),
        1: np.stack([d21 / s, s / 4, s01 / s, s02 / s], -1),
        2: np.stack([d02 / s, s01 / s, s / 4, s12 / s], -1),
        3: np.stack([d10 / s, s02 / s, s12 / s, s / 4], -1),
    }
    for k, r in rows.items():
        m = i == k
        out[m] = r[m]
    return quat_normalize(out).reshape(shape + (4,))


def quat_from_euler(roll, pitch, yaw) -> np.ndarray:
    """Quaternion of ROS-style Euler angles, C = Rz(yaw) Ry(pitch) Rx(roll), rad."""
    roll, pitch, yaw = np.broadcast_arrays(np.asarray(roll, float), np.asarray(pitch, float),
                                           np.asarray(yaw, float))
    cr, sr = np.cos(0.5 * roll), np.sin(0.5 * roll)
    cp, sp = np.cos(0.5 * pitch), np.sin(0.5 * pitch)
    cy, sy = np.cos(0.5 * yaw), np.sin(0.5 * yaw)
    # q = qz(yaw) ⊗ qy(pitch) ⊗ qx(roll), expanded.
    return np.stack([cy * cp * cr + sy * sp * sr,
                     cy * cp * sr - sy * sp * cr,
                     cy * sp * cr + sy * cp * sr,
                     sy * cp * cr - cy * sp * sr], -1)


def dcm_from_euler(roll, pitch, yaw) -> np.ndarray:
    """Rotation matrix Rz(yaw) Ry(pitch) Rx(roll) of ROS-style Euler angles, shape (..., 3, 3)."""
    return quat_to_dcm(quat_from_euler(roll, pitch, yaw))


def quat_to_euler(q):
    """ROS-style Euler angles (roll, pitch, yaw), rad, of a unit quaternion.

    roll, yaw in (-pi, pi], pitch in [-pi/2, pi/2]. At pitch = ±pi/2 (gimbal lock) only
    yaw ∓ roll is defined: when cos(pitch) < 1e-8 roll is set to 0 and yaw is taken from the
    C[0,1], C[1,1] elements, which then depend on that combination only. Either branch
    reproduces the rotation to ~1e-8 rad.
    """
    C = quat_to_dcm(q)
    cos_pitch = np.hypot(C[..., 2, 1], C[..., 2, 2])
    lock = cos_pitch < 1e-8
    roll = np.where(lock, 0.0, np.arctan2(C[..., 2, 1], C[..., 2, 2]))
    pitch = np.arctan2(-C[..., 2, 0], cos_pitch)
    yaw = np.where(lock, np.arctan2(-C[..., 0, 1], C[..., 1, 1]),
                   np.arctan2(C[..., 1, 0], C[..., 0, 0]))
    return roll, pitch, yaw


def quat_angle_between(q1, q2):
    """Angle (rad, in [0, pi]) of the rotation taking q1 to q2, i.e. of q1* ⊗ q2."""
    d = quat_mul(quat_conj(q1), q2)
    return 2.0 * np.arctan2(np.linalg.norm(d[..., 1:], axis=-1), np.abs(d[..., 0]))
