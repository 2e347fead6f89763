"""Message <-> core-type conversions shared by the nodes (no behaviour, only field mapping).

The ``set_*``/``fill_*`` helpers write into the sub-messages a message already has: a generated
message's constructor is plain Python (a few microseconds per sub-message), and ``ins/state`` is
built 200 times a second.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np
from geometry_msgs.msg import Quaternion, Vector3
from ins_gnss_msgs.msg import Heading, InsState

from ..io import NS, encode_columns, field_reader, field_writer, sec_nanosec, set_stamp_sec, \
    stamp_to_sec
from ..nav.increments import SensorErrors, increment_problem
from ..nav.modes import ALIGNING, DEAD_RECKONING, INVALID, NAVIGATING
from ..nav.strapdown import NavState

#: Mode (:mod:`..nav.modes`) -> the MODE_* value of InsState, FilterStatus and InsCorrection (the
#: same values, test/test_messages.py; InsCorrection has no INVALID).
MODE_VALUES = {ALIGNING: InsState.MODE_ALIGNING, NAVIGATING: InsState.MODE_NAVIGATING,
               DEAD_RECKONING: InsState.MODE_DEAD_RECKONING, INVALID: InsState.MODE_INVALID}


def vec(v: Vector3) -> np.ndarray:
    return np.array([v.x, v.y, v.z])


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


def ins_state_payloads(stamp_ns, lat, lon, h, v_enu, q_nb, mode, angular_velocity=0.0,
                       errors: SensorErrors | None = None, correction_sequence: int = 1) -> list:
    """CDR payloads of k ins_gnss_msgs/InsState (frame "map") at once, the fields
    :func:`fill_ins_state` and the sensor-error fields hold: stamps (ns), lat, lon, h (k,),
    v_enu (k, 3), q_nb (k, 4), mode (k,) InsState modes or one for all, angular_velocity
    (k, 3) or zero, ``errors`` of (k, 3) arrays or None (zero); specific force zero."""
    sec, nanosec = np.divmod(np.asarray(stamp_ns, np.int64), NS)
    columns = {"header.stamp.sec": sec, "header.stamp.nanosec": nanosec, "latitude": lat,
               "longitude": lon, "altitude": h, "mode": mode,
               "correction_sequence": correction_sequence}
    fields = {"velocity": v_enu, "angular_velocity": angular_velocity,
              "specific_force": 0.0, "gyro_bias": 0.0, "accel_bias": 0.0,
              "gyro_scale_factor": 0.0, "accel_scale_factor": 0.0}
    if errors is not None:
        fields.update(gyro_bias=errors.gyro_bias, accel_bias=errors.accel_bias,
                      gyro_scale_factor=errors.gyro_scale, accel_scale_factor=errors.accel_scale)
    for name, value in fields.items():
        value = np.asarray(value, float)
        for k, axis in enumerate("xyz"):
            columns[f"{name}.{axis}"] = value[..., k] if value.ndim else value
    for k, axis in enumerate("wxyz"):
        columns["orientation." + axis] = q_nb[:, k]
    return encode_columns("ins_gnss_msgs/msg/InsState", columns, {"header.frame_id": "map"})


_write_ins_state = field_writer("ins_gnss_msgs/msg/InsState", ("map",))


def ins_state_payload(state: NavState, angular_velocity, specific_force,
                      errors: SensorErrors, mode: int, correction_sequence: int) -> bytes:
    """CDR payload of one ins_gnss_msgs/InsState (frame "map"): the fields
    :func:`fill_ins_state` writes, the rates (three floats each) and the applied sensor
    errors, ``mode`` an InsState mode; the bytes the message object would encode to."""
    w, x, y, z = state.q_nb.tolist()
    return _write_ins_state(
        *sec_nanosec(state.t), float(state.lat), float(state.lon), float(state.h),
        *state.v_enu.tolist(), x, y, z, w, *angular_velocity, *specific_force, *errors.values,
        mode, correction_sequence)


_read_delta = field_reader("ins_gnss_msgs/msg/ImuDelta", (
    "header.stamp.sec", "header.stamp.nanosec", "delta_angle.x", "delta_angle.y",
    "delta_angle.z", "delta_velocity.x", "delta_velocity.y", "delta_velocity.z", "dt",
    "bridged_angle_variance", "bridged_velocity_variance"))


class Increment(NamedTuple):
    """An ins_gnss_msgs/ImuDelta as its readers take it (:func:`increment_of`)."""

    problem: str | None   # why it cannot be integrated (increment_problem), None if it can
    t: float              # stamp, s (as stamp_to_sec)
    t_ns: int             # stamp, ns
    dtheta: np.ndarray
    dv: np.ndarray
    dt: float
    angle_var: float      # bridged_angle_variance, rad^2
    velocity_var: float   # bridged_velocity_variance, (m/s)^2


def increment_of(data: bytes) -> Increment:
    """The increment in the CDR payload of an ins_gnss_msgs/ImuDelta, read by field.

    Raises
    ------
    ins_gnss_ros.io.CdrLayoutError
        Not a payload of that type.
    """
    sec, nanosec, ax, ay, az, vx, vy, vz, dt, angle_var, velocity_var = _read_delta(data)
    dtheta, dv = (ax, ay, az), (vx, vy, vz)
    problem = increment_problem(dtheta, dv, dt)
    if problem is None and not (0.0 <= angle_var < math.inf and 0.0 <= velocity_var < math.inf):
        problem = "increment with a negative or non-finite bridged variance dropped"
    return Increment(problem, sec + nanosec * 1e-9, sec * NS + nanosec, np.array(dtheta),
                     np.array(dv), dt, angle_var, velocity_var)


def compass_heading(reading, stamp, frame_id: str, true_reference: bool) -> Heading:
    """``mag/heading`` of a :class:`~ins_gnss_ros.magnetic.compass.CompassReading` at
    ``stamp`` (builtin_interfaces/Time): its true or magnetic azimuth with the declination
    either way; a compass observes neither pitch nor roll (NaN)."""
    out = Heading(azimuth=reading.true_azimuth if true_reference else reading.magnetic_azimuth,
                  pitch=math.nan, roll=math.nan, azimuth_variance=reading.variance,
                  pitch_variance=math.nan, roll_variance=math.nan,
                  reference=Heading.REFERENCE_TRUE if true_reference
                  else Heading.REFERENCE_MAGNETIC,
                  source=Heading.SOURCE_MAGNETIC, declination=reading.declination,
                  status=Heading.STATUS_NONE)
    out.header.stamp = stamp
    out.header.frame_id = frame_id
    return out


def heading_of(msg) -> tuple[float, float, float, float | None] | None:
    """An ins_gnss_msgs/Heading as the aiding front end takes it: (stamp s, azimuth rad,
    variance rad^2, declination rad or None for a true azimuth; NaN: unknown to the publisher),
    or None for a phase-difference or receiver heading without a solution (STATUS_NONE)."""
    if msg.status == msg.STATUS_NONE and msg.source in (msg.SOURCE_PHASE_DIFFERENCE,
                                                        msg.SOURCE_RECEIVER):
        return None
    declination = msg.declination if msg.reference == msg.REFERENCE_MAGNETIC else None
    return stamp_to_sec(msg.header.stamp), msg.azimuth, msg.azimuth_variance, declination


def sensor_errors_of(msg) -> SensorErrors:
    """The sensor-error fields of an ins_gnss_msgs/InsState or InsCorrection (gyro_bias,
    accel_bias, gyro_scale_factor, accel_scale_factor)."""
    return SensorErrors(vec(msg.gyro_bias), vec(msg.accel_bias), vec(msg.gyro_scale_factor),
                        vec(msg.accel_scale_factor))
