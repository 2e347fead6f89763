"""Static frames as ROS publishes them on ``/tf_static`` (REP-105): a tree of rigid transforms
between named frames, and the pose of one frame in another through it.

A robot's URDF (through robot_state_publisher) or a static_transform_publisher places each
sensor frame on the vehicle; REP-145 keeps IMU data in the sensor's frame, so its mounting in
base_link is such a pose. Used by the imu_preprocessor node (the mounting of a live IMU), the
ekf node (the antenna's lever arm) and the replays (trial/installation.py).
"""
from __future__ import annotations

import numpy as np

from .rotations import dcm_to_quat, quat_to_dcm, quat_to_euler


class FrameTree:
    """Child frame -> (parent frame, C_parent_child, child's origin in the parent)."""

    def __init__(self):
        self._parents: dict[str, tuple[str, np.ndarray, np.ndarray]] = {}

    def add_transforms(self, transforms) -> None:
        """geometry_msgs/TransformStamped-like items (``header.frame_id``, ``child_frame_id``,
        ``transform.rotation`` / ``.translation``); a later one of a child replaces an earlier,
        one whose quaternion is not a rotation (e.g. all zeros) is left out. Frame names are
        taken without a leading '/'."""
        for tf in transforms:
            r, t = tf.transform.rotation, tf.transform.translation
            q = np.array([r.w, r.x, r.y, r.z], float)
            norm = np.linalg.norm(q)
            if not abs(norm - 1.0) < 1e-3:
                continue
            self._parents[tf.child_frame_id.lstrip("/")] = (
                tf.header.frame_id.lstrip("/"), quat_to_dcm(q / norm),
                np.array([t.x, t.y, t.z], float))

    def places(self, child: str) -> bool:
        """Whether a transform gives ``child`` a parent."""
        return child in self._parents

    def pose_in(self, frame: str, child: str):
        """(C_frame_child, the position of child's origin in frame) through the tree, or None
        when the two frames are not connected."""
        ups = {name: (C, t) for name, C, t in self._to_root(child)}
        for name, C_nf, t_nf in self._to_root(frame):
            if name in ups:  # the lowest common ancestor
                C_nc, t_nc = ups[name]
                return C_nf.T @ C_nc, C_nf.T @ (t_nc - t_nf)
        return None

    def lever_arm(self, base: str, antenna: str, imu: str):
        """The place of frame ``antenna`` in ``base`` less that of frame ``imu`` (``base``'s
        origin where the IMU's frame is empty, ``base`` or not placed): the GNSS lever arm of
        this project's base_link, which has the IMU at its origin (the imu_preprocessor rotates
        into base_link, it does not translate). None where ``antenna`` is empty, ``base`` or not
        placed."""
        if not antenna or antenna == base:
            return None
        pose = self.pose_in(base, antenna)
        if pose is None:
            return None
        imu_pose = self.pose_in(base, imu) if imu else None
        return pose[1] if imu_pose is None else pose[1] - imu_pose[1]

    def _to_root(self, name: str) -> list:
        """[(frame, C_frame_name, name's origin in frame)] from name up to its root."""
        chain, C, t, seen = [(name, np.eye(3), np.zeros(3))], np.eye(3), np.zeros(3), {name}
        while name in self._parents:
            parent, C_pc, t_pc = self._parents[name]
            if parent in seen:  # a loop in a damaged tree
                break
            seen.add(parent)
            # v_parent = C_pc v_child + t_pc, composed onto what is below
            C, t = C_pc @ C, C_pc @ t + t_pc
            name = parent
            chain.append((name, C, t))
        return chain


def mounting_rpy_deg(C) -> list:
    """Roll, pitch, yaw (deg) of C = Rz(yaw) Ry(pitch) Rx(roll): the imu_preprocessor's
    ``mounting_rpy_deg`` of an IMU frame whose pose in base_link is C."""
    return [round(float(a), 6) for a in np.degrees(quat_to_euler(dcm_to_quat(C)))]
