"""The installation a recording carries: the IMU's mounting and the GNSS antenna's place in
base_link, from the bag's ``/tf_static``.

REP-145 keeps IMU data in the sensor's own frame (``header.frame_id``) and REP-105 places that
frame on the vehicle by a static transform (a URDF through robot_state_publisher, or a
static_transform_publisher); a receiver's fix names its antenna's frame likewise. A replay of
such a recording with a profile that leaves the imu_preprocessor's ``mounting_rpy_deg`` or
the ekf's ``lever_arm`` at zero takes them from there, and says so (a profile that gives them
keeps its own: trial/profile.py, ``profile_with_installation``). This project's base_link
has the IMU at its origin (the imu_preprocessor rotates into base_link, it does not
translate), so the lever arm is the antenna's position minus the IMU's, in base_link axes.
"""
from __future__ import annotations

import numpy as np

from ins_gnss_ros.nav.frame_tree import FrameTree, mounting_rpy_deg
from ins_gnss_ros.trial.inputs import iter_topic

#: The topics whose frames are placed: the IMU's (mounting) and the receiver's (lever arm).
IMU_TOPIC, FIX_TOPIC = "/imu/data_raw", "/gnss/fix"


def static_transforms(bag_path) -> FrameTree:
    """The frames of every transform on the bag's /tf_static."""
    tree = FrameTree()
    for m in iter_topic(bag_path, "/tf_static"):
        tree.add_transforms(m.msg.transforms)
    return tree


def installation(bag_path, base_frame: str, remap=None) -> tuple[dict, dict]:
    """The mounting (``mounting_rpy_deg``: roll, pitch, yaw deg with v_base = Rz Ry Rx v_imu)
    and the antenna's lever arm (``lever_arm``, m) that the bag's /tf_static gives the frames of
    its first imu/data_raw and gnss/fix (``remap``: the bag's topic -> the graph's), where these
    are not ``base_frame``; and, by the same parameter names, the frames it does not place."""
    bag_topic = {to: source for source, to in (remap or {}).items()}
    tree = static_transforms(bag_path)
    found, unplaced = {}, {}
    imu_at = np.zeros(3)  # base_link's origin where the IMU frame is base_link's own
    for topic, name in ((IMU_TOPIC, "mounting_rpy_deg"), (FIX_TOPIC, "lever_arm")):
        frame = _first_frame(bag_path, bag_topic.get(topic, topic))
        if not frame or frame == base_frame:
            continue
        pose = tree.pose_in(base_frame, frame)
        if pose is None:
            unplaced[name] = frame
        elif topic == IMU_TOPIC:
            imu_at = pose[1]
            found[name] = mounting_rpy_deg(pose[0])
        else:
            found[name] = [round(float(x), 6) for x in pose[1] - imu_at]
    return found, unplaced


def _first_frame(bag_path, topic: str) -> str | None:
    """header.frame_id of the bag's first message on topic (None: none there)."""
    m = next(iter_topic(bag_path, topic), None)
    return None if m is None else m.msg.header.frame_id.lstrip("/")
