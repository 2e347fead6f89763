"""Trial bags: rosbag2 folders of one MCAP file, written and read here.

A bag folder holds ``metadata.yaml`` and one ``.mcap`` file, the layout ``ros2 bag record -s
mcap`` produces, so ``ros2 bag play``, Foxglove and the ``mcap`` tools open it. Payloads are CDR
laid out by :mod:`ins_gnss_ros.io.cdr` (padding zero: the same messages give the same bytes),
and read back into the rclpy message classes, so a replay feeds the nodes the same objects DDS
would deliver. :mod:`ins_gnss_ros.io.mcap_writer` writes the container a chunk of messages at
a time (rosbags' writer took five Python writes per message, a sizeable part of a replay:
docs/results/live_cost.md); ``rosbags``' typestore supplies the message definitions and type
hashes that MCAP stores as schemas and metadata.yaml lists (the project's own
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

import numpy as np
import yaml

from ..params_io import ParamsFileError, load_yaml_file
from .cdr import CdrLayoutError, Unsupported, codec, field_reader
from .mcap_reader import McapReader, RawMessage
from .mcap_writer import CHUNK_SIZE, MESSAGE_HEAD_SIZE, McapWriter
from .messages import MessageTypeError, msg_class, msgtype_of, template
from .stamps import msg_stamp_ns

#: Package whose .msg files are registered in the typestore besides the ROS 2 Jazzy ones.
CUSTOM_PACKAGE = "ins_gnss_msgs"
#: Newest rosbag2 metadata version read (Jazzy writes 9).
METADATA_VERSION = 9
#: The Header record's library and metadata.yaml's ros_distro of the bags written here.
LIBRARY = "ins_gnss_ros.io.mcap_writer"
ROS_DISTRO = "jazzy"

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
    writes them a chunk at a time (the producer hands them in stamp order).

    Example
    -------
    >>> with BagWriter("bags/run") as bag:
    ...     bag.write("imu/data_raw", imu_msg)

    Sorting at the end lets a producer write each sensor stream in turn; a bag of a few hundred
    thousand small messages fits in memory comfortably. A producer of hours of output in stamp
    order (trial smooth) writes ``ordered``: the memory is then one MCAP chunk's.

    The container is written by :class:`~ins_gnss_ros.io.mcap_writer.McapWriter` (profile
    ``ros2``, a channel per topic with schema encoding ``ros2msg`` and message encoding ``cdr``,
    zstd chunks: rosbag2's "storage" compression, which the mcap plugin, Foxglove and the mcap
    tools read natively), with rosbag2's ``rosbag2`` metadata record and ``metadata.yaml``
    (version 9) beside it, as ``ros2 bag record -s mcap`` leaves them.
    """

    def __init__(self, path, ordered: bool = False):
        self.path = Path(path)
        if self.path.exists():
            raise BagError(f"{self.path} exists: choose a new output folder")
        self._ordered = ordered
        # Per topic (absolute name, in order of first write): its type, and its message count
        # and channel id once written. Written topic names, relative ones too, map to its index.
        self._names: list[str] = []
        self._msgtypes: list[str] = []
        self._written: list[int] = []
        self._channel_ids: list[int] = []
        self._schema_ids: dict[str, int] = {}   # per type
        self._index_of: dict[str, tuple[int, str]] = {}
        # Messages not written yet: topic index, log time, payload.
        self._topic_rows: list[int] = []
        self._times: list[int] = []
        self._payloads: list[bytes] = []
        self._buffered = 0      # record bytes of an ordered writer's pending chunk
        self._count = 0
        self._last_ns = -1
        self._span = None       # (first, last) log time written
        self._mcap = None       # open from the first chunk (ordered) or the close on

    def write(self, topic: str, msg, t_ns: int | None = None) -> None:
        """Queue ``msg`` on ``topic`` at log time ``t_ns`` (default: its header stamp)."""
        msgtype, encode = _writing(type(msg))
        self.write_raw(topic, msgtype, msg_stamp_ns(msg) if t_ns is None else t_ns,
                       encode(msg))

    def write_raw(self, topic: str, msgtype: str, t_ns: int, data: bytes) -> None:
        """Queue a serialised (CDR) message of type ``msgtype`` on ``topic`` at ``t_ns``."""
        entry = self._index_of.get(topic)
        if entry is None or entry[1] != msgtype:
            entry = self._topic(topic, msgtype)
        t_ns = int(t_ns)
        if self._ordered:
            if t_ns < self._last_ns:
                raise BagError(f"{self.path}: {resolve(topic)} at {t_ns} ns comes after "
                               f"{self._last_ns} ns: an ordered writer takes messages in "
                               "stamp order")
            self._last_ns = t_ns
            self._buffered += len(data) + MESSAGE_HEAD_SIZE
        self._topic_rows.append(entry[0])
        self._times.append(t_ns)
        self._payloads.append(data)
        self._count += 1
        if self._buffered >= CHUNK_SIZE:
            self._flush()

    def _topic(self, topic: str, msgtype: str) -> tuple[int, str]:
        """(index, type) of a topic written for the first time under this name."""
        name = resolve(topic)
        if name in self._names:
            index = self._names.index(name)
            if self._msgtypes[index] != msgtype:
                raise BagError(f"topic {name} carries {self._msgtypes[index]}, not {msgtype}")
        else:
            index = len(self._names)
            self._names.append(name)
            self._msgtypes.append(msgtype)
            self._written.append(0)
            self._channel_ids.append(0)
        self._index_of[topic] = index, msgtype
        return index, msgtype

    def __len__(self) -> int:
        return self._count

    def write_all(self, topic: str, msgs: Iterable) -> None:
        for msg in msgs:
            self.write(topic, msg)

    def close(self) -> Path:
        if not self._ordered:
            # By stamp, ties in writing order (a stable sort); channels in name order.
            order = np.argsort(np.array(self._times, np.int64), kind="stable")
            self._topic_rows = [self._topic_rows[k] for k in order.tolist()]
            self._times = [self._times[k] for k in order.tolist()]
            self._payloads = [self._payloads[k] for k in order.tolist()]
            for index in sorted(range(len(self._names)), key=self._names.__getitem__):
                self._channel(index)
        self._flush()
        mcap = self._open()
        info = self._info()
        mcap.add_metadata("rosbag2", {"serialized_metadata": yaml.safe_dump(
            info, default_flow_style=False).strip()})
        mcap.close()
        _write_text(self.path / "metadata.yaml",
                    yaml.safe_dump({"rosbag2_bagfile_information": info},
                                   default_flow_style=False))
        return self.path

    def _flush(self) -> None:
        """Write the pending messages (in the order held) as MCAP chunks."""
        if not self._payloads:
            return
        rows = np.array(self._topic_rows, np.intp)
        for index in np.unique(rows).tolist():
            self._channel(index)
        times = np.array(self._times, np.int64)
        self._open().write_messages(np.array(self._channel_ids, np.uint16)[rows], times,
                                    self._payloads)
        for index, n in enumerate(np.bincount(rows, minlength=len(self._names)).tolist()):
            self._written[index] += n
        first, last = int(times.min()), int(times.max())
        self._span = (first, last) if self._span is None else \
            (min(first, self._span[0]), max(last, self._span[1]))
        self._topic_rows, self._times, self._payloads = [], [], []
        self._buffered = 0

    def _open(self) -> McapWriter:
        if self._mcap is None:
            self.path.mkdir(parents=True)
            self._mcap = McapWriter(self.path / f"{self.path.name}.mcap", profile="ros2",
                                    library=LIBRARY)
        return self._mcap

    def _channel(self, index: int) -> int:
        """The channel id of topic ``index``, its schema and channel written on first use."""
        if not self._channel_ids[index]:
            mcap = self._open()
            msgtype = self._msgtypes[index]
            if msgtype not in self._schema_ids:
                self._schema_ids[msgtype] = mcap.add_schema(msgtype, "ros2msg",
                                                            _definition(msgtype)[0].encode())
            # No QoS offered (a recording's publishers are the replay's): rosbag2's empty list.
            self._channel_ids[index] = mcap.add_channel(
                self._names[index], self._schema_ids[msgtype], "cdr",
                {"offered_qos_profiles": "[]"})
        return self._channel_ids[index]

    def _info(self) -> dict:
        """rosbag2's bag information (what ``ros2 bag info`` shows), metadata version 9."""
        first, last = self._span or (0, 0)
        file = f"{self.path.name}.mcap"
        topics = sorted((id_, index) for index, id_ in enumerate(self._channel_ids) if id_)
        return {
            "version": 9, "storage_identifier": "mcap", "relative_file_paths": [file],
            "duration": {"nanoseconds": last - first},
            "starting_time": {"nanoseconds_since_epoch": first},
            "message_count": self._count,
            "topics_with_message_count": [{
                "topic_metadata": {
                    "name": self._names[index], "type": self._msgtypes[index],
                    "serialization_format": "cdr", "offered_qos_profiles": [],
                    "type_description_hash": _definition(self._msgtypes[index])[1]},
                "message_count": self._written[index]} for _, index in topics],
            "compression_format": "", "compression_mode": "",
            "files": [{"path": file, "starting_time": {"nanoseconds_since_epoch": first},
                       "duration": {"nanoseconds": last - first},
                       "message_count": self._count}],
            "custom_data": None, "ros_distro": ROS_DISTRO,
        }

    def __enter__(self) -> "BagWriter":
        return self

    def __exit__(self, exc_type, *exc) -> None:
        # An ordered bag holds what was written before a failure, like a recording cut short.
        if exc_type is None or self._mcap is not None:
            self.close()


