"""Shared pytest fixtures: an isolated ROS graph per test process, node runners, data paths, bags.

Every test process gets its own ``ROS_DOMAIN_ID`` and local-only discovery *before* rclpy is
initialised, so parallel CI jobs or a developer's running system never see each other's traffic.
"""

from __future__ import annotations

import os
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
SHARED = REPO.parent / "shared"

os.environ["ROS_AUTOMATIC_DISCOVERY_RANGE"] = "LOCALHOST"
# Domain ids 1..100 are free of the ports other ids use; spread processes over them by pid.
os.environ.setdefault("ROS_DOMAIN_ID", str(1 + os.getpid() % 100))
os.environ.setdefault("AMENT_PREFIX_PATH", os.environ.get("VIRTUAL_ENV", str(REPO / ".venv")))


def shared_path(*parts: str) -> Path:
    """Path into ``../shared`` (recorded data); skips the calling test when it is absent."""
    path = SHARED.joinpath(*parts)
    if not path.exists():
        pytest.skip(f"{path} not available (../shared is absent)")
    return path


@pytest.fixture
def ros_context():
    """An initialised rclpy context of its own, shut down after the test."""
    import rclpy

    context = rclpy.Context()
    rclpy.init(context=context)
    yield context
    if context.ok():
        rclpy.shutdown(context=context)


@pytest.fixture
def executor(ros_context):
    """A single-threaded executor on the test's own context; nodes added to it are destroyed."""
    from rclpy.executors import SingleThreadedExecutor

    ex = SingleThreadedExecutor(context=ros_context)
    yield ex
    for node in list(ex.get_nodes()):
        ex.remove_node(node)
        node.destroy_node()
    ex.shutdown()


@pytest.fixture
def probe(executor, ros_context):
    """A plain node on the test's context for subscribing and publishing in tests."""
    from rclpy.node import Node

    node = Node("test_probe", context=ros_context)
    executor.add_node(node)
    return node


@pytest.fixture
def relative_copy():
    """``copy(src, dst)``: the bag ``src`` rewritten with relative topic names (``imu/delta``),
    as tools other than ``ros2 bag record`` write them. ``BagWriter`` always writes absolute
    names, so this writes the container with rosbags' public writer."""
    from rosbags.rosbag2 import StoragePlugin, Writer

    from ins_gnss_ros import io as bagio

    def copy(src, dst):
        with Writer(dst, version=9, storage_plugin=StoragePlugin.MCAP) as writer:
            connections = {}
            for row in bagio.read_raw(src):
                if row.topic not in connections:
                    connections[row.topic] = writer.add_connection(
                        row.topic.lstrip("/"), row.msgtype, typestore=bagio.typestore())
                writer.write(connections[row.topic], row.t_ns, row.data)
        return dst

    return copy
