"""Bulk CDR encoding and decoding of fixed-layout ROS 2 messages with numpy.

A message made only of primitives, fixed-size arrays and nested messages of the same kind, plus
strings of known lengths, has the same byte layout in every instance, so thousands of payloads
can be read or written as one numpy structured array instead of one Python object each (the
per-message cost of rclpy and rosbags dominated the offline replay: docs/results/replay.md).

The layout is plain CDR (OMG "Common Object Request Broker Architecture", ch. 9.3, "CDR Transfer
Syntax"; XCDR version 1, what the ROS 2 rmw implementations write): a 4-byte encapsulation
header (``00 01 00 00``: little endian; big-endian payloads are refused), then the fields in
order, each primitive aligned to its own size (at most 8) counted from the end of the header;
a string is a uint32 length (including the terminating NUL) followed by its bytes and the NUL.
Sequences (unbounded arrays) have no fixed layout and are refused.

Field names are dotted paths (``header.stamp.sec``, ``delta_angle.x``); a fixed-size array is one
field of shape (n,). Names with a ``#`` are layout fields that are not message fields.
"""
from __future__ import annotations

from functools import lru_cache

import numpy as np

#: numpy type of each ROS primitive (CDR sizes; bool, byte and char are one byte).
PRIMITIVES = {
    "bool": "u1", "byte": "u1", "char": "u1", "octet": "u1", "uint8": "u1", "int8": "i1",
    "uint16": "u2", "int16": "i2", "uint32": "u4", "int32": "i4", "uint64": "u8", "int64": "i8",
    "float32": "f4", "float64": "f8",
}
#: Encapsulation header field, and its value for little-endian plain CDR ("CDR_LE").
HEADER = "#encapsulation"
_CDR_LE = (0, 1, 0, 0)
#: Suffix of the uint32 length field of a string.
LENGTH = "#length"
#: rosbags typestore node kinds (rosbags.typesys.base.Nodetype).
_BASE, _MESSAGE, _ARRAY = 1, 2, 3


class CdrLayoutError(ValueError):
    """A message type without a fixed layout, or payloads that do not fit it."""


def _typestore():
    from ins_gnss_ros.trial.bag import typestore

    return typestore()


@lru_cache(maxsize=None)
def layout(msgtype: str, string_lengths: tuple = ()) -> np.dtype:
    """numpy structured dtype of a whole little-endian CDR payload (encapsulation included).

    Parameters
    ----------
    msgtype : str
        ROS type name ``pkg/msg/Name``.
    string_lengths : tuple of int
        Byte length (without the NUL) of every string of the message, in field order.

    Raises
    ------
    CdrLayoutError
        The type has a sequence, or not as many strings as lengths.
    """
    if len(string_lengths) != len(_string_paths(msgtype)):
        raise CdrLayoutError(f"{msgtype}: {len(_string_paths(msgtype))} string(s), "
                             f"{len(string_lengths)} length(s) given")
    fields = {"names": [HEADER], "formats": [("u1", 4)], "offsets": [0]}
    end = _walk(_typestore().fielddefs, msgtype, "", 0, list(string_lengths), fields)
    return np.dtype(dict(fields, itemsize=4 + end))


def _walk(defs, msgtype, prefix, pos, lengths, fields):
    """Append the fields of ``msgtype`` at CDR offset ``pos`` (counted after the header),
    taking string lengths from the front of ``lengths``; returns the offset after them."""
    for name, (kind, spec) in defs[msgtype][1]:
        path = prefix + name
        count = None
        if kind == _ARRAY:
            (kind, spec), count = spec
        if kind == _MESSAGE and count is None:
            pos = _walk(defs, spec, path + ".", pos, lengths, fields)
        elif kind == _BASE and spec[0] == "string" and count is None:
            pos = _align(pos, 4)
            _add(fields, path + LENGTH, "<u4", pos)
            _add(fields, path, f"S{lengths[0] + 1}", pos + 4)
            pos += 4 + lengths.pop(0) + 1
        elif kind == _BASE and spec[0] in PRIMITIVES:
            code = PRIMITIVES[spec[0]]
            size = int(code[1])
            pos = _align(pos, size)
            _add(fields, path, ("<" + code, (count,)) if count else "<" + code, pos)
            pos += size * (count or 1)
        else:
            raise CdrLayoutError(f"{msgtype}.{name}: no fixed layout (sequences and arrays "
                                 "of strings or messages are not supported)")
    return pos


