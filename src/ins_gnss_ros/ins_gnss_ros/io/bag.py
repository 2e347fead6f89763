"""Trial bags: rosbag2 folders of one MCAP file, written with ``rosbags`` and read here.

A bag folder holds ``metadata.yaml`` and one ``.mcap`` file, the layout ``ros2 bag record -s
mcap`` produces, so ``ros2 bag play``, Foxglove and the ``mcap`` tools open it. Payloads are CDR
laid out by :mod:`ins_gnss_ros.io.cdr` (padding zero: the same messages give the same bytes),
and read back into the rclpy message classes, so a replay feeds the nodes the same objects DDS
would deliver. ``rosbags``' public :class:`~rosbags.rosbag2.Writer` writes the container; its
typestore supplies the message definitions that MCAP stores as schemas (the project's own
``ins_gnss_msgs`` are registered from their .msg files).

Reading parses ``metadata.yaml`` and walks the MCAP files (:mod:`ins_gnss_ros.io.mcap_reader`),
which also reads a recording that was cut short, up to where it ends, with a warning on the
``ins_gnss_ros.io.bag`` logger saying what was lost; bags of other storage (sqlite3) or with
whole-file compression go through ``rosbags``' public :class:`~rosbags.rosbag2.Reader`.
Readers for which speed matters (the offline replay) take the undecoded rows (:func:`iter_raw`,
streamed: an hours-long bag is never held whole; :func:`read_raw` as a list)
and decode fixed-layout topics in bulk (:func:`ins_gnss_ros.io.cdr.decode_columns`);
:meth:`BagWriter.write_raw` takes payloads encoded that way.

The log time of every message is its header stamp (sensor time; CONTRACT.md "Stamps"); messages
are written in stamp order and a reader returns them in stamp order, ties in writing order.
"""
from __future__ import annotations

import heapq
import logging
import os
from dataclasses import dataclass
from functools import lru_cache
from operator import itemgetter
from pathlib import Path, PurePath
from typing import Any, Iterable, Iterator

from ..params_io import ParamsFileError, load_yaml_file
from .cdr import Unsupported, codec
from .mcap_reader import McapReader, RawMessage
from .messages import MessageTypeError, msg_class, msgtype_of, template
from .stamps import msg_stamp_ns

#: Package whose .msg files are registered in the typestore besides the ROS 2 Jazzy ones.
CUSTOM_PACKAGE = "ins_gnss_msgs"
#: Newest rosbag2 metadata version read (Jazzy writes 9).
METADATA_VERSION = 9

log = logging.getLogger(__name__)


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
    return _writing(type(msg))[1](msg)


