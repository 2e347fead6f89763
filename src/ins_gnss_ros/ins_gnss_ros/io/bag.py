"""Trial bags: rosbag2-compatible MCAP folders written and read with ``rosbags``.

A bag folder holds ``metadata.yaml`` and one ``.mcap`` file, the layout ``ros2 bag record -s
mcap`` produces, so ``ros2 bag play``, Foxglove and the ``mcap`` tools open it. Payloads are CDR
laid out by :mod:`ins_gnss_ros.io.cdr` (padding zero: the same messages give the same bytes),
and read back into the rclpy message classes, so a replay feeds the nodes the same objects DDS
would deliver.
``rosbags`` is used only for the container: its typestore supplies the message definitions that
MCAP stores as schemas (the project's own ``ins_gnss_msgs`` are registered from their .msg files).
Readers for which speed matters (the offline replay) take the undecoded rows (:func:`read_raw`;
a one-file MCAP bag is parsed here directly) and decode fixed-layout topics in bulk
(:func:`ins_gnss_ros.io.cdr.decode_columns`); :meth:`BagWriter.write_raw` takes payloads encoded
that way.

The log time of every message is its header stamp (sensor time; CONTRACT.md "Stamps"); messages
are written in stamp order and a reader returns them in stamp order, ties in writing order.
"""
from __future__ import annotations

import os
import struct
from dataclasses import dataclass
from functools import lru_cache
from operator import itemgetter
from pathlib import Path
from typing import Any, Iterable, Iterator, NamedTuple

from .cdr import Unsupported, codec
from .messages import MessageTypeError, msg_class, msgtype_of
from .stamps import msg_stamp_ns

#: Package whose .msg files are registered in the typestore besides the ROS 2 Jazzy ones.
CUSTOM_PACKAGE = "ins_gnss_msgs"

class BagError(ValueError):
    """A bag that cannot be read or written (missing, malformed, unknown message type)."""


@dataclass(frozen=True)
class BagMessage:
    """One decoded message: absolute topic, log time (ns, = header stamp) and the rclpy object."""

    topic: str
    t_ns: int
    msg: Any


def _msg_dirs() -> list[Path]:
    # The source tree (editable install, tests) first, then an installed share directory.
    dirs = [Path(__file__).resolve().parents[3] / CUSTOM_PACKAGE / "msg"]
    for prefix in filter(None, os.environ.get("AMENT_PREFIX_PATH", "").split(os.pathsep)):
        dirs.append(Path(prefix) / "share" / CUSTOM_PACKAGE / "msg")
    return dirs


@lru_cache(maxsize=1)
def typestore():
    """ROS 2 Jazzy typestore with ``ins_gnss_msgs`` registered from its .msg definitions."""
    from rosbags.typesys import Stores, get_types_from_msg, get_typestore

    store = get_typestore(Stores.ROS2_JAZZY)
    folder = next((d for d in _msg_dirs() if d.is_dir()), None)
    if folder is None:
        raise BagError(f"message definitions of {CUSTOM_PACKAGE} not found in "
                       f"{', '.join(map(str, _msg_dirs()))}")
    types = {}
    for path in sorted(folder.glob("*.msg")):
        types.update(get_types_from_msg(path.read_text(), f"{CUSTOM_PACKAGE}/msg/{path.stem}"))
    store.register(types)
    return store


def serialize(msg) -> bytes:
    """CDR payload of an rclpy message (:mod:`ins_gnss_ros.io.cdr`, padding zero).

    Raises
    ------
    BagError
        A type with wide strings, which the layout does not cover.
    """
    try:
        return codec(type(msg)).encode(msg)
    except Unsupported as err:
        raise BagError(f"cannot write {msgtype_of(msg)}: {err}") from None


def decode_message(raw: RawMessage, path="bag"):
    """The rclpy message of a :class:`RawMessage`.

    Raises
    ------
    BagError
        The type is not installed or not supported (wide strings), or the payload does not
        decode (``path`` names the bag in the message).
    """
    try:
        cls = msg_class(raw.msgtype)
    except MessageTypeError as err:
        raise BagError(f"{path}: {err}") from None
    try:
        return codec(cls).decode(raw.data)
    except Exception as err:
        raise BagError(f"{path}: message on {raw.topic} at {raw.t_ns} ns does not decode "
                       f"({first_line(err)})") from None


