"""CDR, the ROS 2 wire format: one layout of each message type, for objects and for columns.

The layout is plain CDR (OMG "Common Object Request Broker Architecture", ch. 9.3, "CDR Transfer
Syntax"; XCDR version 1, what the ROS 2 rmw implementations write): a 4-byte encapsulation
header (``00 01 00 00``: little endian; big-endian payloads are refused), then the fields in
order, nested messages inline, each primitive aligned to its own size (at most 8) counted from
the end of the header. A string is a uint32 length (including the terminating NUL) followed by
its UTF-8 bytes and the NUL; a sequence is a uint32 count followed by its elements (the first
one aligned to its size, so an empty sequence has no padding after its count); a fixed-size
array is its elements alone. Padding bytes are written as zeros, so equal messages give equal
bytes (rclpy's ``serialize_message`` leaves padding and a tail up to its size estimate
uninitialised: process memory on the wire).

:func:`fields` walks a message definition (the ``SLOT_TYPES`` of the rclpy class) into that
order once; two users lay it out:

* :class:`Codec` (:func:`codec`) encodes and decodes one message object with :mod:`struct`,
  every field kind but wide strings (no project or ROS 2 core message has them): the bag
  writer, the bag reader for generic topics. Decoded
  objects are equal to rclpy's, with the same Python types (``float``/``int``/``bool``/``str``,
  ``bytes`` for octets, numpy arrays for fixed numeric arrays, ``array.array`` for numeric
  sequences, lists otherwise) (test/io/test_cdr.py checks both directions against rclpy).
* :func:`decode_columns` / :func:`encode_columns` read or write thousands of payloads of a type
  without sequences as one numpy structured array (:func:`column_layout`), field by field,
  instead of one Python object each: the per-message cost of rclpy and rosbags dominated the
  offline replay (docs/results/replay.md). Column names are dotted field paths
  (``header.stamp.sec``, ``delta_angle.x``); a fixed-size array is one column of shape (n,);
  names with a ``#`` are layout fields that are not message fields. :func:`field_reader` reads
  chosen columns of one payload at a time, for a stream.

Hosts are little endian (x86-64, aarch64): numeric sequences are copied to and from
``array.array`` bytes as they are.
"""
from __future__ import annotations

import array
import struct
from functools import lru_cache
from importlib import import_module
from operator import attrgetter
from typing import NamedTuple

import numpy as np

from .messages import MessageTypeError, msg_class, msgtype_of_class, template


class CdrLayoutError(ValueError):
    """A message type without a fixed layout, or payloads that do not fit it."""


class Unsupported(CdrLayoutError):
    """A field kind this module does not lay out (wide strings and characters)."""


# ---------------------------------------------------------------------------------------------
# The layout of a message type: its fields in CDR order
# ---------------------------------------------------------------------------------------------
#: struct code (little endian, standard sizes) of each rosidl primitive type; ``octet`` is
#: rclpy's one-byte ``bytes``.
_CODES = {
    "double": "d", "float": "f", "boolean": "?", "octet": "c", "uint8": "B", "int8": "b",
    "uint16": "H", "int16": "h", "uint32": "I", "int32": "i", "uint64": "Q", "int64": "q",
}
#: numpy dtype of each code (booleans and octets are uint8 columns).
_DTYPES = {code: np.dtype("<" + ("u1" if code in "?c" else code)) for code in _CODES.values()}
#: struct code of each column dtype (booleans and octets read as uint8).
_CODE_OF_DTYPE = {dtype.str: code for code, dtype in _DTYPES.items() if code not in "?c"}
#: Field kinds; the element of an ARRAY or SEQUENCE is a struct code, STRING or a class.
PRIMITIVE, STRING, MESSAGE, ARRAY, SEQUENCE = "primitive", "string", "message", "array", \
    "sequence"
_CDR_LE = b"\x00\x01\x00\x00"
_U32 = struct.Struct("<I")
#: A uint32 (string length, sequence count) after 0-3 bytes of padding.
_COUNT = [struct.Struct(f"<{pad}xI") for pad in range(4)]


