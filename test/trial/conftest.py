"""Fixtures of the trial tests."""
import pytest


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
