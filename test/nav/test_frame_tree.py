"""nav/frame_tree.py: poses through a tree of static transforms, as /tf_static gives them."""
from __future__ import annotations

from types import SimpleNamespace as NS

import numpy as np
import pytest

from ins_gnss_ros.nav.frame_tree import FrameTree, mounting_rpy_deg
from ins_gnss_ros.nav.rotations import dcm_from_euler, dcm_to_quat


def transform(parent, child, rpy, xyz):
    """A TransformStamped-like item: child's pose in parent (roll, pitch, yaw rad; m)."""
    w, x, y, z = dcm_to_quat(dcm_from_euler(*rpy))
    return NS(header=NS(frame_id=parent), child_frame_id=child,
              transform=NS(rotation=NS(w=w, x=x, y=y, z=z),
                           translation=NS(x=xyz[0], y=xyz[1], z=xyz[2])))


def test_a_pose_is_composed_through_the_tree_either_way():
    """base_link -> mast (yawed 90 deg, 1 m forward) -> antenna (rolled 180 deg, 2 m along
    the mast's y): the antenna's origin at (1, 0, 0) + Rz(90) (0, 2, 0) = (-1, 0, 0)."""
    tree = FrameTree()
    tree.add_transforms([transform("base_link", "mast", (0.0, 0.0, np.pi / 2), (1.0, 0.0, 0.0)),
                         transform("/mast", "antenna", (np.pi, 0.0, 0.0), (0.0, 2.0, 0.0)),
                         transform("odom", "odom_child", (0.0, 0.0, 0.0), (0.0, 0.0, 0.0))])
    broken = transform("base_link", "nothing", (0.0, 0.0, 0.0), (0.0, 0.0, 0.0))
    broken.transform.rotation.w = 0.0
    tree.add_transforms([broken])  # not a rotation: left out
    yaw, roll = dcm_from_euler(0.0, 0.0, np.pi / 2), dcm_from_euler(np.pi, 0.0, 0.0)
    C, t = tree.pose_in("base_link", "antenna")
    np.testing.assert_allclose(C, yaw @ roll, atol=1e-15)
    np.testing.assert_allclose(t, [-1.0, 0.0, 0.0], atol=1e-15)
    C_back, t_back = tree.pose_in("antenna", "base_link")
    np.testing.assert_allclose(C_back, C.T, atol=1e-15)
    np.testing.assert_allclose(t_back, -C.T @ t, atol=1e-15)
    C_self, t_self = tree.pose_in("mast", "mast")
    np.testing.assert_allclose(C_self, np.eye(3))
    np.testing.assert_allclose(t_self, 0.0)
    assert tree.pose_in("base_link", "odom_child") is None and not tree.places("nothing")
    assert mounting_rpy_deg(C) == pytest.approx([180.0, 0.0, 90.0], abs=1e-9)


def test_the_lever_arm_is_the_antennas_place_less_the_imus():
    """In base_link axes, through a rotated mount; the IMU at base_link's origin where its
    frame is not placed; none for an antenna frame not placed or base_link's own."""
    tree = FrameTree()
    tree.add_transforms([transform("base_link", "mount", (0.0, 0.0, np.pi / 2), (1.0, 0.0, 0.5)),
                         transform("mount", "gps", (0.0, 0.0, 0.0), (0.2, 0.0, 0.3)),
                         transform("base_link", "imu_link", (np.pi, 0.0, 0.0), (0.1, 0.1, 0.0))])
    np.testing.assert_allclose(tree.lever_arm("base_link", "gps", "imu_link"), [0.9, 0.1, 0.8],
                               atol=1e-12)
    np.testing.assert_allclose(tree.lever_arm("base_link", "gps", "unplaced"), [1.0, 0.2, 0.8],
                               atol=1e-12)
    assert tree.lever_arm("base_link", "unplaced", "imu_link") is None
    assert tree.lever_arm("base_link", "base_link", "imu_link") is None
