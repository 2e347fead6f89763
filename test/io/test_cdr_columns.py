"""io/cdr.py numpy columns (bulk decoding and encoding) against rclpy's serialisation (the rmw's
CDR) and against the object codec."""
import math

import numpy as np
import pytest
from rclpy.serialization import deserialize_message, serialize_message

from ins_gnss_ros.io import cdr, messages_equal
from ins_gnss_ros.trial import contract_messages as msgs

T0 = 1_767_225_600_123_456_789
RNG = np.random.default_rng(7)


def _delta(k, frame_id):
    msg = msgs.delta_msg(T0 + 5_000_000 * k, RNG.normal(size=3) * 1e-3, RNG.normal(size=3),
                          0.005, frame_id)
    if k == 3:
        msg.delta_velocity.y = math.nan
        msg.dt = math.inf
    return msg


@pytest.mark.parametrize("msgtype, make", [
    ("ins_gnss_msgs/msg/ImuDelta", _delta),
    ("sensor_msgs/msg/Imu", lambda k, frame: msgs.imu_msg(
        T0 + k, RNG.normal(size=3), RNG.normal(size=3), frame)),
])
def test_decode_equals_rclpy_for_any_frame_id(msgtype, make):
    # Frame ids of every length modulo 8 shift the doubles by different paddings.
    msgs = [make(k, "imu_link"[:k % 9]) for k in range(40)]
    columns = cdr.decode_columns(msgtype, [serialize_message(m) for m in msgs])
    for k, msg in enumerate(msgs):
        for path, values in columns.items():
            expected = msg
            for part in path.split("."):
                expected = getattr(expected, part)
            got = values[k]
            np.testing.assert_array_equal(got, expected, err_msg=path)


def test_encode_gives_what_rclpy_decodes_to_the_same_message():
    from nav_msgs.msg import Odometry

    n = 5
    v, q = RNG.normal(size=(n, 3)), RNG.normal(size=(n, 4))
    cov = RNG.normal(size=(n, 36))
    header = {"header.stamp.sec": np.arange(n) + 1_767_225_600,
              "header.stamp.nanosec": np.arange(n) * 7}
    vec = {f"{prefix}.{c}": v[:, i] for prefix in ("pose.pose.position", "twist.twist.linear",
                                                   "twist.twist.angular")
           for i, c in enumerate("xyz")}
    quat = {f"pose.pose.orientation.{c}": q[:, i] for i, c in enumerate("wxyz")}
    payloads = cdr.encode_columns("nav_msgs/msg/Odometry",
                          dict(header, **vec, **quat, **{"pose.covariance": cov,
                                                         "twist.covariance": -cov}),
                          {"header.frame_id": "map", "child_frame_id": "base_link"})
    for k, data in enumerate(payloads):
        msg = Odometry(child_frame_id="base_link")
        msg.header.frame_id = "map"
        msg.header.stamp.sec, msg.header.stamp.nanosec = 1_767_225_600 + k, 7 * k
        for obj in (msg.pose.pose.position, msg.twist.twist.linear, msg.twist.twist.angular):
            obj.x, obj.y, obj.z = (float(x) for x in v[k])
        o = msg.pose.pose.orientation
        o.w, o.x, o.y, o.z = (float(x) for x in q[k])
        msg.pose.covariance, msg.twist.covariance = cov[k].tolist(), (-cov[k]).tolist()
        assert len(data) == len(serialize_message(msg))
        assert messages_equal(deserialize_message(data, Odometry), msg)
        assert data == cdr.codec(Odometry).encode(msg)   # one layout, objects and columns