@lru_cache(maxsize=None)
def _writing(cls) -> tuple:
    """(type name, encoder) of an rclpy message class, looked up once per class (a replay
    records a few hundred thousand messages of a dozen types)."""
    try:
        return msgtype_of(template(cls)), codec(cls).encode
    except Unsupported as err:
        raise BagError(f"cannot write {msgtype_of(template(cls))}: {err}") from None


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
    """Collects messages and writes them, sorted by stamp, when closed; or, ``ordered``,
    writes each at once (the producer hands them in stamp order).

    Example
    -------
    >>> with BagWriter("bags/run") as bag:
    ...     bag.write("imu/data_raw", imu_msg)

    Sorting at the end lets a producer write each sensor stream in turn; a bag of a few hundred
    thousand small messages fits in memory comfortably. A producer of hours of output in stamp
    order (trial smooth) writes ``ordered``: the memory is then one MCAP chunk's.
    """

    def __init__(self, path, ordered: bool = False):
        self.path = Path(path)
        if self.path.exists():
            raise BagError(f"{self.path} exists: choose a new output folder")
        self._rows: list[tuple[int, int, str, bytes]] = []
        self._types: dict[str, str] = {}
        self._ordered = ordered
        self._count = 0
        self._last_ns = -1
        self._writer = None   # the rosbags writer, open from the first ordered message on
        self._connections: dict[str, Any] = {}

    def write(self, topic: str, msg, t_ns: int | None = None) -> None:
        """Queue ``msg`` on ``topic`` at log time ``t_ns`` (default: its header stamp)."""
        msgtype, encode = _writing(type(msg))
        self.write_raw(topic, msgtype, msg_stamp_ns(msg) if t_ns is None else t_ns,
                       encode(msg))

    def write_raw(self, topic: str, msgtype: str, t_ns: int, data: bytes) -> None:
        """Queue a serialised (CDR) message of type ``msgtype`` on ``topic`` at ``t_ns``."""
        topic = resolve(topic)
        if self._types.setdefault(topic, msgtype) != msgtype:
            raise BagError(f"topic {topic} carries {self._types[topic]}, not {msgtype}")
        t_ns = int(t_ns)
        if self._ordered:
            if t_ns < self._last_ns:
                raise BagError(f"{self.path}: {topic} at {t_ns} ns comes after {self._last_ns} "
                               "ns: an ordered writer takes messages in stamp order")
            self._last_ns = t_ns
            self._open().write(self._connection(topic), t_ns, data)
        else:
            self._rows.append((t_ns, self._count, topic, data))
        self._count += 1

    def __len__(self) -> int:
        return self._count

    def write_all(self, topic: str, msgs: Iterable) -> None:
        for msg in msgs:
            self.write(topic, msg)

    def close(self) -> Path:
        # (stamp, writing order) decide: the order is unique, so no key function is needed.
        self._rows.sort()
        writer = self._open()
        for topic in sorted(self._types):   # channels in name order, as ever
            self._connection(topic)
        for t, _, topic, data in self._rows:
            writer.write(self._connection(topic), t, data)
        self._rows = []
        writer.close()
        return self.path

    def _open(self):
        if self._writer is None:
            from rosbags.rosbag2 import CompressionFormat, CompressionMode, StoragePlugin, Writer

            self.path.parent.mkdir(parents=True, exist_ok=True)
            self._writer = Writer(self.path, version=9, storage_plugin=StoragePlugin.MCAP)
            # zstd-compressed MCAP chunks (rosbag2's "storage" compression, which the mcap
            # plugin, Foxglove and the mcap tools read natively): IMU messages shrink fourfold.
            self._writer.set_compression(CompressionMode.STORAGE, CompressionFormat.ZSTD)
            self._writer.open()
        return self._writer

    def _connection(self, topic: str):
        if topic not in self._connections:
            self._connections[topic] = self._writer.add_connection(
                topic, self._types[topic], typestore=typestore())
        return self._connections[topic]

    def __enter__(self) -> "BagWriter":
        return self

    def __exit__(self, exc_type, *exc) -> None:
        # An ordered bag holds what was written before a failure, like a recording cut short.
        if exc_type is None or self._writer is not None:
            self.close()


def bag_topics(path) -> dict[str, str]:
    """Topics of a bag with their type names (from its metadata.yaml)."""
    return {topic: msgtype for topic, (msgtype, _) in _metadata(Path(path))[1].items()}


def bag_message_counts(path) -> dict[str, int]:
    """Topics of a bag with their message counts (from its metadata.yaml: what was recorded,
    more than a file cut short holds)."""
    return {topic: count for topic, (_, count) in _metadata(Path(path))[1].items()}


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
    """Like :func:`read_bag`, streaming (:func:`iter_raw`, each message decoded as it comes)."""
    for raw in iter_raw(path, topics):
        yield BagMessage(raw.topic, raw.t_ns, decode_message(raw, path))


def read_raw(path, topics: Iterable[str] | None = None) -> list[RawMessage]:
    """The messages of a bag (or of ``topics``) undecoded, in stamp order, ties in writing
    order: for readers that decode in bulk (:mod:`ins_gnss_ros.io.cdr`) or not at all
    (:func:`iter_raw` as a list)."""
    return list(iter_raw(path, topics))


def iter_raw(path, topics: Iterable[str] | None = None) -> Iterator[RawMessage]:
    """The messages of a bag (or of ``topics``) undecoded, streamed in stamp order, ties in
    writing order; memory bounded by a chunk per MCAP file, not by the bag's length.

    A bag whose MCAP file ends early (a recording that was killed) is read up to where it
    ends; a warning on the ``ins_gnss_ros.io.bag`` logger says how much was read, once the
    file's messages have been handed on.

    Raises (while iterating)
    ------
    BagError
        One line naming the bag and what is wrong with it.
    """
    path = Path(path)
    info, listed = _metadata(path)
    wanted = None if topics is None else {resolve(t) for t in topics}
    try:
        if info["storage_identifier"] == "mcap" and not info.get("compression_mode"):
            # Files in stamp order each; merged stably (ties in file order, as written).
            yield from heapq.merge(*(_mcap_rows(path, file, info, listed, wanted)
                                     for file in _files(path, info)), key=itemgetter(1))
        else:
            yield from _read_with_rosbags(path, wanted)
    except BagError:
        raise
    except Exception as err:  # mcap_reader, rosbags and the decompressors raise many types
        raise BagError(f"{path}: unreadable bag ({type(err).__name__}: {first_line(err)})") \
            from None


