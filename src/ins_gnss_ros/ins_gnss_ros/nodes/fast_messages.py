"""Fast construction, CDR encoding and decoding of rclpy message objects.

rclpy's generated message classes are slow per object for the hot paths of this package: the
constructor imports and builds every default sub-message and then sets it through a property
(``Imu()`` ~30 µs, ``InsState()`` ~65 µs here), ``deserialize_message`` builds the defaults and
then the decoded values again (~150 µs for an ``Imu``), ``serialize_message`` reads every field
through its property (~35 µs). A 200 Hz replay handles a few such objects per IMU sample, and
their cost was about 40 % of the in-process graph (docs/results/replay.md).

The classes of ``rosidl_generator_py`` keep each field ``f`` in the slot ``_f`` (plus
``_check_fields``) and describe the fields in ``SLOT_TYPES``; the properties only check and
store. This module builds objects through the slots:

* :func:`new` — a default instance, equal to ``cls()``, made from the fields of one instance
  made by ``cls()`` (immutable values shared, arrays copied, sub-messages made the same way);
* :class:`Codec` — plain little-endian CDR of one message (OMG "Common Object Request Broker
  Architecture", ch. 9.3, "CDR Transfer Syntax"; XCDR version 1 as the ROS 2 rmw
  implementations write it: a 4-byte encapsulation
  header ``00 01 00 00``, each primitive aligned to its size counted from the end of the header,
  a string as a uint32 length with the NUL and the UTF-8 bytes with the NUL) with
  :mod:`struct`, for types made of primitives, strings, fixed-size numeric arrays and nested
  such types: every message of the contract's high-rate topics. Types with sequences have no
  codec (:func:`codec` returns None): callers use rclpy for them. (The same layout for many
  messages at once, as numpy columns rather than objects: :mod:`ins_gnss_ros.trial.cdr`.)

Decoded objects are equal to rclpy's (same Python types: ``float``/``int``/``bool``/``str``,
numpy arrays for fixed numeric arrays), and rclpy decodes the encoded bytes to the same message
(test/nodes/test_fast_messages.py checks both against rclpy for every message type of the
contract). Padding bytes are zero (rclpy leaves them uninitialised).
"""
from __future__ import annotations

import struct
from functools import lru_cache
from importlib import import_module
from operator import attrgetter

import numpy as np

#: struct code of each ROS primitive this codec handles.
_PRIMITIVES = {
    "double": "d", "float": "f", "boolean": "?", "uint8": "B", "int8": "b", "uint16": "H",
    "int16": "h", "uint32": "I", "int32": "i", "uint64": "Q", "int64": "q",
}
#: Element types of the fixed-size arrays handled (rclpy keeps them as numpy arrays; boolean
#: arrays are lists) and the little-endian dtype of each struct code.
_ARRAY_TYPES = set(_PRIMITIVES) - {"boolean"}
_ARRAY_DTYPES = {code: np.dtype("<" + code) for code in _PRIMITIVES.values()}
_ENCAPSULATION = b"\x00\x01\x00\x00"   # CDR_LE
#: A string's uint32 length after 0-3 bytes of padding.
_STRING_LENGTH = [struct.Struct(f"<{pad}xI") for pad in range(4)]


class Unsupported(TypeError):
    """A message type this module has no codec for (sequences, byte/char fields, ...)."""


def new(cls):
    """A default instance of the rclpy message class ``cls``, equal to ``cls()``."""
    return _constructor(cls)()


@lru_cache(maxsize=None)
def _template(cls):
    return cls()


@lru_cache(maxsize=None)
def _constructor(cls):
    """Function making instances equal to ``cls()`` from the fields of one made by ``cls()``:
    numbers and strings shared (immutable), arrays copied, sub-messages made the same way."""
    plain, made = [], []
    for slot in cls.__slots__:
        value = getattr(_template(cls), slot)
        if hasattr(value, "SLOT_TYPES"):
            made.append((slot, _constructor(type(value))))
        elif isinstance(value, list):      # an array of messages, or an empty sequence
            made.append((slot, lambda v=value: [_constructor(type(e))() for e in v]))
        elif hasattr(value, "copy"):       # numpy and array.array values (mutable)
            made.append((slot, value.copy))
        else:
            plain.append((slot, value))
    new_object = cls.__new__

    def construct():
        out = new_object(cls)
        for slot, value in plain:
            setattr(out, slot, value)
        for slot, make in made:
            setattr(out, slot, make())
        return out

    return construct


@lru_cache(maxsize=None)
def codec(cls) -> "Codec | None":
    """The :class:`Codec` of ``cls``, or None when its type is not supported."""
    try:
        return Codec(cls)
    except Unsupported:
        return None


