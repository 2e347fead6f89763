"""io/cdr.py message objects against the references: rclpy (the rmw's CDR) decodes what the codec
encodes and the codec decodes what rclpy encodes, to equal messages of the same Python types;
rosbags' serialiser (which writes zero padding) gives the same bytes; default objects."""
import importlib

import numpy as np
import pytest
from rclpy.serialization import deserialize_message, serialize_message

from ins_gnss_ros.io import cdr, messages_equal, msg_class, new, typestore

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
#: Packages whose every message type is checked too: every field kind rosidl has but wide
#: strings (octets, bounded strings and sequences, arrays of messages, empty messages, ...).
PACKAGES = ["std_msgs", "geometry_msgs", "sensor_msgs", "nav_msgs", "diagnostic_msgs",
            "shape_msgs", "visualization_msgs", "trajectory_msgs", "rcl_interfaces",
            "type_description_interfaces", "builtin_interfaces", "ins_gnss_msgs"]

_INT_RANGES = {"B": (0, 255), "b": (-128, 127), "H": (0, 65535), "h": (-32768, 32767),
               "I": (0, 2**32 - 1), "i": (-2**31, 2**31 - 1), "Q": (0, 2**63 - 1),
               "q": (-2**63, 2**63 - 1)}


def _all_types():
    for package in PACKAGES:
        module = importlib.import_module(f"{package}.msg")
        for name in sorted(dir(module)):
            if hasattr(getattr(module, name), "SLOT_TYPES") and not name.startswith("Metaclass"):
                yield f"{package}/msg/{name}"


def _randomised(cls, rng, depth=0):
    """An instance of ``cls`` with random values in every field, sequences of 0-3 elements
    (through the properties, as user code sets them)."""
    msg = cls()
    for f in cdr.fields(cls):
        if f.element == "x":   # the member of an empty message
            continue
        if f.kind == cdr.MESSAGE:
            value = _randomised(f.element, rng, depth + 1)
        elif f.kind in (cdr.PRIMITIVE, cdr.STRING):
            value = _random_element(f.element, rng, depth)
        else:
            t = cls.SLOT_TYPES[cls.__slots__.index("_" + f.name)]
            n = f.count if f.kind == cdr.ARRAY else \
                min(int(rng.integers(0, 4 if depth < 2 else 2)),
                    getattr(t, "maximum_size", None) or 3)
            value = [_random_element(f.element, rng, depth) for _ in range(n)]
        setattr(msg, f.name, value)
    return msg


def _random_element(element, rng, depth):
    if element == cdr.STRING:
        return "".join(rng.choice(list("abcxyz_/é"), rng.integers(0, 12)))
    if isinstance(element, type):
        return _randomised(element, rng, depth + 1)
    if element == "d":
        return float(rng.normal(0.0, 1e3)) if rng.random() > 0.1 else float("nan")
    if element == "f":
        return float(np.float32(rng.normal(0.0, 10.0)))
    if element == "?":
        return bool(rng.random() > 0.5)
    if element == "c":
        return bytes([int(rng.integers(0, 256))])
    lo, hi = _INT_RANGES[element]
    return int(rng.integers(lo, hi, endpoint=True))


@pytest.mark.parametrize("msgtype", TYPES)
def test_new_equals_the_generated_constructor(msgtype):
    cls = msg_class(msgtype)
    a, b = new(cls), new(cls)
    assert type(a) is cls and a == cls() and messages_equal(a, cls())
    if hasattr(a, "header"):
        # Independent objects: changing one leaves the template and the other alone.
        a.header.stamp.sec = 5
        assert b.header.stamp.sec == 0 and new(cls).header.stamp.sec == 0


@pytest.mark.parametrize("msgtype", sorted(set(TYPES) | set(_all_types())))
def test_codec_agrees_with_rclpy(msgtype):
    cls = msg_class(msgtype)
    codec = cdr.codec(cls)
    rng = np.random.default_rng(len(msgtype))
    for _ in range(10):
        msg = _randomised(cls, rng)
        decoded = codec.decode(serialize_message(msg))
        assert type(decoded) is cls and messages_equal(decoded, msg)
        assert messages_equal(deserialize_message(codec.encode(msg), cls), msg)
        # The same Python types as rclpy's objects (a node may rely on them).
        reference = deserialize_message(serialize_message(msg), cls)
        for name in cls.get_fields_and_field_types():
            assert type(getattr(decoded, name)) is type(getattr(reference, name)), name


@pytest.mark.parametrize("msgtype", TYPES)
def test_encoding_is_rosbags_zero_padded_cdr(msgtype):
    """rosbags lays CDR out independently and writes its padding as zeros: equal bytes mean the
    same layout and zero padding (rclpy's serialisation would differ in its padding bytes)."""
    store = typestore()
    codec = cdr.codec(msg_class(msgtype))
    rng = np.random.default_rng(3)
    for _ in range(10):
        data = codec.encode(_randomised(msg_class(msgtype), rng))
        assert bytes(store.serialize_cdr(store.deserialize_cdr(data, msgtype), msgtype)) == data
        assert codec.encode(codec.decode(data)) == data


def test_empty_sequences_have_no_element_padding():
    """FilterStatus: state_std (float64[]) empty, then accepted_count (uint32): rclpy's CDR puts
    the count right after the sequence's length (no alignment to 8 for no element)."""
    cls = msg_class("ins_gnss_msgs/msg/FilterStatus")
    msg = cls(accepted_count=7, rejected_count=9)
    data = cdr.codec(cls).encode(msg)
    assert data.endswith(b"\x00" * 4 + (7).to_bytes(4, "little") + (9).to_bytes(4, "little"))
    assert deserialize_message(data, cls).accepted_count == 7
    msg.state_std = [1.0]
    data = cdr.codec(cls).encode(msg)
    assert data[-24:] == ((1).to_bytes(4, "little") + bytes(4) + np.float64(1.0).tobytes()
                          + (7).to_bytes(4, "little") + (9).to_bytes(4, "little"))


def test_decode_refuses_malformed_payloads():
    codec = cdr.codec(msg_class("sensor_msgs/msg/Imu"))
    good = serialize_message(msg_class("sensor_msgs/msg/Imu")())
    # Empty, big endian, cut short, a string length beyond the end (header.frame_id at 12).
    for bad in (b"", b"\x00\x00\x00\x00" + good[4:], good[:20],
                good[:12] + b"\xff\xff\x00\x00" + good[16:]):
        with pytest.raises(ValueError):
            codec.decode(bad)
    # A sequence count beyond the payload.
    status = cdr.codec(msg_class("ins_gnss_msgs/msg/FilterStatus"))
    data = bytearray(status.encode(msg_class("ins_gnss_msgs/msg/FilterStatus")()))
    data[20:24] = (10**9).to_bytes(4, "little")   # updates' count
    with pytest.raises(ValueError, match="sequence"):
        status.decode(bytes(data))


def test_encode_refuses_an_array_of_another_length():
    cls = msg_class("sensor_msgs/msg/NavSatFix")
    msg = cls()
    msg._position_covariance = np.zeros(8)    # past the property, which would check it
    with pytest.raises(ValueError, match=r"not \(9,\)"):
        cdr.codec(cls).encode(msg)


def test_wide_strings_are_refused():
    from rosidl_parser.definition import UnboundedWString

    class Wide:
        __slots__ = ["_text", "_check_fields"]
        SLOT_TYPES = (UnboundedWString(),)

    with pytest.raises(cdr.Unsupported, match="Wide.text"):
        cdr.codec(Wide)