def _mcap_rows(path: Path, file: Path, info: dict, listed: dict, wanted) -> Iterator[RawMessage]:
    """One MCAP file's messages, its channel types checked against metadata.yaml's (rosbag2
    would mis-decode), and a warning once they are read if the file was cut short."""
    def check(topic, msgtype):
        if topic in listed and listed[topic][0] != msgtype:
            raise BagError(f"{path}: {topic} carries {msgtype}, metadata.yaml says "
                           f"{listed[topic][0]}")

    reader = McapReader(file, wanted, on_channel=check)
    yield from reader
    if reader.cut_at is not None:
        _warn_cut(path, file, reader, info, listed, wanted)


def _metadata(path: Path) -> tuple[dict, dict]:
    """The rosbag2 metadata of a bag folder, and {topic: (type, message count)} from it."""
    if not (path / "metadata.yaml").is_file():
        raise BagError(f"{path}: not a bag folder (no metadata.yaml)")
    try:
        info = load_yaml_file(path / "metadata.yaml")["rosbag2_bagfile_information"]
        if info["version"] > METADATA_VERSION:
            raise BagError(f"{path}: rosbag2 metadata version {info['version']} (this reads "
                           f"up to {METADATA_VERSION})")
        if info["storage_identifier"] not in ("mcap", "sqlite3"):
            raise BagError(f"{path}: storage {info['storage_identifier']!r} is not supported")
        listed = {}
        for entry in info["topics_with_message_count"]:
            meta = entry["topic_metadata"]
            if meta["serialization_format"] != "cdr":
                raise BagError(f"{path}: {meta['name']} is {meta['serialization_format']}, "
                               "not CDR")
            listed[meta["name"]] = (meta["type"], int(entry["message_count"]))
    except BagError:
        raise
    except ParamsFileError as err:
        raise BagError(f"{path}: unreadable bag ({first_line(err)})") from None
    except (KeyError, TypeError, ValueError, AttributeError) as err:
        raise BagError(f"{path}: malformed metadata.yaml ({type(err).__name__}: "
                       f"{first_line(err)})") from None
    return info, listed


def _files(path: Path, info: dict) -> list[Path]:
    files = [path / PurePath(name).name for name in info["relative_file_paths"]]
    missing = [file.name for file in files if not file.is_file()]
    if missing:
        raise BagError(f"{path}: missing storage file(s) {', '.join(missing)}")
    return files


def _warn_cut(path: Path, file: Path, reader: McapReader, info: dict, listed: dict,
              wanted) -> None:
    """Log what a cut MCAP file (a recording that was killed) lost."""
    n = reader.count
    expected = sum(count for topic, (_, count) in listed.items()
                   if wanted is None or topic in wanted)
    read = f"{n:,} of the {expected:,} messages metadata.yaml lists" \
        if expected > n else f"{n:,} messages"
    try:
        start = info["starting_time"]["nanoseconds_since_epoch"]
        duration = info["duration"]["nanoseconds"] * 1e-9
        span = f", the first {(reader.last_ns - start) * 1e-9:.1f} s of " \
               f"{duration:.1f} s" if n else ""
    except (KeyError, TypeError):
        span = ""
    where = "between records" if reader.cut_at == reader.size else \
        f"inside a record that starts at byte {reader.cut_at:,}"
    log.warning("%s: %s ends at byte %s, %s, without the end of its data (the recording was "
                "cut short): read %s%s; the rest is lost", path, file.name,
                f"{reader.size:,}", where, read, span)


def _read_with_rosbags(path: Path, wanted) -> Iterator[RawMessage]:
    """The rows of a bag that is not plain MCAP, through rosbags' public reader (in stamp
    order, streamed)."""
    from rosbags.rosbag2 import Reader

    with Reader(path) as reader:
        connections = [c for c in reader.connections if wanted is None or c.topic in wanted]
        if connections:
            for c, t, data in reader.messages(connections=connections):
                yield RawMessage(c.topic, t, c.msgtype, data)


def first_line(err: Exception) -> str:
    """First line of an exception's message (for one-line error reports)."""
    text = str(err).strip().splitlines()
    return text[0] if text else type(err).__name__
