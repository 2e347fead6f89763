"""Trial bags: decoded round trip, stamp order, readability by the mcap tools, byte-identical
output, hostile files.

Truth is independent of the writer: field values put in by hand, and the ``mcap`` +
``mcap-ros2-support`` decoder (what Foxglove uses), which parses the CDR with the schemas
stored in the file, never with rclpy.
"""
import math
from pathlib import Path

import numpy as np
import pytest
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from ins_gnss_msgs.msg import FilterStatus, GnssObservations, MeasurementUpdate

from ins_gnss_ros import io as bagio
from ins_gnss_ros.io import messages_equal, ns_to_stamp
from ins_gnss_ros.trial import contract_messages as msgs


def test_messages_equal_is_nan_aware():
    a = msgs.heading_msg(5, azimuth=1.0)
    b = msgs.heading_msg(5, azimuth=1.0)
    assert a != b  # rclpy: NaN fields differ
    assert messages_equal(a, b)
    b.azimuth = 1.0 + 1e-15
    assert not messages_equal(a, b)
    c = msgs.fix_msg(1, 0.1, 0.2, 3.0, [1, 2, 3])
    d = msgs.fix_msg(1, 0.1, 0.2, 3.0, [1, 2, 4])
    assert not messages_equal(c, d)


T0 = 1_767_225_600_123_456_789


def _sample_messages():
    return [
        ("imu/data_raw", msgs.imu_msg(T0 + 10, [0.1, -0.2, 0.3], [0.0, 0.5, 9.8])),
        ("imu/delta", msgs.delta_msg(T0 + 5, [1e-4, 2e-4, -3e-4], [0.01, 0.0, 0.098], 0.005)),
        ("gnss/fix", msgs.fix_msg(T0, math.radians(59.9), math.radians(30.3), 22.5,
                                   [0.25, 0.36, 1.0])),
        ("gnss/vel", msgs.twist_msg(T0, [1.0, 2.0, -0.1], [0.01, 0.01, 0.04], "gnss")),
        ("log/speed", msgs.twist_msg(T0 + 1, [5.0, math.nan, math.nan],
                                      [0.0025, math.nan, math.nan], "base_link")),
        ("imu/mag_raw", msgs.mag_msg(T0 + 3, [1.5e-5, 2e-6, -5e-5], 1e-14)),
        ("truth/state", msgs.ins_state_msg(T0 + 2, 1.0, 0.5, 10.0, [1, 2, 3],
                                            [1.0, 0.0, 0.0, 0.0])),
        ("truth/heading", msgs.heading_msg(T0 + 2, azimuth=1.25, azimuth_variance=3e-6)),
        # Sequences, strings, arrays of messages, an octet.
        ("nav/status", FilterStatus(
            header=msgs.ins_state_msg(T0 + 4, 0, 0, 0, None, None).header, mode=1, coupling=2,
            updates=[MeasurementUpdate(name="gnss_position", stamp=ns_to_stamp(T0 + 3),
                                       innovation=[0.5, -0.25, 1.0], innovation_variance=[1.0] * 3,
                                       nis=1.5, gate=11.3, accepted=True),
                     MeasurementUpdate(name="heading", reason="gate")],
            state_names=["dr_e", "dr_n", "phi_u"], state_std=[0.1, 0.2, 1e-3],
            accepted_count=7, rejected_count=1)),
        ("gnss/observations", GnssObservations(
            header=msgs.fix_msg(T0 + 6, 0, 0, 0, [1, 1, 1]).header, gps_week=2400,
            system=[0, 0], prn=[5, 12], frequency_slot=[0, -3], pseudorange=[2.1e7, 2.3e7],
            cn0=[41.5, 38.0], loss_of_lock=[False, True])),
        ("/diagnostics", DiagnosticArray(
            header=msgs.fix_msg(T0 + 7, 0, 0, 0, [1, 1, 1]).header,
            status=[DiagnosticStatus(level=DiagnosticStatus.WARN, name="ekf", message="m",
                                     values=[KeyValue(key="rejected", value="3")]),
                    DiagnosticStatus(name="strapdown")])),
    ]


@pytest.fixture(scope="module")
def sample_bag(tmp_path_factory):
    path = tmp_path_factory.mktemp("bag") / "sample"
    with bagio.BagWriter(path) as writer:
        for topic, msg in _sample_messages():
            writer.write(topic, msg)
    return path


