"""nodes/fast_messages.py against rclpy: default objects, CDR decoding and encoding."""
import numpy as np
import pytest
from rclpy.serialization import deserialize_message, serialize_message

from ins_gnss_ros.nodes import fast_messages as fm
from ins_gnss_ros.trial.bag import messages_equal, msg_class

#: Every message type of CONTRACT.md and the nodes' other topics.
TYPES = [
    "sensor_msgs/msg/Imu", "sensor_msgs/msg/MagneticField", "sensor_msgs/msg/NavSatFix",
    "sensor_msgs/msg/TimeReference", "geometry_msgs/msg/TwistWithCovarianceStamped",
    "nav_msgs/msg/Odometry", "rosgraph_msgs/msg/Clock", "ins_gnss_msgs/msg/ImuDelta",
    "ins_gnss_msgs/msg/InsState", "ins_gnss_msgs/msg/InsCorrection", "ins_gnss_msgs/msg/Heading",
    "ins_gnss_msgs/msg/FilterStatus", "ins_gnss_msgs/msg/MeasurementUpdate",
    "ins_gnss_msgs/msg/GnssEphemeris", "ins_gnss_msgs/msg/GnssObservations",
    "diagnostic_msgs/msg/DiagnosticArray",
]
#: Types with sequences: no codec (rclpy serialises them).
WITHOUT_CODEC = {"ins_gnss_msgs/msg/GnssObservations", "diagnostic_msgs/msg/DiagnosticArray",
                 "ins_gnss_msgs/msg/MeasurementUpdate", "ins_gnss_msgs/msg/FilterStatus"}

_INT_RANGES = {"B": (0, 255), "b": (-128, 127), "H": (0, 65535), "h": (-32768, 32767),
               "I": (0, 2**32 - 1), "i": (-2**31, 2**31 - 1), "Q": (0, 2**63),
               "q": (-2**63, 2**63 - 1)}


def _randomised(cls, rng):
    """An instance of ``cls`` with random values in every supported field (through the
    properties, as user code sets them)."""
    msg = cls()
    for name, t in zip(cls.get_fields_and_field_types(), cls.SLOT_TYPES):
        kind = type(t).__name__
        if kind == "NamespacedType":
            setattr(msg, name, _randomised(type(getattr(msg, name)), rng))
        elif kind == "UnboundedString":
            setattr(msg, name, "".join(rng.choice(list("abcxyz_/é"), rng.integers(0, 12))))
        elif kind == "BasicType" and t.typename in fm._PRIMITIVES:
            setattr(msg, name, _random_value(fm._PRIMITIVES[t.typename], rng))
        elif kind == "Array" and t.value_type.typename in fm._ARRAY_TYPES:
            code = fm._PRIMITIVES[t.value_type.typename]
            setattr(msg, name, np.array([_random_value(code, rng) for _ in range(t.size)],
                                        fm._ARRAY_DTYPES[code]))
    return msg


def _random_value(code, rng):
    if code == "d":
        return float(rng.normal(0.0, 1e3)) if rng.random() > 0.1 else float("nan")
    if code == "f":
        return float(np.float32(rng.normal(0.0, 10.0)))
    if code == "?":
        return bool(rng.random() > 0.5)
    lo, hi = _INT_RANGES[code]
    return int(rng.integers(lo, hi, endpoint=True))


@pytest.mark.parametrize("msgtype", TYPES)
def test_new_equals_the_generated_constructor(msgtype):
    cls = msg_class(msgtype)
    a, b = fm.new(cls), fm.new(cls)
    assert type(a) is cls and a == cls() and messages_equal(a, cls())
    if hasattr(a, "header"):
        # Independent objects: changing one leaves the template and the other alone.
        a.header.stamp.sec = 5
        assert b.header.stamp.sec == 0 and fm.new(cls).header.stamp.sec == 0


@pytest.mark.parametrize("msgtype", TYPES)
def test_codec_agrees_with_rclpy(msgtype):
    cls = msg_class(msgtype)
    codec = fm.codec(cls)
    if msgtype in WITHOUT_CODEC:
        assert codec is None
        return
    rng = np.random.default_rng(len(msgtype))
    for _ in range(20):
        msg = _randomised(cls, rng)
        decoded = codec.decode(serialize_message(msg))
        assert type(decoded) is cls and messages_equal(decoded, msg)
        assert messages_equal(deserialize_message(codec.encode(msg), cls), msg)
        # The same Python types as rclpy's objects (a node may rely on them).
        reference = deserialize_message(serialize_message(msg), cls)
        for name in cls.get_fields_and_field_types():
            assert type(getattr(decoded, name)) is type(getattr(reference, name))


def test_decode_refuses_malformed_payloads():
    codec = fm.codec(msg_class("sensor_msgs/msg/Imu"))
    good = serialize_message(msg_class("sensor_msgs/msg/Imu")())
    # Empty, big endian, cut short, a string length beyond the end (header.frame_id at 12).
    for bad in (b"", b"\x00\x00\x00\x00" + good[4:], good[:20],
                good[:12] + b"\xff\xff\x00\x00" + good[16:]):
        with pytest.raises(ValueError):
            codec.decode(bad)


def test_encode_refuses_an_array_of_another_length():
    cls = msg_class("sensor_msgs/msg/NavSatFix")
    msg = cls()
    msg._position_covariance = np.zeros(8)    # past the property, which would check it
    with pytest.raises(ValueError, match=r"not \(9,\)"):
        fm.codec(cls).encode(msg)