class Codec:
    """CDR encoder and decoder of one rclpy message class (see the module doc).

    The fields are walked in CDR order down to leaves: primitives, strings and fixed-size
    numeric arrays. The primitives and arrays between two strings form a segment read or
    written with one :class:`struct.Struct` (an array as one byte string); its padding depends
    only on where the segment starts modulo 8, so a struct is made once per (segment, start mod
    8). Encoding reads a segment's leaves with one :func:`operator.attrgetter` of their slot
    paths.

    Raises
    ------
    Unsupported
        The class has a field this codec does not handle.
    """

    def __init__(self, cls):
        self.cls = cls
        # Leaves between strings: (struct code, size, count, slot path); and the strings' paths.
        self._segments: list[list] = [[]]
        self._strings: list[str] = []
        self._build = self._builder(cls, "")
        # Per segment, for encode(): the getter of its leaves (one value or a tuple), the index,
        # dtype and length of its arrays, and the getter of the string after it (None: last).
        strings = [attrgetter(path) for path in self._strings] + [None]
        self._plan = [(attrgetter(*[leaf[3] for leaf in leaves]) if leaves else None,
                       len(leaves) == 1,
                       [(k, _ARRAY_DTYPES[code], count)
                        for k, (code, _, count, _) in enumerate(leaves) if count > 1],
                       string)
                      for leaves, string in zip(self._segments, strings)]
        self._structs: dict = {}

    def _builder(self, cls, prefix):
        """Function taking an iterator of leaf values to a new ``cls`` object; records the
        leaves and strings (slot paths after ``prefix``) as it walks the fields."""
        check_fields = _template(cls)._check_fields
        steps = []
        for slot, t in zip(cls.__slots__, cls.SLOT_TYPES):
            kind, path = type(t).__name__, prefix + slot
            if kind == "NamespacedType":
                steps.append((slot, self._builder(_message_class(t), path + ".")))
            elif kind == "BasicType" and t.typename in _PRIMITIVES:
                code = _PRIMITIVES[t.typename]
                self._segments[-1].append((code, struct.calcsize(code), 1, path))
                steps.append((slot, next))
            elif kind == "UnboundedString":
                self._strings.append(path)
                self._segments.append([])
                steps.append((slot, next))
            elif kind == "Array" and getattr(t.value_type, "typename", None) in _ARRAY_TYPES:
                code = _PRIMITIVES[t.value_type.typename]
                self._segments[-1].append((code, struct.calcsize(code), t.size, path))
                steps.append((slot, lambda values, dtype=_ARRAY_DTYPES[code]:
                              np.frombuffer(next(values), dtype).copy()))
            else:
                raise Unsupported(f"{cls.__name__}.{slot[1:]}: {kind} fields are not supported")
        new_object = cls.__new__

        def build(values):
            out = new_object(cls)
            out._check_fields = check_fields
            for slot, read in steps:
                setattr(out, slot, read(values))
            return out

        return build

    def _struct(self, segment: int, start: int) -> struct.Struct:
        """Struct of segment ``segment`` when it starts at payload offset ``start`` (mod 8)."""
        key = (segment, start % 8)
        s = self._structs.get(key)
        if s is None:
            fmt, pos = ["<"], start % 8
            for code, size, count, _ in self._segments[segment]:
                pad = -pos % size
                fmt.append(f"{pad}x{code}" if count == 1 else f"{pad}x{size * count}s")
                pos += pad + size * count
            s = self._structs[key] = struct.Struct("".join(fmt))
        return s

    # -- use ------------------------------------------------------------------------------------
    def encode(self, msg) -> bytes:
        """CDR payload of ``msg`` (an instance of the codec's class).

        Raises
        ------
        ValueError
            A fixed-size array field of another length.
        """
        parts, pos = [_ENCAPSULATION], 0
        for segment, (getter, single, arrays, string) in enumerate(self._plan):
            if getter is not None:
                values = (getter(msg),) if single else getter(msg)
                if arrays:
                    values = list(values)
                    for k, dtype, count in arrays:
                        array = np.asarray(values[k], dtype)
                        if array.shape != (count,):
                            raise ValueError(f"{self.cls.__name__}: an array field of shape "
                                             f"{array.shape}, not ({count},)")
                        values[k] = array.tobytes()
                s = self._struct(segment, pos)
                parts.append(s.pack(*values))
                pos += s.size
            if string is not None:
                data = string(msg).encode()
                pad = -pos % 4
                parts += (_STRING_LENGTH[pad].pack(len(data) + 1), data, b"\0")
                pos += pad + 4 + len(data) + 1
        return b"".join(parts)

    def decode(self, data):
        """Message object of a CDR payload.

        Raises
        ------
        ValueError
            Not a little-endian plain CDR payload of this type (short, bad string).
        """
        if data[:4] != _ENCAPSULATION:
            raise ValueError("not a little-endian plain CDR payload")
        body = memoryview(data)[4:]
        values, pos = [], 0
        last = len(self._segments) - 1
        try:
            for segment in range(last + 1):
                s = self._struct(segment, pos)
                values += s.unpack_from(body, pos)
                pos += s.size
                if segment < last:
                    pos += -pos % 4
                    (size,) = struct.unpack_from("<I", body, pos)
                    end = pos + 4 + size
                    if size < 1 or end > len(body) or body[end - 1] != 0:
                        raise ValueError("malformed string")
                    values.append(bytes(body[pos + 4:end - 1]).decode())
                    pos = end
        except struct.error as err:
            raise ValueError(f"payload too short: {err}") from None
        return self._build(iter(values))


def _message_class(t):
    return getattr(import_module(".".join(t.namespaces)), t.name)