def test_refused_layouts_and_payloads():
    with pytest.raises(cdr.CdrLayoutError, match="fixed layout"):
        cdr.column_layout("diagnostic_msgs/msg/DiagnosticArray", (0,))
    with pytest.raises(cdr.CdrLayoutError, match="more than one string"):
        cdr.decode_columns("nav_msgs/msg/Odometry", [])
    good = serialize_message(msgs.delta_msg(T0, [0, 0, 0], [0, 0, 0], 0.01))
    with pytest.raises(cdr.CdrLayoutError, match="little-endian"):
        cdr.decode_columns("ins_gnss_msgs/msg/ImuDelta", [b"\x00\x00" + good[2:]])
    with pytest.raises(cdr.CdrLayoutError):
        cdr.decode_columns("ins_gnss_msgs/msg/ImuDelta", [good[:40]])
    with pytest.raises(cdr.CdrLayoutError,
                       match="missing: bridged_angle_variance, .*delta_angle.x.*, dt, header"):
        cdr.encode_columns("ins_gnss_msgs/msg/ImuDelta", {"header.stamp.sec": 1},
                   {"header.frame_id": "x"})


def test_field_reader_reads_rclpy_payloads_of_any_frame_id():
    """field_reader's values are the fields of rclpy's own serialisation of the message,
    whatever the length of its string; a payload of another layout is a CdrLayoutError."""
    paths = ("header.stamp.sec", "header.stamp.nanosec", "orientation_covariance",
             "angular_velocity.x", "linear_acceleration.z")
    read = cdr.field_reader("sensor_msgs/msg/Imu", paths)
    for k, frame in enumerate(("", "imu", "imu_link_with_a_long_name")):
        msg = msgs.imu_msg(T0 + k, RNG.normal(size=3), RNG.normal(size=3), frame)
        msg.orientation_covariance = RNG.normal(size=9)
        sec, nanosec, *cov, wx, fz = read(serialize_message(msg))
        assert (sec, nanosec) == (msg.header.stamp.sec, msg.header.stamp.nanosec)
        assert cov == msg.orientation_covariance.tolist()
        assert (wx, fz) == (msg.angular_velocity.x, msg.linear_acceleration.z)
    good = serialize_message(msg)
    for bad in (good[:100], b"\x00\x00" + good[2:], good[:12] + b"\xff\xff\xff\x7f" + good[16:]):
        with pytest.raises(cdr.CdrLayoutError):
            read(bad)
    with pytest.raises(cdr.CdrLayoutError):
        cdr.field_reader("sensor_msgs/msg/Imu", ("angular_velocity.x", "header.stamp.sec"))


@pytest.mark.parametrize("msgtype, strings, make", [
    ("ins_gnss_msgs/msg/ImuDelta", 1, _delta),
    ("sensor_msgs/msg/Imu", 1, lambda k, frame: msgs.imu_msg(
        T0 + k, RNG.normal(size=3), RNG.normal(size=3), frame)),
    ("nav_msgs/msg/Odometry", 2, None),
    ("builtin_interfaces/msg/Time", 0, None),
])
def test_field_writer_packs_what_rclpy_serializes(msgtype, strings, make):
    """field_writer's payload, from every numeric field's value in field order, decodes by
    rclpy's own deserializer into the message and is the object codec's bytes, whatever the
    length of its strings (each shifts what follows by its own padding)."""
    from nav_msgs.msg import Odometry

    from ins_gnss_ros.io import msg_class
    from ins_gnss_ros.io.cdr import _flat

    for k in range(9):
        frames = tuple(("imu_link", "base_link")[i][:(k + 3 * i) % 9] for i in range(strings))
        if make is not None:
            msg = make(k, frames[0])
        else:
            msg = msg_class(msgtype)()
            if msg_class(msgtype) is Odometry:
                msg.header.frame_id, msg.child_frame_id = frames
                msg.pose.covariance = RNG.normal(size=36)
                msg.twist.twist.angular.y = RNG.normal()
            else:
                msg.sec, msg.nanosec = -k, 7 * k
        values = []
        for path, f in _flat(type(msg)):
            if f.kind != cdr.STRING:
                value = msg
                for part in path.split("."):
                    value = getattr(value, part)
                values += list(value) if f.kind == cdr.ARRAY else [value]
        data = cdr.field_writer(msgtype, frames)(*values)
        assert messages_equal(deserialize_message(data, type(msg)), msg)
        assert data == cdr.codec(type(msg)).encode(msg)   # padding zero (rclpy's is not set)
