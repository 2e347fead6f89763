"""Message <-> core-type conversions shared by the nodes (no behaviour, only field mapping).

The ``set_*``/``fill_*`` helpers write into the sub-messages a message already has: a generated
message's constructor is plain Python (a few microseconds per sub-message), and ``ins/state`` is
built 200 times a second.
"""

from __future__ import annotations

import math

import numpy as np
from geometry_msgs.msg import Quaternion, Vector3

from ..io import set_stamp_sec, stamp_to_sec
from ..nav.strapdown import NavState


def vec(v: Vector3) -> np.ndarray:
    return np.array([v.x, v.y, v.z])


#: Bounds of a physically possible increment: angular rate (rad/s, ~5700 deg/s) and specific
#: force (m/s^2, ~1000 g), far beyond any navigation IMU's range. A value past them is a corrupt
#: message: integrated, it would wreck the state and the filter's covariance (a 1e12 rad
#: increment made the ekf's innovation covariance non-positive-definite).
MAX_RATE, MAX_SPECIFIC_FORCE = 100.0, 1e4


def increment_problem(msg) -> str | None:
    """Why an ImuDelta cannot be integrated (non-finite, non-positive dt, beyond MAX_RATE or
    MAX_SPECIFIC_FORCE), or None."""
    # Each field read once: a message field is a Python property (checked on every sample).
    a, v, dt = msg.delta_angle, msg.delta_velocity, msg.dt
    ax, ay, az, vx, vy, vz = a.x, a.y, a.z, v.x, v.y, v.z
    if not (math.isfinite(dt) and dt > 0.0
            and all(map(math.isfinite, (ax, ay, az, vx, vy, vz)))):
        return "non-finite or non-positive increment dropped"
    if (math.sqrt(ax * ax + ay * ay + az * az) > MAX_RATE * dt
            or math.sqrt(vx * vx + vy * vy + vz * vz) > MAX_SPECIFIC_FORCE * dt):
        return "implausible increment dropped"
    return None


def held_increments(t: float, dtheta: np.ndarray, dv: np.ndarray, dt: float,
                    interval: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Bridge a gap in the increments: the increment (dtheta, dv) over dt ending at t, its rates
    held over the whole `interval` before t, as increments of about dt each (end stamps, angle
    and velocity increments; shapes (n,), (n, 3), (n, 3)).

    Increments of the usual length, not one long one, so that measurements with epochs inside
    the gap are applied there, against states of the gap.
    """
    n = max(1, round(interval / dt))
    stamps = t - interval + interval / n * np.arange(1, n + 1)
    stamps[-1] = t
    scale = interval / n / dt
    return stamps, np.tile(dtheta * scale, (n, 1)), np.tile(dv * scale, (n, 1))


def to_vector3(a) -> Vector3:
    return Vector3(x=float(a[0]), y=float(a[1]), z=float(a[2]))


def set_vector3(v: Vector3, a: np.ndarray) -> None:
    """Write a 3-vector (numpy array) into an existing Vector3."""
    v.x, v.y, v.z = a.tolist()


def quat(q: Quaternion) -> np.ndarray:
    """ROS quaternion (x, y, z, w fields) -> project array [w, x, y, z]."""
    return np.array([q.w, q.x, q.y, q.z])


def to_quaternion(q) -> Quaternion:
    return Quaternion(w=float(q[0]), x=float(q[1]), y=float(q[2]), z=float(q[3]))


def nav_state_from_msg(msg) -> NavState:
    """ins_gnss_msgs/InsState -> NavState."""
    return NavState(msg.latitude, msg.longitude, msg.altitude, vec(msg.velocity),
                    quat(msg.orientation), stamp_to_sec(msg.header.stamp))


def fill_ins_state(msg, state: NavState) -> None:
    """Write a NavState into an ins_gnss_msgs/InsState (other fields untouched)."""
    set_stamp_sec(msg.header.stamp, state.t)
    msg.latitude, msg.longitude, msg.altitude = float(state.lat), float(state.lon), float(state.h)
    set_vector3(msg.velocity, state.v_enu)
    q = msg.orientation
    q.w, q.x, q.y, q.z = state.q_nb.tolist()
