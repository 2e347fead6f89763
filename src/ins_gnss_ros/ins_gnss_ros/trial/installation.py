"""The installation a recording carries: the IMU's mounting and the GNSS antenna's place in
base_link, from the bag's ``/tf_static``.

REP-145 keeps IMU data in the sensor's own frame (``header.frame_id``) and REP-105 places that
frame on the vehicle by a static transform (a URDF through robot_state_publisher, or a
static_transform_publisher); a receiver's fix names its antenna's frame likewise. A replay of
such a recording with a profile that leaves the imu_preprocessor's ``mounting_rpy_deg`` or
the ekf's ``lever_arm`` at zero takes them from there, and says so (a profile that gives them
keeps its own: trial/profile.py, ``profile_with_installation``). The lever arm is the
antenna's position less the IMU's (``FrameTree.lever_arm``), as the ekf node takes it live.
"""
from __future__ import annotations

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
    imu, fix = (_first_frame(bag_path, bag_topic.get(topic, topic))
                for topic in (IMU_TOPIC, FIX_TOPIC))
    found, unplaced = {}, {}
    if imu and imu != base_frame:
        pose = tree.pose_in(base_frame, imu)
        if pose is None:
            unplaced["mounting_rpy_deg"] = imu
        else:
            found["mounting_rpy_deg"] = mounting_rpy_deg(pose[0])
    if fix and fix != base_frame:
        lever = tree.lever_arm(base_frame, fix, imu)
        if lever is None:
            unplaced["lever_arm"] = fix
        else:
            found["lever_arm"] = [round(float(x), 6) for x in lever]
    return found, unplaced


def _first_frame(bag_path, topic: str) -> str | None:
    """header.frame_id of the bag's first message on topic (None: none there)."""
    m = next(iter_topic(bag_path, topic), None)
    return None if m is None else m.msg.header.frame_id.lstrip("/")
