"""Trial bags: decoded round trip, stamp order, readability by the mcap tools, hostile files.

Truth is independent of the writer: field values put in by hand, and the ``mcap`` +
``mcap-ros2-support`` decoder (what Foxglove uses), which parses the CDR with the schemas
stored in the file, never with rclpy.
"""
import math
from pathlib import Path

import numpy as np
import pytest

from ins_gnss_ros.trial import bag as bagio
from ins_gnss_ros.trial.bag import messages_equal


def test_messages_equal_is_nan_aware():
    a = bagio.heading_msg(5, azimuth=1.0)
    b = bagio.heading_msg(5, azimuth=1.0)
    assert a != b  # rclpy: NaN fields differ
    assert messages_equal(a, b)
    b.azimuth = 1.0 + 1e-15
    assert not messages_equal(a, b)
    c = bagio.fix_msg(1, 0.1, 0.2, 3.0, [1, 2, 3])
    d = bagio.fix_msg(1, 0.1, 0.2, 3.0, [1, 2, 4])
    assert not messages_equal(c, d)


T0 = 1_767_225_600_123_456_789


def _sample_messages():
    return [
        ("imu/data_raw", bagio.imu_msg(T0 + 10, [0.1, -0.2, 0.3], [0.0, 0.5, 9.8])),
        ("imu/delta", bagio.delta_msg(T0 + 5, [1e-4, 2e-4, -3e-4], [0.01, 0.0, 0.098], 0.005)),
        ("gnss/fix", bagio.fix_msg(T0, math.radians(59.9), math.radians(30.3), 22.5,
                                   [0.25, 0.36, 1.0])),
        ("gnss/vel", bagio.twist_msg(T0, [1.0, 2.0, -0.1], [0.01, 0.01, 0.04], "gnss")),
        ("log/speed", bagio.twist_msg(T0 + 1, [5.0, math.nan, math.nan],
                                      [0.0025, math.nan, math.nan], "base_link")),
        ("imu/mag_raw", bagio.mag_msg(T0 + 3, [1.5e-5, 2e-6, -5e-5], 1e-14)),
        ("truth/state", bagio.ins_state_msg(T0 + 2, 1.0, 0.5, 10.0, [1, 2, 3],
                                            [1.0, 0.0, 0.0, 0.0])),
        ("truth/heading", bagio.heading_msg(T0 + 2, azimuth=1.25, azimuth_variance=3e-6)),
    ]


@pytest.fixture(scope="module")
def sample_bag(tmp_path_factory):
    path = tmp_path_factory.mktemp("bag") / "sample"
    with bagio.BagWriter(path) as writer:
        for topic, msg in _sample_messages():
            writer.write(topic, msg)
    return path


def test_round_trip_decodes_equal_messages_in_stamp_order(sample_bag):
    written = sorted(((bagio.stamp_ns(m), i, "/" + t, m)
                      for i, (t, m) in enumerate(_sample_messages())), key=lambda r: r[:2])
    read = bagio.read_bag(sample_bag)
    assert [m.topic for m in read] == [r[2] for r in written]
    assert [m.t_ns for m in read] == [r[0] for r in written]
    for (_, _, _, msg), got in zip(written, read):
        assert messages_equal(msg, got.msg), got.topic


def test_fields_on_the_wire(sample_bag):
    by_topic = {m.topic: m.msg for m in bagio.read_bag(sample_bag)}
    fix = by_topic["/gnss/fix"]
    assert fix.latitude == pytest.approx(59.9) and fix.longitude == pytest.approx(30.3)
    assert list(fix.position_covariance[[0, 4, 8]]) == [0.25, 0.36, 1.0]
    assert fix.header.stamp.sec == T0 // 10**9 and fix.header.stamp.nanosec == T0 % 10**9
    assert by_topic["/imu/data_raw"].orientation_covariance[0] == -1.0
    assert math.isnan(by_topic["/log/speed"].twist.twist.linear.y)


def test_topic_filter_and_types(sample_bag):
    topics = bagio.bag_topics(sample_bag)
    assert topics["/truth/state"] == "ins_gnss_msgs/msg/InsState"
    assert topics["/gnss/fix"] == "sensor_msgs/msg/NavSatFix"
    only = bagio.read_bag(sample_bag, ["gnss/fix", "/truth/state"])
    assert {m.topic for m in only} == {"/gnss/fix", "/truth/state"}


def test_mcap_tools_decode_the_bag(sample_bag):
    """Foxglove's path: the mcap reader with the ROS 2 decoder and the embedded schemas."""
    from mcap.reader import make_reader
    from mcap_ros2.decoder import DecoderFactory

    mcap_file = next(Path(sample_bag).glob("*.mcap"))
    expected = {m.topic: m.msg for m in bagio.read_bag(sample_bag)}
    seen = set()
    with open(mcap_file, "rb") as f:
        reader = make_reader(f, decoder_factories=[DecoderFactory()])
        for schema, channel, message, decoded in reader.iter_decoded_messages():
            seen.add(channel.topic)
            assert message.log_time == bagio.stamp_ns(expected[channel.topic])
            if channel.topic == "/truth/state":
                assert decoded.latitude == 1.0 and decoded.orientation.w == 1.0
                assert schema.name == "ins_gnss_msgs/msg/InsState"
            if channel.topic == "/imu/delta":
                assert decoded.dt == 0.005 and decoded.delta_angle.z == -3e-4
    assert seen == set(expected)


def test_existing_output_is_refused(sample_bag):
    with pytest.raises(bagio.BagError, match="exists"):
        bagio.BagWriter(sample_bag)


@pytest.mark.parametrize("damage", ["no_metadata", "garbage_metadata", "truncated_mcap",
                                    "garbage_mcap", "unknown_type"])
def test_hostile_bags_raise_one_line_bag_error(sample_bag, tmp_path, damage):
    import shutil

    path = tmp_path / "bad"
    shutil.copytree(sample_bag, path)
    mcap_file = next(path.glob("*.mcap"))
    metadata = path / "metadata.yaml"
    if damage == "no_metadata":
        metadata.unlink()
    elif damage == "garbage_metadata":
        metadata.write_text("rosbag2_bagfile_information: [1, 2\n")
    elif damage == "truncated_mcap":
        data = mcap_file.read_bytes()
        mcap_file.write_bytes(data[: len(data) // 2])
    elif damage == "garbage_mcap":
        mcap_file.write_bytes(bytes(np.random.default_rng(1).integers(0, 256, 5000,
                                                                      dtype=np.uint8)))
    else:
        metadata.write_text(metadata.read_text().replace("sensor_msgs/msg/NavSatFix",
                                                         "evil_msgs/msg/Boom"))
    with pytest.raises(bagio.BagError) as info:
        bagio.read_bag(path)
    assert "\n" not in str(info.value)