def resolve(topic: str) -> str:
    """Absolute topic name (bags store absolute names; the contract's names are relative)."""
    return topic if topic.startswith("/") else "/" + topic


class BagWriter:
    """Collects messages and writes them, sorted by stamp, when closed.

    Example
    -------
    >>> with BagWriter("bags/run") as bag:
    ...     bag.write("imu/data_raw", imu_msg)

    Sorting at the end lets a producer write each sensor stream in turn; a bag of a few hundred
    thousand small messages fits in memory comfortably.
    """

    def __init__(self, path):
        self.path = Path(path)
        if self.path.exists():
            raise BagError(f"{self.path} exists: choose a new output folder")
        self._rows: list[tuple[int, int, str, bytes]] = []
        self._types: dict[str, str] = {}

    def write(self, topic: str, msg, t_ns: int | None = None) -> None:
        """Queue ``msg`` on ``topic`` at log time ``t_ns`` (default: its header stamp)."""
        self.write_raw(topic, msgtype_of(msg), msg_stamp_ns(msg) if t_ns is None else t_ns,
                       serialize(msg))

    def write_raw(self, topic: str, msgtype: str, t_ns: int, data: bytes) -> None:
        """Queue a serialised (CDR) message of type ``msgtype`` on ``topic`` at ``t_ns``."""
        topic = resolve(topic)
        if self._types.setdefault(topic, msgtype) != msgtype:
            raise BagError(f"topic {topic} carries {self._types[topic]}, not {msgtype}")
        self._rows.append((int(t_ns), len(self._rows), topic, data))

    def __len__(self) -> int:
        return len(self._rows)

    def write_all(self, topic: str, msgs: Iterable) -> None:
        for msg in msgs:
            self.write(topic, msg)

    def close(self) -> Path:
        from rosbags.rosbag2 import CompressionFormat, CompressionMode, StoragePlugin, Writer

        # (stamp, writing order) decide: the order is unique, so no key function is needed.
        self._rows.sort()
        self.path.parent.mkdir(parents=True, exist_ok=True)
        store = typestore()
        writer = Writer(self.path, version=9, storage_plugin=StoragePlugin.MCAP)
        # zstd-compressed MCAP chunks (rosbag2's "storage" compression, which the mcap plugin,
        # Foxglove and the mcap tools read natively): IMU messages shrink about fourfold.
        writer.set_compression(CompressionMode.STORAGE, CompressionFormat.ZSTD)
        with writer:
            connections = {topic: writer.add_connection(topic, msgtype, typestore=store)
                           for topic, msgtype in sorted(self._types.items())}
            for t, _, topic, data in self._rows:
                writer.write(connections[topic], t, data)
        return self.path

    def __enter__(self) -> "BagWriter":
        return self

    def __exit__(self, exc_type, *exc) -> None:
        if exc_type is None:
            self.close()


def bag_topics(path) -> dict[str, str]:
    """Topics of a bag with their type names."""
    with _open(path) as reader:
        return {c.topic: c.msgtype for c in reader.connections}


def read_bag(path, topics: Iterable[str] | None = None) -> list[BagMessage]:
    """All messages of a bag (or of ``topics``), decoded into rclpy messages, in stamp order.

    Parameters
    ----------
    path : path
        Bag folder.
    topics : iterable of str, optional
        Only these topics (relative names are taken as absolute).

    Raises
    ------
    BagError
        One line naming the bag and what is wrong with it.
    """
    return list(iter_bag(path, topics))


def iter_bag(path, topics: Iterable[str] | None = None) -> Iterator[BagMessage]:
    """Like :func:`read_bag`, decoding lazily (rows are read and sorted by stamp first)."""
    for raw in read_raw(path, topics):
        yield BagMessage(raw.topic, raw.t_ns, decode_message(raw, path))


class RawMessage(NamedTuple):
    """One undecoded message: absolute topic, log time (ns), type name and CDR payload (a
    named tuple: a bag has a few hundred thousand of them)."""

    topic: str
    t_ns: int
    msgtype: str
    data: bytes