def test_round_trip_decodes_equal_messages_in_stamp_order(sample_bag):
    written = sorted(((bagio.msg_stamp_ns(m), i, bagio.resolve(t), m)
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
            assert message.log_time == bagio.msg_stamp_ns(expected[channel.topic])
            _assert_same(decoded, expected[channel.topic], channel.topic)
            if channel.topic == "/truth/state":
                assert decoded.latitude == 1.0 and decoded.orientation.w == 1.0
                assert schema.name == "ins_gnss_msgs/msg/InsState"
            if channel.topic == "/imu/delta":
                assert decoded.dt == 0.005 and decoded.delta_angle.z == -3e-4
    assert seen == set(expected)


def _assert_same(decoded, msg, path):
    """An mcap-ros2-support object (SimpleNamespace, lists, bytes for uint8 arrays, int for
    octets) against the rclpy message, field by field, NaN equal to NaN."""
    if hasattr(msg, "get_fields_and_field_types"):
        for name in msg.get_fields_and_field_types():
            _assert_same(getattr(decoded, name), getattr(msg, name), f"{path}.{name}")
    elif isinstance(msg, bytes):
        assert decoded == msg[0], path
    elif isinstance(msg, str) or not hasattr(msg, "__len__"):
        assert decoded == msg or (msg != msg and decoded != decoded), path
    else:
        assert len(decoded) == len(msg), path
        for k, (x, y) in enumerate(zip(decoded, msg)):
            _assert_same(x, y, f"{path}[{k}]")


def test_output_bytes_are_the_same_in_every_run(sample_bag, tmp_path):
    """Padding is written as zeros: the same messages make the same file, byte for byte (in a
    folder of the same name: the file records its name)."""
    again = tmp_path / sample_bag.name
    with bagio.BagWriter(again) as writer:
        for topic, msg in _sample_messages():
            writer.write(topic, msg)
    (a,), (b,) = Path(sample_bag).glob("*.mcap"), again.glob("*.mcap")
    assert a.read_bytes() == b.read_bytes()


def test_full_graph_replay_gives_the_same_payloads_twice(tmp_path):
    """imu_preprocessor -> strapdown <-> ekf on a simulated drive: nav/status (sequences,
    strings) and /diagnostics carried process memory in their padding while rclpy serialised
    them; now every payload and the whole file are the same in two runs."""
    from ins_gnss_ros.trial.replay import replay
    from ins_gnss_ros.trial.simulate import simulate

    profile = tmp_path / "graph.yaml"
    profile.write_text("strapdown:\n  ros__parameters:\n    init.latitude_deg: 0.0\n"
                       "imu_preprocessor:\n  ros__parameters:\n    rate_hz: 200.0\n"
                       "    nav_rate_hz: 100.0\n"
                       "ekf:\n  ros__parameters:\n    imu_grade: mems_adis16405\n")
    bag = simulate("car", 4.0, 2, tmp_path / "raw")
    for run in "ab":
        replay(bag, profile, tmp_path / run, init_from_truth=True)
    a, b = (bagio.read_raw(tmp_path / run / "bag") for run in "ab")
    assert {"/nav/status", "/diagnostics"} <= {row.topic for row in a}
    assert a == b
    (fa,), (fb,) = ((tmp_path / run / "bag").glob("*.mcap") for run in "ab")
    assert fa.read_bytes() == fb.read_bytes()


def test_other_storage_is_read_through_rosbags(sample_bag, tmp_path):
    """An sqlite3 bag (``ros2 bag record`` before Iron): rosbags' public reader."""
    from rosbags.rosbag2 import StoragePlugin, Writer

    path = tmp_path / "sqlite"
    store = bagio.typestore()
    with Writer(path, version=9, storage_plugin=StoragePlugin.SQLITE3) as writer:
        connections = {}
        for topic, msg in _sample_messages():
            topic = bagio.resolve(topic)
            if topic not in connections:
                connections[topic] = writer.add_connection(topic, bagio.msgtype_of(msg),
                                                           typestore=store)
            writer.write(connections[topic], bagio.msg_stamp_ns(msg), bagio.serialize(msg))
    assert bagio.read_raw(path) == bagio.read_raw(sample_bag)


def test_existing_output_is_refused(sample_bag):
    with pytest.raises(bagio.BagError, match="exists"):
        bagio.BagWriter(sample_bag)


@pytest.mark.parametrize("damage", ["no_metadata", "garbage_metadata", "newer_metadata",
                                    "missing_mcap", "garbage_mcap", "unknown_type",
                                    "uninstalled_type"])
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
    elif damage == "newer_metadata":
        metadata.write_text(metadata.read_text().replace("version: 9", "version: 99"))
    elif damage == "missing_mcap":
        mcap_file.unlink()
    elif damage == "garbage_mcap":
        mcap_file.write_bytes(bytes(np.random.default_rng(1).integers(0, 256, 5000,
                                                                      dtype=np.uint8)))
    elif damage == "unknown_type":   # metadata.yaml and the MCAP schema disagree
        metadata.write_text(metadata.read_text().replace("sensor_msgs/msg/NavSatFix",
                                                         "evil_msgs/msg/Boom"))
    else:
        data = mcap_file.read_bytes()
        mcap_file.write_bytes(data.replace(b"sensor_msgs/msg/NavSatFix",
                                           b"sensor_msgs/msg/NavSatFiz"))
        metadata.write_text(metadata.read_text().replace("sensor_msgs/msg/NavSatFix",
                                                         "sensor_msgs/msg/NavSatFiz"))
    with pytest.raises(bagio.BagError) as info:
        bagio.read_bag(path)
    assert "\n" not in str(info.value) and str(path) in str(info.value)


def test_an_imu_delta_of_the_layout_before_its_bridged_variances_reads_them_zero(tmp_path):
    # Recorded before 2026-12-05: the same fields without the two trailing float64 variances.
    msg = msgs.delta_msg(1_767_225_600_000_000_000, [1e-3, 2e-3, 3e-3], [0.01, 0.02, 0.098],
                         0.01, "base_link")
    current = bagio.serialize(msg)
    with bagio.BagWriter(tmp_path / "bag") as writer:
        writer.write_raw("imu/delta", "ins_gnss_msgs/msg/ImuDelta", 1, current[:-16])
        writer.write_raw("imu/delta", "ins_gnss_msgs/msg/ImuDelta", 2, current)
        writer.write_raw("imu/delta", "ins_gnss_msgs/msg/ImuDelta", 3, current[:-8])  # neither
    rows = bagio.read_raw(tmp_path / "bag")
    assert rows[0].data == current and rows[1].data == current
    assert len(rows[2].data) == len(current) - 8
    old, new = (bagio.decode_message(r) for r in rows[:2])
    assert messages_equal(old, new) and old.bridged_angle_variance == 0.0
    with pytest.raises(bagio.BagError, match="does not decode"):
        bagio.decode_message(rows[2])