class Field(NamedTuple):
    """One field of a message type.

    Attributes
    ----------
    name : str
        Field name.
    kind : str
        PRIMITIVE, STRING, MESSAGE (one nested message), ARRAY (fixed size) or SEQUENCE
        (bounded or not).
    element : str or type
        Struct code of a primitive, STRING, or the rclpy class of a message.
    count : int or None
        Size of an ARRAY.
    """

    name: str
    kind: str
    element: object
    count: int | None = None


@lru_cache(maxsize=None)
def fields(cls) -> tuple[Field, ...]:
    """The fields of the rclpy message class ``cls`` in CDR order.

    Raises
    ------
    Unsupported
        A wide string or character field.
    """
    out = []
    for slot, t in zip(cls.__slots__, cls.SLOT_TYPES):
        kind, name = type(t).__name__, slot[1:]
        if kind in ("Array", "UnboundedSequence", "BoundedSequence"):
            out.append(Field(name, ARRAY if kind == "Array" else SEQUENCE,
                             _element(cls, name, t.value_type),
                             t.size if kind == "Array" else None))
        else:
            element = _element(cls, name, t)
            out.append(Field(name, STRING if element == STRING else
                             MESSAGE if isinstance(element, type) else PRIMITIVE, element))
    return tuple(out) or (_EMPTY,)


#: The member of a message without fields: rosidl gives its C struct a uint8 member that the
#: Python class does not have, written as one zero byte (struct code "x": no value).
_EMPTY = Field("structure_needs_at_least_one_member", PRIMITIVE, "x")


def _element(cls, name, t):
    kind = type(t).__name__
    if kind == "NamespacedType":
        return getattr(import_module(".".join(t.namespaces)), t.name)
    if kind in ("UnboundedString", "BoundedString"):
        return STRING
    if kind == "BasicType" and t.typename in _CODES:
        return _CODES[t.typename]
    what = f"{kind} {t.typename}" if kind == "BasicType" else kind
    raise Unsupported(f"{cls.__name__}.{name}: {what} fields are not supported")


def _flat(cls, prefix=""):
    """(dotted path, field) of every field of ``cls`` but nested messages, which are walked."""
    for f in fields(cls):
        if f.kind == MESSAGE:
            yield from _flat(f.element, f"{prefix}{f.name}.")
        else:
            yield prefix + f.name, f


def _fixed(f: Field) -> bool:
    """Whether a field has the same size in every message (a primitive or a primitive array)."""
    return f.kind == PRIMITIVE or (f.kind == ARRAY and isinstance(f.element, str)
                                   and f.element != STRING)


