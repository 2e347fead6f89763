"""What a replay reads from a bag: inputs under absolute names, truth apart, matching checked.

Truth: small bags written by ``BagWriter`` (absolute names) and their copies with relative names.
"""
import pytest

from ins_gnss_ros import io as bagio
from ins_gnss_ros.trial import contract_messages as msgs
from ins_gnss_ros.trial.inputs import (InputTopicsError, check_inputs, iter_topic, parse_remap,
                                        read_inputs)

T0 = 1_767_225_600 * 10**9


@pytest.fixture
def bags(tmp_path, relative_copy):
    with bagio.BagWriter(tmp_path / "abs") as writer:
        for k in range(1, 11):
            writer.write("imu/delta", msgs.delta_msg(T0 + k * 10**8, [0, 0, 0], [0, 0, 0.981],
                                                      0.1))
        writer.write("gnss/fix", msgs.fix_msg(T0 + 5 * 10**8, 0.1, 0.2, 3.0, [1, 1, 1]))
        writer.write("truth/state", msgs.ins_state_msg(T0, 0.1, 0.2, 3.0, [0, 0, 0],
                                                       [1, 0, 0, 0]))
    return tmp_path / "abs", relative_copy(tmp_path / "abs", tmp_path / "rel")


def test_relative_topic_names_read_as_absolute(bags):
    absolute, relative = bags
    assert set(bagio.bag_topics(relative)) == {"imu/delta", "gnss/fix", "truth/state"}
    a, r = read_inputs(absolute), read_inputs(relative)
    assert [m.topic for m in r] == [m.topic for m in a] == ["/imu/delta"] * 5 + ["/gnss/fix"] + \
        ["/imu/delta"] * 5
    assert all(x.t_ns == y.t_ns and bagio.messages_equal(x.msg, y.msg) for x, y in zip(a, r))
    for bag in bags:
        for name in ("truth/state", "/truth/state"):
            (truth,) = iter_topic(bag, name)
            assert truth.topic == "/truth/state" and truth.t_ns == T0


def test_a_bag_matching_no_input_is_one_line_naming_both(bags):
    assert check_inputs(bags[1], dict.fromkeys(["/imu/delta", "/ins/correction"])) == []
    with pytest.raises(InputTopicsError) as info:  # relative names matched as absolute ones
        check_inputs(bags[1], dict.fromkeys(["/imu/data_raw", "/ins/correction"]))
    text = str(info.value)
    assert "\n" not in text and isinstance(info.value, ValueError)
    for name in ("imu/delta", "gnss/fix", "truth/state", "/imu/data_raw", "/ins/correction"):
        assert name in text


def test_a_bag_under_other_names_reads_with_a_remapping(tmp_path):
    """A driver's names (``/fix``; relative ``imu``) read as the graph's with ``--remap``;
    without it the bag is refused, the message naming the remedy."""
    with bagio.BagWriter(tmp_path / "other") as writer:
        for k in range(1, 4):
            writer.write("imu", msgs.delta_msg(T0 + k * 10**8, [0, 0, 0], [0, 0, 0.981], 0.1))
        writer.write("/fix", msgs.fix_msg(T0 + 2 * 10**8, 0.1, 0.2, 3.0, [1, 1, 1]))
    bag = tmp_path / "other"
    inputs = {"/imu/delta": "ins_gnss_msgs/msg/ImuDelta",
              "/gnss/fix": "sensor_msgs/msg/NavSatFix"}
    with pytest.raises(InputTopicsError, match="--remap FROM:=TO"):
        check_inputs(bag, dict.fromkeys(inputs))  # the inputs' types not known
    with pytest.raises(InputTopicsError, match="names: --remap /fix:=/gnss/fix "
                                               "--remap /imu:=/imu/delta\\)$"):
        check_inputs(bag, inputs)
    remap = parse_remap(["/fix:=gnss/fix", "imu:=/imu/delta"])
    assert remap == {"/fix": "/gnss/fix", "/imu": "/imu/delta"}
    assert check_inputs(bag, inputs, remap) == []
    # The IMU read, the fixes not: said, with the remapping (the graph would run without GNSS)
    assert check_inputs(bag, inputs, parse_remap(["imu:=/imu/delta"])) == [
        "/fix (sensor_msgs/msg/NavSatFix) is read by no node: --remap /fix:=/gnss/fix"]
    # ... unless the graph publishes that input itself, or no input of the type is lacking
    assert check_inputs(bag, inputs, parse_remap(["imu:=/imu/delta"]), {"/gnss/fix"}) == []
    assert check_inputs(bag, {**inputs, "/fix": "sensor_msgs/msg/NavSatFix"},
                        parse_remap(["imu:=/imu/delta"])) == []
    assert [m.topic for m in read_inputs(bag, remap)] == ["/imu/delta", "/imu/delta", "/gnss/fix",
                                                          "/imu/delta"]
    for rule in ("/fix", "/fix:=", ":=/gnss/fix"):
        with pytest.raises(ValueError, match="expected FROM:=TO"):
            parse_remap([rule])


