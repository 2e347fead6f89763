"""tf2_msgs built for the venv (packaging/tf2_msgs) is the tf2_msgs of a full ROS 2 Jazzy install.

Nodes of a full install (rviz, tf2_ros, Nav2) match a topic's type by its RIHS01 type hash, so
the hash our publisher announces must be the published one. The reference value is the
``type_hashes`` entry of ``share/tf2_msgs/msg/TFMessage.json`` as rosidl generates it in a Jazzy
install (/opt/ros/jazzy, tf2_msgs 0.36.4; a copy of that share directory is the public repository
ruredot/opt-ros-jazzy-share, commit 28471ab6622322562a010932b6af1fad60f3e8a7); `ros2 topic info
--verbose /tf` on Jazzy nodes reports the same value.
"""
from __future__ import annotations

import json
import sys

from conftest import REPO

JAZZY_TFMESSAGE_HASH = "RIHS01_e369d0f05a23ae52508854b66f6aa0437f3449d652e8cbf22d5abe85d020f087"
UPSTREAM_DEFINITION = "geometry_msgs/TransformStamped[] transforms\n"  # ros2/geometry2 jazzy


def test_definition_is_upstream():
    msg = REPO / "packaging" / "tf2_msgs" / "interface" / "msg" / "TFMessage.msg"
    assert msg.read_text() == UPSTREAM_DEFINITION


def test_type_hash_on_the_wire_is_jazzy(probe):
    """The hash rmw announces for a /tf publisher (from the built type support)."""
    from tf2_msgs.msg import TFMessage

    probe.create_publisher(TFMessage, "/tf_hash_check", 1)
    (info,) = probe.get_publishers_info_by_topic("/tf_hash_check")
    assert str(info.topic_type_hash) == JAZZY_TFMESSAGE_HASH


def test_generated_type_description_hash_is_jazzy():
    with open(f"{sys.prefix}/share/tf2_msgs/msg/TFMessage.json") as f:
        hashes = {h["type_name"]: h["hash_string"] for h in json.load(f)["type_hashes"]}
    assert hashes["tf2_msgs/msg/TFMessage"] == JAZZY_TFMESSAGE_HASH