@lru_cache(maxsize=None)
def _definition(msgtype: str) -> tuple[str, str]:
    """(``ros2msg`` definition with its dependencies, RIHS01 type hash) of a type, from the
    typestore: what rosbag2 stores as a channel's schema and in metadata.yaml."""
    store = typestore()
    return store.generate_msgdef(msgtype, ros_version=2)[0], store.hash_rihs01(msgtype)


def _write_text(path: Path, text: str) -> None:
    # Through a temporary name: a reader never sees half a metadata.yaml.
    tmp = path.with_suffix(".yaml.tmp")
    tmp.write_text(text, "utf8")
    tmp.replace(path)


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


#: Types given trailing fields after bags were recorded with them: type name -> the bytes
#: those fields take (aligned where the older layout ends). A payload of the older layout is
#: read with them zero, so that every reader sees one layout.
EXTENDED_TYPES = {"ins_gnss_msgs/msg/ImuDelta": 16}  # bridged_*_variance, 2026-12-05


def current_layout(raw: RawMessage) -> RawMessage:
    """``raw`` with the fields its type gained since (:data:`EXTENDED_TYPES`) zero, when its
    payload is exactly that much short of the current layout; else as it is."""
    extra = EXTENDED_TYPES.get(raw.msgtype)
    if extra is None:
        return raw
    check = field_reader(raw.msgtype, ())

    def fits(data) -> bool:
        try:
            check(data)
        except CdrLayoutError:
            return False
        return True

    data = bytes(raw.data) + bytes(extra)
    # (the reader ignores bytes after the layout: one byte fewer must not fit)
    if fits(raw.data) or not fits(data) or fits(data[:-1]):
        return raw
    return raw._replace(data=data)


def iter_raw(path, topics: Iterable[str] | None = None) -> Iterator[RawMessage]:
    """The messages of a bag (or of ``topics``) undecoded, streamed in stamp order, ties in
    writing order; memory bounded by a chunk per MCAP file, not by the bag's length. A type
    extended since the bag was recorded is given in its current layout
    (:func:`current_layout`).

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
            rows = heapq.merge(*(_mcap_rows(path, file, info, listed, wanted)
                                 for file in _files(path, info)), key=itemgetter(1))
        else:
            rows = _read_with_rosbags(path, wanted)
        yield from map(current_layout, rows)
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
