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

from ins_gnss_ros.nav.rotations import dcm_to_quat, quat_to_dcm, quat_to_euler
from ins_gnss_ros.trial.inputs import iter_topic

#: The topics whose frames are placed: the IMU's (mounting) and the receiver's (lever arm).
IMU_TOPIC, FIX_TOPIC = "/imu/data_raw", "/gnss/fix"


def static_transforms(bag_path) -> dict:
    """Child frame -> (parent frame, C_parent_child (3, 3), translation in the parent (3,)) of
    every transform on the bag's /tf_static (a later one of a child replaces an earlier; one
    whose quaternion is not a rotation, e.g. all zeros, is left out)."""
    tree = {}
    for m in iter_topic(bag_path, "/tf_static"):
        for tf in m.msg.transforms:
            r, t = tf.transform.rotation, tf.transform.translation
            q = np.array([r.w, r.x, r.y, r.z])
            norm = np.linalg.norm(q)
            if not abs(norm - 1.0) < 1e-3:
                continue
            tree[tf.child_frame_id.lstrip("/")] = (
                tf.header.frame_id.lstrip("/"), quat_to_dcm(q / norm), np.array([t.x, t.y, t.z]))
    return tree


def pose_in(tree: dict, frame: str, child: str):
    """(C_frame_child, position of child's origin in frame) through the tree, or None when the
    two frames are not connected."""
    def to_root(name):
        """[(name, C_root_name, t)] from name up to its root."""
        chain, C, t, seen = [(name, np.eye(3), np.zeros(3))], np.eye(3), np.zeros(3), {name}
        while name in tree:
            parent, C_pc, t_pc = tree[name]
            if parent in seen:  # a loop in a damaged tree
                break
            seen.add(parent)
            # v_parent = C_pc v_child + t_pc, composed onto what is below
            C, t = C_pc @ C, C_pc @ t + t_pc
            name = parent
            chain.append((name, C, t))
        return chain

    ups = {name: (C, t) for name, C, t in to_root(child)}
    for name, C_nf, t_nf in to_root(frame):
        if name in ups:  # the lowest common ancestor
            C_nc, t_nc = ups[name]
            return C_nf.T @ C_nc, C_nf.T @ (t_nc - t_nf)
    return None


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
        pose = pose_in(tree, base_frame, frame)
        if pose is None:
            unplaced[name] = frame
        elif topic == IMU_TOPIC:
            imu_at = pose[1]
            found[name] = [round(float(a), 6) for a in
                           np.degrees(quat_to_euler(dcm_to_quat(pose[0])))]
        else:
            found[name] = [round(float(x), 6) for x in pose[1] - imu_at]
    return found, unplaced


def _first_frame(bag_path, topic: str) -> str | None:
    """header.frame_id of the bag's first message on topic (None: none there)."""
    m = next(iter_topic(bag_path, topic), None)
    return None if m is None else m.msg.header.frame_id.lstrip("/")