def read_raw(path, topics: Iterable[str] | None = None) -> list[RawMessage]:
    """The messages of a bag (or of ``topics``) undecoded, in stamp order, ties in writing
    order: for readers that decode in bulk (:func:`ins_gnss_ros.io.cdr.decode_columns`) or not at all."""
    wanted = None if topics is None else {resolve(t) for t in topics}
    try:
        with _open(path) as reader:
            connections = [c for c in reader.connections if wanted is None or c.topic in wanted]
            rows = _mcap_rows(reader, connections) if connections else []
            if rows is None:
                rows = [RawMessage(c.topic, t, c.msgtype, data)
                        for c, t, data in reader.messages(connections=connections)]
    except BagError:
        raise
    except Exception as err:  # rosbags, mcap and yaml raise many types on a damaged file
        raise BagError(f"{path}: unreadable bag ({type(err).__name__}: {first_line(err)})") \
            from None
    # Stable: ties stay in file order. The rows are built once, in their final type (a bag
    # has a few hundred thousand of them).
    rows.sort(key=itemgetter(1))
    return rows


#: MCAP file magic and the record opcodes read here (MCAP specification, "Records").
_MCAP_MAGIC = b"\x89MCAP0\r\n"
_OP_FOOTER, _OP_CHANNEL, _OP_MESSAGE, _OP_CHUNK, _OP_DATA_END = 0x02, 0x04, 0x05, 0x06, 0x0F


def _mcap_rows(reader, connections) -> list | None:
    """The :class:`RawMessage` rows of a one-file MCAP bag in file order, parsed here.

    rosbags' reader costs several microseconds per message (a stream object per record and a
    heap merge across chunks), about twice what this costs, which was a sizeable part of the
    offline replay (docs/results/replay.md); this walks the records of the data section directly (MCAP specification: a record is an opcode
    byte, a uint64 length and its content; a chunk holds compressed records; a message is
    channel id u16, sequence u32, log time u64, publish time u64 and the payload). Stable
    sorting by time afterwards gives rosbags' order (time, then file order). None (use
    rosbags) for other storage, several files or a topic with several types. The file was
    opened and checked by rosbags first.
    """
    from rosbags.rosbag2.storage_mcap import McapReader, decompress

    # The file rosbags opened (its reader's attributes; anything unexpected: rosbags reads).
    files = getattr(getattr(reader, "storage", None), "storages", None) or []
    types = {}
    if len(files) != 1 or not isinstance(files[0], McapReader) or any(
            types.setdefault(c.topic, c.msgtype) != c.msgtype for c in connections):
        return None
    data = Path(files[0].path).read_bytes()
    if not data.startswith(_MCAP_MAGIC):
        raise BagError(f"{files[0].path}: not an MCAP file")
    channels: dict[int, str] = {}
    rows: list = []

    def walk(buf, pos, end):
        unpack = struct.unpack_from
        while pos < end:
            op = buf[pos]
            body = pos + 9
            pos = body + unpack("<Q", buf, pos + 1)[0]
            if pos > end:
                raise BagError(f"{reader.path}: truncated MCAP record")
            if op == _OP_MESSAGE:
                channel, _, t = unpack("<HIQ", buf, body)
                if channel in channels:
                    topic = channels[channel]
                    rows.append(RawMessage(topic, t, types[topic], buf[body + 22:pos]))
            elif op == _OP_CHANNEL:
                channel, _, size = unpack("<HHI", buf, body)
                topic = buf[body + 8:body + 8 + size].decode()
                if topic in types:
                    channels[channel] = topic
            elif op == _OP_CHUNK:
                _, _, size, crc, n = unpack("<QQQII", buf, body)
                compression = buf[body + 32:body + 32 + n].decode()
                start = body + 32 + n + 8
                length = unpack("<Q", buf, start - 8)[0]
                chunk = decompress(buf[start:start + length], compression, size, crc)
                walk(chunk, 0, len(chunk))
            elif op in (_OP_DATA_END, _OP_FOOTER):
                return

    walk(data, len(_MCAP_MAGIC), len(data))
    return rows


def _open(path):
    from rosbags.rosbag2 import Reader

    path = Path(path)
    if not (path / "metadata.yaml").is_file():
        raise BagError(f"{path}: not a bag folder (no metadata.yaml)")
    try:
        reader = Reader(path)
        reader.open()
    except Exception as err:
        raise BagError(f"{path}: unreadable bag ({type(err).__name__}: {first_line(err)})") \
            from None
    return _Closing(reader)


class _Closing:
    def __init__(self, reader):
        self.reader = reader

    def __enter__(self):
        return self.reader

    def __exit__(self, *exc):
        self.reader.close()


def first_line(err: Exception) -> str:
    """First line of an exception's message (for one-line error reports)."""
    text = str(err).strip().splitlines()
    return text[0] if text else type(err).__name__