def test_payloads_of_a_fixed_layout_stay_undecoded_and_checked(tmp_path, bags):
    """With ``payloads``, fixed-layout inputs (ImuDelta, NavSatFix) are the bag's own bytes,
    decoding to the messages read otherwise; a payload cut short is a BagError at reading."""
    from ins_gnss_ros.trial.inputs import payload_types

    absolute = bags[0]
    assert payload_types(absolute) == {"/imu/delta": "ins_gnss_msgs/msg/ImuDelta",
                                       "/gnss/fix": "sensor_msgs/msg/NavSatFix"}
    decoded, kept = read_inputs(absolute), read_inputs(absolute, payloads=True)
    assert all(type(m.msg) is bytes for m in kept)
    assert all(bagio.messages_equal(bagio.codec(type(a.msg)).decode(b.msg), a.msg)
               for a, b in zip(decoded, kept))
    rows = bagio.read_raw(absolute)
    with bagio.BagWriter(tmp_path / "cut") as writer:
        for row in rows:
            writer.write_raw(row.topic, row.msgtype, row.t_ns,
                             row.data[:40] if row.topic == "/imu/delta" else row.data)
    with pytest.raises(bagio.BagError, match="/imu/delta at .* does not decode"):
        read_inputs(tmp_path / "cut", payloads=True)


def test_a_velocity_without_covariance_is_read_as_the_graph_takes_it(tmp_path):
    """A driver's TwistStamped (nmea_navsat_driver's ``vel``) on gnss/vel was refused as not
    the graph's type; it reads as a TwistWithCovarianceStamped with an all-zero covariance (the
    ekf then assumes one), said in the replay's summary, and a bag topic of it no node reads is
    proposed for gnss/vel."""
    from geometry_msgs.msg import TwistStamped

    from ins_gnss_ros.trial.inputs import TWIST, TWIST_WITH_COVARIANCE, conversion_notes, \
        input_types

    vel = TwistStamped()
    vel.header.stamp = bagio.ns_to_stamp(T0)
    vel.header.frame_id = "gnss"
    vel.twist.linear.x, vel.twist.linear.y = 3.0, -1.0
    for name in ("gnss/vel", "vel"):
        with bagio.BagWriter(tmp_path / name) as writer:
            writer.write("imu/delta", msgs.delta_msg(T0, [0, 0, 0], [0, 0, 0.981], 0.01))
            writer.write(name, vel)
    bag = tmp_path / "gnss/vel"
    assert bagio.bag_topics(bag)["/gnss/vel"] == TWIST
    assert input_types(bag)["/gnss/vel"] == TWIST_WITH_COVARIANCE
    (read,) = [m.msg for m in read_inputs(bag) if m.topic == "/gnss/vel"]
    assert read.header == vel.header and bagio.messages_equal(read.twist.twist, vel.twist)
    assert not any(read.twist.covariance)
    inputs = {"/imu/delta": "ins_gnss_msgs/msg/ImuDelta", "/gnss/vel": TWIST_WITH_COVARIANCE}
    assert check_inputs(bag, inputs) == []
    assert conversion_notes(bag) == [
        f"/gnss/vel ({TWIST}) read as {TWIST_WITH_COVARIANCE} without a covariance: the ekf "
        "assumes one"]  # (replay.json "converted", printed by trial replay)
    (note,) = check_inputs(tmp_path / "vel", inputs)
    assert "--remap /vel:=/gnss/vel" in note
    assert conversion_notes(tmp_path / "vel") == [] and \
        len(conversion_notes(tmp_path / "vel", {"/vel": "/gnss/vel"})) == 1
