"""The contract's bag topics as rclpy messages, built from core values (SI units, radians,
ENU, integer ns stamps): what the simulators and importers write into trial bags."""
from __future__ import annotations

import math

import numpy as np
from geometry_msgs.msg import Quaternion, TwistWithCovarianceStamped, Vector3
from ins_gnss_msgs.msg import Heading, ImuDelta, InsState
from nav_msgs.msg import Odometry
from sensor_msgs.msg import Imu, MagneticField, NavSatFix, NavSatStatus
from std_msgs.msg import Header

from ins_gnss_ros.io.stamps import ns_to_stamp
from ins_gnss_ros.nav.conventions import seed_angles_from_quat


def _vector3(v):
    return Vector3(x=float(v[0]), y=float(v[1]), z=float(v[2]))


def _header(t_ns, frame_id):
    return Header(stamp=ns_to_stamp(t_ns), frame_id=frame_id)


def imu_msg(t_ns, gyro, accel, frame_id="imu_link", orientation=None, orientation_cov=None):
    """sensor_msgs/Imu of raw rates (rad/s) and specific force (m/s^2); with an orientation
    (w, x, y, z: ENU <- sensor, an AHRS's) and the diagonal of its covariance (rad^2), or
    without one (REP-145: covariance -1)."""
    msg = Imu(header=_header(t_ns, frame_id), angular_velocity=_vector3(gyro),
              linear_acceleration=_vector3(accel))
    if orientation is None:
        msg.orientation_covariance[0] = -1.0
    else:
        o = msg.orientation
        o.w, o.x, o.y, o.z = (float(c) for c in orientation)
        msg.orientation_covariance[0::4] = [float(v) for v in orientation_cov]
    return msg


def delta_msg(t_ns, dtheta, dv, dt, frame_id="base_link"):
    """ins_gnss_msgs/ImuDelta over [t - dt, t]."""
    return ImuDelta(header=_header(t_ns, frame_id), delta_angle=_vector3(dtheta),
                    delta_velocity=_vector3(dv), dt=float(dt))


def fix_msg(t_ns, lat, lon, h, cov_enu_diag, frame_id="gnss"):
    """sensor_msgs/NavSatFix (degrees on the wire, as REP/NavSatFix define) with diagonal ENU
    covariance, m^2 (None: COVARIANCE_TYPE_UNKNOWN, as receivers without accuracy output)."""
    msg = NavSatFix(header=_header(t_ns, frame_id), latitude=math.degrees(lat),
                    longitude=math.degrees(lon), altitude=float(h))
    msg.status.status, msg.status.service = NavSatStatus.STATUS_FIX, NavSatStatus.SERVICE_GPS
    if cov_enu_diag is None:
        msg.position_covariance_type = NavSatFix.COVARIANCE_TYPE_UNKNOWN
    else:
        msg.position_covariance[0::4] = [float(c) for c in cov_enu_diag]
        msg.position_covariance_type = NavSatFix.COVARIANCE_TYPE_DIAGONAL_KNOWN
    return msg


def twist_msg(t_ns, linear, cov_diag, frame_id):
    """geometry_msgs/TwistWithCovarianceStamped: velocity (m/s) and its variances ((m/s)^2);
    angular parts unknown (variance -1). NaN marks a component that is not measured."""
    msg = TwistWithCovarianceStamped(header=_header(t_ns, frame_id))
    msg.twist.twist.linear = _vector3(linear)
    cov = [0.0] * 36
    cov[0], cov[7], cov[14] = (float(c) for c in cov_diag)
    cov[21] = cov[28] = cov[35] = -1.0
    msg.twist.covariance = cov
    return msg


def wheel_odom_msg(t_ns, speed, cov_diag, frame_id="odom", child_frame_id="base_link"):
    """nav_msgs/Odometry of a wheel odometry: the forward speed (m/s) in the child frame,
    lateral and vertical zero (the wheels allow no other motion), their variances ((m/s)^2);
    pose and angular rate not provided (variance -1)."""
    msg = Odometry(header=_header(t_ns, frame_id), child_frame_id=child_frame_id)
    msg.twist.twist.linear = _vector3((speed, 0.0, 0.0))
    cov = [0.0] * 36
    cov[0], cov[7], cov[14] = (float(c) for c in cov_diag)
    cov[21] = cov[28] = cov[35] = -1.0
    msg.twist.covariance = cov
    msg.pose.covariance = [-1.0 if i % 7 == 0 else 0.0 for i in range(36)]
    return msg


def mag_msg(t_ns, field_t, variance, frame_id="imu_link"):
    """sensor_msgs/MagneticField, T."""
    msg = MagneticField(header=_header(t_ns, frame_id), magnetic_field=_vector3(field_t))
    msg.magnetic_field_covariance[0::4] = [float(variance)] * 3
    return msg


def ins_state_msg(t_ns, lat, lon, h, v_enu, q_nb, omega_b=None, f_b=None, gyro_bias=None,
                  accel_bias=None):
    """ins_gnss_msgs/InsState (as ins/state and truth/state); unknown vectors are NaN."""
    nan3 = np.full(3, np.nan)
    q = q_nb if q_nb is not None else np.full(4, np.nan)
    msg = InsState(header=_header(t_ns, "map"), latitude=float(lat), longitude=float(lon),
                   altitude=float(h), mode=InsState.MODE_NAVIGATING)
    msg.velocity = _vector3(nan3 if v_enu is None else v_enu)
    msg.orientation = Quaternion(w=float(q[0]), x=float(q[1]), y=float(q[2]), z=float(q[3]))
    msg.angular_velocity = _vector3(nan3 if omega_b is None else omega_b)
    msg.specific_force = _vector3(nan3 if f_b is None else f_b)
    msg.gyro_bias = _vector3(nan3 if gyro_bias is None else gyro_bias)
    msg.accel_bias = _vector3(nan3 if accel_bias is None else accel_bias)
    return msg


def heading_msg(t_ns, q_nb=None, azimuth=None, azimuth_variance=0.0, source=None,
                reference=None, with_tilt=True):
    """ins_gnss_msgs/Heading of attitude ``q_nb`` (azimuth, and pitch/roll if ``with_tilt``) or
    of a bare ``azimuth`` (rad, clockwise from north); defaults: TRUE reference, RECEIVER."""
    msg = Heading(header=_header(t_ns, "base_link"), pitch=math.nan, roll=math.nan,
                  pitch_variance=math.nan, roll_variance=math.nan,
                  reference=Heading.REFERENCE_TRUE if reference is None else reference,
                  source=Heading.SOURCE_RECEIVER if source is None else source,
                  declination=0.0, baseline_length=math.nan, ambiguity_ratio=math.nan,
                  status=Heading.STATUS_FIXED)
    if q_nb is not None:
        azimuth, pitch, roll = (float(a) for a in seed_angles_from_quat(q_nb))
        if with_tilt:
            msg.pitch, msg.roll, msg.pitch_variance, msg.roll_variance = pitch, roll, 0.0, 0.0
    msg.azimuth, msg.azimuth_variance = float(azimuth), float(azimuth_variance)
    return msg