def _align(pos, size):
    return -(-pos // size) * size


def _add(fields, name, fmt, pos):
    fields["names"].append(name)
    fields["formats"].append(fmt)
    fields["offsets"].append(4 + pos)


def _first_string_offset(msgtype: str) -> int | None:
    """Payload offset of the length of the first string (None: no string). Everything before
    the first string has a fixed size, so this is the same in every instance."""
    if not _string_paths(msgtype):
        return None
    dtype = layout(msgtype, (0,) * len(_string_paths(msgtype)))
    return dtype.fields[_string_paths(msgtype)[0] + LENGTH][1]


def decode(msgtype: str, payloads) -> dict:
    """Numeric fields of many little-endian CDR payloads of a type with at most one string.

    Parameters
    ----------
    msgtype : str
    payloads : sequence of bytes-like
        Serialised messages (e.g. the ``data`` of bag rows), any mix of string lengths.

    Returns
    -------
    dict of str to ndarray
        Every numeric field by its dotted path, shape (n,) or (n, size); strings are left out.

    Raises
    ------
    CdrLayoutError
        The type has no fixed layout or more than one string, or a payload is not
        little-endian plain CDR or is shorter than its layout.
    """
    if len(_string_paths(msgtype)) > 1:
        raise CdrLayoutError(f"{msgtype}: more than one string, the layout varies")
    offset = _first_string_offset(msgtype)
    template = layout(msgtype, () if offset is None else (0,))
    n = len(payloads)
    out = {name: np.empty((n,) + sub.shape, sub.base)
           for name, (sub, *_) in template.fields.items()
           if "#" not in name and sub.base.kind != "S"}
    sizes = np.fromiter(map(len, payloads), np.int64, n)
    for size in np.unique(sizes):
        rows = np.flatnonzero(sizes == size)
        raw = np.frombuffer(b"".join([payloads[k] for k in rows]), np.uint8).reshape(-1, size)
        if size < 4 + (0 if offset is None else offset) or np.any(raw[:, :4] != _CDR_LE):
            raise CdrLayoutError(f"{msgtype}: a payload of {size} bytes is not little-endian "
                                 f"plain CDR of this type")
        # Length of the string (NUL included) of each payload: it shifts what follows.
        lengths = np.ones(len(rows), np.int64) if offset is None else \
            raw[:, offset:offset + 4].copy().view("<u4")[:, 0].astype(np.int64)
        for length in np.unique(lengths):
            sel = lengths == length
            dtype = layout(msgtype, () if offset is None else (max(int(length) - 1, 0),))
            if dtype.itemsize > size or length < 1:
                raise CdrLayoutError(f"{msgtype}: a payload of {size} bytes does not fit the "
                                     f"layout of {dtype.itemsize} bytes")
            view = np.ascontiguousarray(raw[sel, :dtype.itemsize]).view(dtype)[:, 0]
            for name, column in out.items():
                column[rows[sel]] = view[name]
    return out


def encode(msgtype: str, columns: dict, strings: dict | None = None) -> list:
    """CDR payloads (little endian) of n messages given field by field.

    Parameters
    ----------
    msgtype : str
    columns : dict of str to array_like
        Every numeric field: dotted path -> n values (or n rows of a fixed-size array); a
        scalar is used for every message. (No defaults: a .msg default such as
        ``Quaternion.w = 1`` is easily forgotten.)
    strings : dict of str to str, optional
        Dotted path -> the value of each string field (the same in every message).

    Returns
    -------
    list of bytes
        One payload per message, as rclpy's ``serialize_message`` gives (padding bytes zero).

    Raises
    ------
    CdrLayoutError
        No fixed layout, a string without a value, a missing or unknown field.
    """
    strings = dict(strings or {})
    n = max((len(v) for v in columns.values() if np.ndim(v)), default=1)
    names = _string_paths(msgtype)
    missing = [p for p in names if p not in strings]
    if missing or set(strings) - set(names):
        raise CdrLayoutError(f"{msgtype}: string values needed for {', '.join(names) or 'none'}"
                             f", got {', '.join(strings) or 'none'}")
    encoded = {p: strings[p].encode() for p in names}
    dtype = layout(msgtype, tuple(len(encoded[p]) for p in names))
    numeric = {name for name in dtype.names if "#" not in name and name not in encoded}
    if set(columns) != numeric:
        raise CdrLayoutError(f"{msgtype}: fields missing: "
                             f"{', '.join(sorted(numeric - set(columns))) or 'none'}; unknown: "
                             f"{', '.join(sorted(set(columns) - numeric)) or 'none'}")
    rec = np.zeros(n, dtype)
    rec[HEADER] = _CDR_LE
    for path, value in encoded.items():
        rec[path + LENGTH] = len(value) + 1
        rec[path] = value
    for name, value in columns.items():
        rec[name] = value
    data = rec.tobytes()
    size = dtype.itemsize
    return [data[k * size:(k + 1) * size] for k in range(n)]


@lru_cache(maxsize=None)
def _string_paths(msgtype: str) -> tuple:
    """Dotted paths of the string fields of a type, in field order."""
    defs = _typestore().fielddefs

    def walk(t, prefix):
        if t not in defs:
            raise CdrLayoutError(f"unknown message type {t!r}")
        for name, (kind, spec) in defs[t][1]:
            if kind == _MESSAGE:
                yield from walk(spec, prefix + name + ".")
            elif kind == _BASE and spec[0] == "string":
                yield prefix + name

    return tuple(walk(msgtype, ""))