def _align(pos: int, size: int) -> int:
    return -(-pos // size) * size


# ---------------------------------------------------------------------------------------------
# Message objects
# ---------------------------------------------------------------------------------------------
@lru_cache(maxsize=None)
def codec(cls) -> "Codec":
    """The :class:`Codec` of the rclpy message class ``cls`` (made once).

    Raises
    ------
    Unsupported
        The class has a wide string or character field.
    """
    return Codec(cls)


class Codec:
    """CDR encoder and decoder of one rclpy message class (see the module doc).

    The fields are walked in CDR order down to leaves. The fixed-size leaves (primitives and
    primitive arrays, nested messages flattened) between two variable ones (strings,
    sequences, arrays of strings or messages) form a segment read or written with one
    :class:`struct.Struct` (an array as one byte string); its padding depends only on where the
    segment starts modulo 8, so a struct is made once per (segment, start mod 8). Encoding reads
    a segment's leaves with one :func:`operator.attrgetter` of their slot paths; a type whose
    only variable fields are strings is encoded whole, one getter and one struct per tuple of
    string lengths.

    Raises
    ------
    Unsupported
        The class has a field this codec does not handle.
    """

    def __init__(self, cls):
        self.cls = cls
        # Per segment its leaves: (struct code, size, count, slot path, array to bytes).
        self._segments: list[list] = [[]]
        # Per variable field after a segment: (slot path, writer, reader).
        self._variable: list[tuple] = []
        self._build = self._builder(cls, "")
        # Per segment, for write(): the getter of its leaves (one value or a tuple), the index
        # and converter of its arrays, and the getter and writer of the variable field after it.
        self._plan = []
        for k, leaves in enumerate(self._segments):
            variable = None
            if k < len(self._variable):
                path, write, _ = self._variable[k]
                variable = attrgetter(path), write
            leaves = [leaf for leaf in leaves if leaf[3] is not None]
            self._plan.append((attrgetter(*[leaf[3] for leaf in leaves]) if leaves else None,
                               len(leaves) == 1,
                               [(i, leaf[4]) for i, leaf in enumerate(leaves)
                                if leaf[4] is not None],
                               variable))
        self._readers = [read for _, _, read in self._variable] + [None]
        self._structs: dict = {}
        # A type whose only variable fields are strings (most: a header's frame_id) is encoded
        # with one getter of all its leaves and one struct per tuple of string lengths, not a
        # pack per segment (the replay encodes ~200k such messages): (getter, (index, array to
        # bytes) of its arrays, index of each string's bytes in the getter's values).
        self._whole = None
        self._whole_structs: dict = {}
        if all(write is _write_string for _, write, _ in self._variable):
            paths, arrays, strings = [], [], []
            for k, leaves in enumerate(self._segments):
                for _, _, _, path, to_bytes in leaves:
                    if path is not None:
                        if to_bytes is not None:
                            arrays.append((len(paths), to_bytes))
                        paths.append(path)
                if k < len(self._variable):
                    paths += [self._variable[k][0]] * 2   # the length's place, then the bytes
                    strings.append(len(paths) - 1)
            if len(paths) > 1:   # attrgetter of one path gives the value, not a tuple
                self._whole = attrgetter(*paths), arrays, strings

    def _builder(self, cls, prefix):
        """Function taking an iterator of leaf values to a new ``cls`` object; records the
        segments and variable fields (slot paths after ``prefix``) as it walks the fields."""
        members = fields(cls)
        check_fields = template(cls)._check_fields
        steps = []
        for f in members:
            slot = "_" + f.name
            path = prefix + slot
            if f.kind == MESSAGE:
                steps.append((slot, self._builder(f.element, path + ".")))
            elif f is _EMPTY:
                self._segments[-1].append(("x", 1, 1, None, None))
            elif _fixed(f):
                size = struct.calcsize("<" + f.element)
                if f.kind == PRIMITIVE:
                    self._segments[-1].append((f.element, size, 1, path, None))
                    steps.append((slot, next))
                else:
                    to_bytes, from_bytes = _array_converters(self.cls, f.element, f.count)
                    self._segments[-1].append((f.element, size, f.count, path, to_bytes))
                    steps.append((slot, lambda values, convert=from_bytes:
                                  convert(next(values))))
            else:
                self._variable.append((path, *_variable_field(f)))
                self._segments.append([])
                steps.append((slot, next))
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
            fmt = ["<"]
            _segment_format(self._segments[segment], start % 8, fmt)
            s = self._structs[key] = struct.Struct("".join(fmt))
        return s

    def _whole_struct(self, lengths: tuple) -> struct.Struct:
        """Struct of a whole payload (after its header) of a type whose variable fields are
        strings, for these string byte lengths (each string its uint32 length and its bytes
        with the NUL, which ``s`` pads)."""
        fmt, pos = ["<"], 0
        for k, leaves in enumerate(self._segments):
            pos = _segment_format(leaves, pos, fmt)
            if k < len(lengths):
                pad = -pos % 4
                fmt.append(f"{pad}xI{lengths[k] + 1}s")
                pos += pad + 4 + lengths[k] + 1
        s = self._whole_structs[lengths] = struct.Struct("".join(fmt))
        return s

    # -- use ------------------------------------------------------------------------------------
    def encode(self, msg) -> bytes:
        """CDR payload of ``msg`` (an instance of the codec's class), padding zero.

        Raises
        ------
        ValueError
            A fixed-size array field of another length.
        """
        if self._whole is None:
            parts = [_CDR_LE]
            self.write(msg, parts, 0)
            return b"".join(parts)
        getter, arrays, strings = self._whole
        values = list(getter(msg))
        for k, to_bytes in arrays:
            values[k] = to_bytes(values[k])
        lengths = []
        for k in strings:   # the string's bytes at k, its length (NUL included) before them
            data = values[k].encode()
            values[k] = data
            values[k - 1] = len(data) + 1
            lengths.append(len(data))
        lengths = tuple(lengths)
        s = self._whole_structs.get(lengths) or self._whole_struct(lengths)
        return _CDR_LE + s.pack(*values)

    def write(self, msg, parts: list, pos: int) -> int:
        """Append the CDR of ``msg`` at payload offset ``pos`` (after the header) to ``parts``;
        returns the offset after it."""
        for segment, (getter, single, arrays, variable) in enumerate(self._plan):
            if getter is not None:
                values = (getter(msg),) if single else getter(msg)
                if arrays:
                    values = list(values)
                    for k, to_bytes in arrays:
                        values[k] = to_bytes(values[k])
            else:
                values = ()
            s = self._struct(segment, pos)
            if s.size:
                parts.append(s.pack(*values))
                pos += s.size
            if variable is not None:
                get, write = variable
                pos = write(get(msg), parts, pos)
        return pos

    def decode(self, data):
        """Message object of a CDR payload (bytes after the message are ignored: rclpy's
        serialisation leaves some there).

        Raises
        ------
        ValueError
            Not a little-endian plain CDR payload of this type (short, bad string or count).
        """
        if data[:4] != _CDR_LE:
            raise ValueError("not a little-endian plain CDR payload")
        try:
            return self.read(memoryview(data)[4:], 0)[0]
        except struct.error as err:
            raise ValueError(f"payload too short: {err}") from None

    def read(self, body, pos: int) -> tuple:
        """(message, offset after it) of the CDR at offset ``pos`` of ``body`` (the payload
        after its header)."""
        values = []
        for segment, read in enumerate(self._readers):
            s = self._struct(segment, pos)
            values += s.unpack_from(body, pos)
            pos += s.size
            if read is not None:
                value, pos = read(body, pos)
                values.append(value)
        return self._build(iter(values)), pos


def _segment_format(leaves, pos: int, fmt: list) -> int:
    """Append the struct codes of a segment's leaves starting at payload offset ``pos`` (their
    padding zero bytes, an array as one byte string) to ``fmt``; returns the offset after."""
    for code, size, count, _, _ in leaves:
        pad = -pos % size
        fmt.append(f"{pad}x{code}" if count == 1 else f"{pad}x{size * count}s")
        pos += pad + size * count
    return pos


def _converters(code: str, fixed: bool) -> tuple:
    """(to bytes, from bytes) of the elements of a primitive array (``fixed``) or sequence as
    rclpy holds them: lists of ``bool`` or of one-byte ``bytes``; numbers as numpy arrays
    (arrays) or ``array.array`` (sequences)."""
    if code == "?":
        return bytes, lambda data: [b != 0 for b in data]
    if code == "c":
        return b"".join, lambda data: [data[k:k + 1] for k in range(len(data))]
    if fixed:
        dtype = _DTYPES[code]
        return (lambda values: np.asarray(values, dtype).tobytes(),
                lambda data: np.frombuffer(data, dtype).copy())

    def to_bytes(values):
        if type(values) is array.array and values.typecode == code:
            return values.tobytes()
        return array.array(code, values).tobytes()

    return to_bytes, lambda data: array.array(code, data)


def _array_converters(cls, code: str, count: int) -> tuple:
    """:func:`_converters` of a fixed-size array, its length checked when encoding."""
    to_bytes, from_bytes = _converters(code, fixed=True)
    size = struct.calcsize("<" + code)

    def checked(values):
        data = to_bytes(values)
        if len(data) != size * count:
            raise ValueError(f"{cls.__name__}: an array field of shape ({len(data) // size},),"
                             f" not ({count},)")
        return data

    return checked, from_bytes


def _variable_field(f: Field) -> tuple:
    """(writer, reader) of a string, sequence, or array of strings or messages:
    ``writer(value, parts, pos) -> pos`` appends its CDR at payload offset ``pos``,
    ``reader(body, pos) -> (value, pos)`` reads it."""
    if f.kind == STRING:
        return _write_string, _read_string
    write_all, read_all = _elements(f.element)
    if f.kind == ARRAY:
        count = f.count

        def write_array(values, parts, pos):
            if len(values) != count:
                raise ValueError(f"{f.name}: an array of {len(values)} elements, not {count}")
            return write_all(values, parts, pos)

        return write_array, lambda body, pos: read_all(body, pos, count)

    def write_sequence(values, parts, pos):
        pad = -pos % 4
        parts.append(_COUNT[pad].pack(len(values)))
        return write_all(values, parts, pos + pad + 4)

    def read_sequence(body, pos):
        pos += -pos % 4
        (n,) = _U32.unpack_from(body, pos)
        pos += 4
        if n > len(body) - pos:   # every element takes a byte at least
            raise ValueError(f"{f.name}: a sequence of {n} elements in {len(body) - pos} bytes")
        return read_all(body, pos, n)

    return write_sequence, read_sequence


def _write_string(value: str, parts: list, pos: int) -> int:
    data = value.encode()
    pad = -pos % 4
    parts += (_COUNT[pad].pack(len(data) + 1), data, b"\0")
    return pos + pad + 4 + len(data) + 1


def _read_string(body, pos: int) -> tuple:
    pos += -pos % 4
    (size,) = _U32.unpack_from(body, pos)
    end = pos + 4 + size
    if size < 1 or end > len(body) or body[end - 1] != 0:
        raise ValueError("malformed string")
    return bytes(body[pos + 4:end - 1]).decode(), end


def _elements(element) -> tuple:
    """(write n, read n) for the elements of a sequence or array: strings, messages (their
    :class:`Codec`), primitives (:func:`_converters`)."""
    if element == STRING:
        return _each(_write_string, _read_string)
    if isinstance(element, type):
        inner = codec(element)   # Unsupported propagates: the outer type is not supported
        return _each(inner.write, inner.read)
    to_bytes, from_bytes = _converters(element, fixed=False)
    size = struct.calcsize("<" + element)

    def write_all(values, parts, pos):
        data = to_bytes(values)
        pad = -pos % size if data else 0   # before the first element: none without one
        parts += (bytes(pad), data)
        return pos + pad + len(data)

    def read_all(body, pos, n):
        pos += -pos % size if n else 0
        end = pos + n * size
        if end > len(body):
            raise ValueError("payload too short for its sequence")
        return from_bytes(bytes(body[pos:end])), end

    return write_all, read_all


def _each(write_one, read_one) -> tuple:
    def write_all(values, parts, pos):
        for value in values:
            pos = write_one(value, parts, pos)
        return pos

    def read_all(body, pos, n):
        out = []
        for _ in range(n):
            value, pos = read_one(body, pos)
            out.append(value)
        return out, pos

    return write_all, read_all


# ---------------------------------------------------------------------------------------------
# Numpy columns of many payloads of a type without sequences
# ---------------------------------------------------------------------------------------------
#: Encapsulation header column, and the suffix of the uint32 length column of a string.
HEADER = "#encapsulation"
LENGTH = "#length"


def _class(msgtype: str):
    try:
        return msg_class(msgtype)
    except MessageTypeError as err:
        raise CdrLayoutError(str(err)) from None


@lru_cache(maxsize=None)
def column_layout(msgtype: str, string_lengths: tuple = ()) -> np.dtype:
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
        The type has a sequence or an array of strings or messages, or not as many strings as
        lengths.
    """
    if len(string_lengths) != len(_string_paths(msgtype)):
        raise CdrLayoutError(f"{msgtype}: {len(_string_paths(msgtype))} string(s), "
                             f"{len(string_lengths)} length(s) given")
    columns = {"names": [HEADER], "formats": [("u1", 4)], "offsets": [0]}

    def add(name, fmt, at):
        columns["names"].append(name)
        columns["formats"].append(fmt)
        columns["offsets"].append(4 + at)

    lengths, pos = list(string_lengths), 0
    for path, f in _flat(_class(msgtype)):
        if f.kind == STRING:
            pos = _align(pos, 4)
            add(path + LENGTH, "<u4", pos)
            add(path, f"S{lengths[0] + 1}", pos + 4)
            pos += 4 + lengths.pop(0) + 1
        elif f is _EMPTY:
            pos += 1
        elif _fixed(f):
            dtype = _DTYPES[f.element]
            pos = _align(pos, dtype.itemsize)
            add(path, (dtype, (f.count,)) if f.kind == ARRAY else dtype, pos)
            pos += dtype.itemsize * (f.count or 1)
        else:
            raise CdrLayoutError(f"{msgtype}.{path}: no fixed layout (sequences and arrays "
                                 "of strings or messages are not supported)")
    return np.dtype(dict(columns, itemsize=4 + pos))


@lru_cache(maxsize=None)
def _string_paths(msgtype: str) -> tuple:
    """Dotted paths of the string fields of a type (outside sequences), in field order."""
    return tuple(path for path, f in _flat(_class(msgtype)) if f.kind == STRING)


def _first_string_offset(msgtype: str) -> int | None:
    """Payload offset of the length of the first string (None: no string). Everything before
    the first string has a fixed size, so this is the same in every instance."""
    if not _string_paths(msgtype):
        return None
    dtype = column_layout(msgtype, (0,) * len(_string_paths(msgtype)))
    return dtype.fields[_string_paths(msgtype)[0] + LENGTH][1]


def decode_columns(msgtype: str, payloads) -> dict:
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
    template_dtype = column_layout(msgtype, () if offset is None else (0,))
    n = len(payloads)
    out = {name: np.empty((n,) + sub.shape, sub.base)
           for name, (sub, *_) in template_dtype.fields.items()
           if "#" not in name and sub.base.kind != "S"}
    sizes = np.fromiter(map(len, payloads), np.int64, n)
    header = np.frombuffer(_CDR_LE, np.uint8)
    for size in np.unique(sizes):
        rows = np.flatnonzero(sizes == size)
        raw = np.frombuffer(b"".join([payloads[k] for k in rows]), np.uint8).reshape(-1, size)
        if size < 4 + (0 if offset is None else offset) or np.any(raw[:, :4] != header):
            raise CdrLayoutError(f"{msgtype}: a payload of {size} bytes is not little-endian "
                                 f"plain CDR of this type")
        # Length of the string (NUL included) of each payload: it shifts what follows.
        lengths = np.ones(len(rows), np.int64) if offset is None else \
            raw[:, offset:offset + 4].copy().view("<u4")[:, 0].astype(np.int64)
        for length in np.unique(lengths):
            sel = lengths == length
            dtype = column_layout(msgtype, () if offset is None else (max(int(length) - 1, 0),))
            if dtype.itemsize > size or length < 1:
                raise CdrLayoutError(f"{msgtype}: a payload of {size} bytes does not fit the "
                                     f"layout of {dtype.itemsize} bytes")
            view = np.ascontiguousarray(raw[sel, :dtype.itemsize]).view(dtype)[:, 0]
            for name, column in out.items():
                column[rows[sel]] = view[name]
    return out


@lru_cache(maxsize=None)
def field_reader(msgtype: str, paths: tuple):
    """A function taking one little-endian CDR payload of a type with at most one string to
    the values of its numeric fields ``paths`` (dotted, as :func:`column_layout` names them,
    in field order), as one flat tuple of Python numbers (an array field gives its elements).

    For a stream read message by message (the offline replay's IMU samples): one
    :class:`struct.Struct` per string length instead of a message object.

    Raises
    ------
    CdrLayoutError
        The type has no fixed layout, more than one string, or ``paths`` not in field order;
        the function raises it for a payload that is not of this type.
    """
    if len(_string_paths(msgtype)) > 1:
        raise CdrLayoutError(f"{msgtype}: more than one string, the layout varies")
    offset = _first_string_offset(msgtype)
    structs: dict[int, struct.Struct] = {}

    def layout(length: int) -> struct.Struct:
        dtype = column_layout(msgtype, () if offset is None else (max(length - 1, 0),))
        fmt, pos = ["<"], 0
        for path in paths:
            sub, at = dtype.fields[path][:2]
            if at < pos:
                raise CdrLayoutError(f"{msgtype}: {path} is not in field order")
            count = sub.shape[0] if sub.shape else 1
            fmt.append(f"{at - pos}x{count}{_CODE_OF_DTYPE[sub.base.str]}")
            pos = at + sub.itemsize
        fmt.append(f"{dtype.itemsize - pos}x")
        return struct.Struct("".join(fmt))

    layout(1)   # the paths are checked now

    def read(data) -> tuple:
        try:
            length = 1 if offset is None else _U32.unpack_from(data, offset)[0]
            if data[:4] != _CDR_LE or not 1 <= length <= len(data):
                raise CdrLayoutError(f"{msgtype}: not a little-endian plain CDR payload of "
                                     "this type")
            s = structs.get(length)
            if s is None:
                s = structs[length] = layout(length)
            return s.unpack_from(data)
        except struct.error as err:
            raise CdrLayoutError(f"{msgtype}: payload too short ({err})") from None

    return read


_STAMP = struct.Struct("<iI")


def payload_stamp_ns(data) -> int:
    """The header stamp (ns) of the CDR payload of a message whose first field is a
    ``std_msgs/Header`` (:func:`starts_with_header`): its int32 sec and uint32 nanosec follow
    the 4-byte encapsulation."""
    sec, nanosec = _STAMP.unpack_from(data, 4)
    return sec * 1_000_000_000 + nanosec


@lru_cache(maxsize=None)
def starts_with_header(cls) -> bool:
    """Whether the first field of the rclpy message class ``cls`` is a ``std_msgs/Header``."""
    first = fields(cls)[0]
    return first.kind == MESSAGE and msgtype_of_class(first.element) == "std_msgs/msg/Header"


@lru_cache(maxsize=None)
def field_writer(msgtype: str, strings: tuple = ()):
    """A function taking the values of every numeric field of a type without sequences (in
    field order as :func:`column_layout` lists them, an array field as its elements) to the
    message's little-endian CDR payload, its strings given once (``strings``: the value of
    each, in field order): the bytes :meth:`Codec.encode` gives for that message.

    For a stream written message by message (the imu_preprocessor's increments, the
    strapdown's states): the values packed into one layout, no message object each.

    Raises
    ------
    CdrLayoutError
        The type has no fixed layout, or not as many strings as ``strings``.
    """
    encoded = [value.encode() for value in strings]
    dtype = column_layout(msgtype, tuple(len(value) for value in encoded))
    # The payload as numeric runs packed by a struct each, between constant bytes (padding,
    # each string's length, its bytes and NUL): one run more than there are strings.
    runs, constants = [], []       # runs: (struct, its first and end index in the values)
    fmt, pos, first, end = ["<"], 4, 0, 0
    placed = sorted(((at, name, sub) for name, (sub, at) in dtype.fields.items()
                     if name != HEADER), key=lambda field: field[0])
    for at, name, sub in placed:
        if name.endswith(LENGTH):
            runs.append((struct.Struct("".join(fmt)), first, end))
            text = encoded[len(constants)]
            constants.append(bytes(at - pos) + _U32.pack(len(text) + 1) + text + b"\0")
            fmt, pos, first = ["<"], at + 4 + len(text) + 1, end
        elif sub.base.kind != "S":
            count = sub.shape[0] if sub.shape else 1
            fmt.append(f"{at - pos}x{count}{_CODE_OF_DTYPE[sub.base.str]}")
            pos, end = at + sub.itemsize, end + count
    fmt.append(f"{dtype.itemsize - pos}x")
    runs.append((struct.Struct("".join(fmt)), first, end))
    if not constants:
        whole = runs[0][0]
        return lambda *values: _CDR_LE + whole.pack(*values)
    pieces = [(run, first, end, constant)
              for (run, first, end), constant in zip(runs, constants + [b""])]

    def write(*values) -> bytes:
        out = [_CDR_LE]
        for run, first, end, constant in pieces:
            out.append(run.pack(*values[first:end]))
            out.append(constant)
        return b"".join(out)

    return write


def encode_columns(msgtype: str, columns: dict, strings: dict | None = None) -> list:
    """CDR payloads (little endian, padding zero) of n messages given field by field.

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
        One payload per message, the bytes :meth:`Codec.encode` gives for it.

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
    dtype = column_layout(msgtype, tuple(len(encoded[p]) for p in names))
    numeric = {name for name in dtype.names if "#" not in name and name not in encoded}
    if set(columns) != numeric:
        raise CdrLayoutError(f"{msgtype}: fields missing: "
                             f"{', '.join(sorted(numeric - set(columns))) or 'none'}; unknown: "
                             f"{', '.join(sorted(set(columns) - numeric)) or 'none'}")
    rec = np.zeros(n, dtype)
    rec[HEADER] = np.frombuffer(_CDR_LE, np.uint8)
    for path, value in encoded.items():
        rec[path + LENGTH] = len(value) + 1
        rec[path] = value
    for name, value in columns.items():
        rec[name] = value
    data = rec.tobytes()
    size = dtype.itemsize
    return [data[k * size:(k + 1) * size] for k in range(n)]
