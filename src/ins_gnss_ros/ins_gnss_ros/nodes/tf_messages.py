"""TF (REP-105) of the navigation solution and of the sensors' mounting, as tf2_msgs/TFMessage.

``/tf`` carries ``map -> base_link`` from the filter's solution (the ``ekf`` node and the offline
replay build it here alike); ``/tf_static`` carries ``base_link -> imu_link`` (the IMU mounting,
``imu_preprocessor``) and ``base_link -> gnss_0`` (the antenna lever arm, ``ekf``). base_link
is the navigation centre, i.e. the IMU: the IMU frame differs from it by the mounting rotation
only. Once wheel odometry is fused (``use_wheel_odometry``) the solution's chain is
``map -> odom -> base_link`` (REP-105: odom continuous, map -> odom absorbing the GNSS
corrections; nav/odom_frame.py); ``odom_frame`` names it.
"""
from __future__ import annotations

from geometry_msgs.msg import TransformStamped
from tf2_msgs.msg import TFMessage

from ..nav.local_frame import to_map
from ..nav.rotations import dcm_to_quat
from ..params import Param

#: Frame parameters of the ekf node (and of the ekf section the offline replay reads).
FRAME_PARAMS = (
    Param("publish_tf", True, "publish map_frame -> base_link_frame on /tf (the solution) and "
          "base_link_frame -> gnss_frame (lever_arm) on /tf_static"),
    Param("map_frame", "map", "ENU frame around the datum: nav/odom's frame, the root on /tf"),
    Param("odom_frame", "odom", "continuous frame between map and base_link once wheel "
          "odometry is fused (REP-105); without it map -> base_link is published"),
    Param("base_link_frame", "base_link", "the vehicle frame (FLU) at the navigation centre "
          "(the IMU): nav/odom's child frame"),
    Param("gnss_frame", "gnss_0", "frame of the GNSS antenna at lever_arm, on /tf_static"),
)

#: Frame parameters of the imu_preprocessor node (its frame_id is the parent).
IMU_FRAME_PARAMS = (
    Param("publish_tf", True, "publish frame_id -> imu_frame (the mounting) on /tf_static"),
    Param("imu_frame", "imu_link", "the IMU's sensor frame, rotated into frame_id by the mounting"),
)


def transform(stamp, parent: str, child: str, translation, q_wxyz) -> TransformStamped:
    """The transform of ``child`` in ``parent``: a point p in child is
    ``q p q* + translation`` in parent (m; Hamilton quaternion [w, x, y, z])."""
    tf = TransformStamped()
    tf.header.stamp, tf.header.frame_id, tf.child_frame_id = stamp, parent, child
    t, r = tf.transform.translation, tf.transform.rotation
    t.x, t.y, t.z = (float(v) for v in translation)
    r.w, r.x, r.y, r.z = (float(v) for v in q_wxyz)
    return tf


def solution_tf(stamp, st, datum, map_frame: str, base_frame: str, odom=None) -> TFMessage:
    """/tf of a NavState: base_link in the map frame around ``datum`` (lat rad, lon rad, h m),
    the pose nav/odom carries; with ``odom`` = (odom frame, :class:`~ins_gnss_ros.nav.odom_frame.OdomTrack`)
    the chain map -> odom -> base_link of the same pose, odom -> base_link continuous."""
    position = to_map(datum, st.lat, st.lon, st.h)
    if odom is None:
        return TFMessage(transforms=[transform(stamp, map_frame, base_frame, position, st.q_nb)])
    odom_frame, track = odom
    p_odom = track.advance(st.t, position, st.v_enu)
    return TFMessage(transforms=[
        transform(stamp, map_frame, odom_frame, position - p_odom, (1.0, 0.0, 0.0, 0.0)),
        transform(stamp, odom_frame, base_frame, p_odom, st.q_nb)])


def static_tf(stamp, parent: str, children) -> TFMessage:
    """/tf_static of ``children``: (frame, translation m, rotation DCM parent <- child)."""
    return TFMessage(transforms=[transform(stamp, parent, child, translation, dcm_to_quat(c))
                                 for child, translation, c in children])
