"""Trial bags: rosbag2-compatible MCAP folders written and read with ``rosbags``.

A bag folder holds ``metadata.yaml`` and one ``.mcap`` file, the layout ``ros2 bag record -s
mcap`` produces, so ``ros2 bag play``, Foxglove and the ``mcap`` tools open it. Payloads are CDR,
serialised by rclpy itself (``rclpy.serialization``, the code path rosbag2 uses), and read back
into the rclpy message classes, so a replay feeds the nodes the same objects DDS would deliver.
``rosbags`` is used only for the container: its typestore supplies the message definitions that
MCAP stores as schemas (the project's own ``ins_gnss_msgs`` are registered from their .msg files).

The log time of every message is its header stamp (sensor time; CONTRACT.md "Stamps"); messages
are written in stamp order and a reader returns them in stamp order, ties in writing order.
"""
from __future__ import annotations

import os
from dataclasses import dataclass
from functools import lru_cache
from importlib import import_module
from pathlib import Path
from typing import Any, Iterable, Iterator

from rclpy.serialization import deserialize_message, serialize_message
from rosbags.rosbag2 import Reader, StoragePlugin, Writer
from rosbags.typesys import Stores, get_types_from_msg, get_typestore

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


def msgtype_of(msg) -> str:
    """ROS type name ``pkg/msg/Name`` of an rclpy message object."""
    package = type(msg).__module__.split(".")[0]
    return f"{package}/msg/{type(msg).__name__}"


@lru_cache(maxsize=None)
def msg_class(msgtype: str):
    """rclpy class of a type name ``pkg/msg/Name`` (also ``pkg/Name``)."""
    parts = msgtype.split("/")
    if len(parts) not in (2, 3) or (len(parts) == 3 and parts[1] != "msg"):
        raise BagError(f"not a message type name: {msgtype!r}")
    try:
        return getattr(import_module(f"{parts[0]}.msg"), parts[-1])
    except (ImportError, AttributeError):
        raise BagError(f"message type {msgtype!r} is not installed") from None


def stamp_ns(msg) -> int:
    """Header stamp of a message in ns (rosgraph/Clock: its clock field)."""
    stamp = msg.header.stamp if hasattr(msg, "header") else msg.clock
    return stamp.sec * 1_000_000_000 + stamp.nanosec


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
        topic = resolve(topic)
        msgtype = msgtype_of(msg)
        if self._types.setdefault(topic, msgtype) != msgtype:
            raise BagError(f"topic {topic} carries {self._types[topic]}, not {msgtype}")
        t = stamp_ns(msg) if t_ns is None else int(t_ns)
        self._rows.append((t, len(self._rows), topic, serialize_message(msg)))

    def write_all(self, topic: str, msgs: Iterable) -> None:
        for msg in msgs:
            self.write(topic, msg)

    def close(self) -> Path:
        self._rows.sort(key=lambda row: row[:2])
        self.path.parent.mkdir(parents=True, exist_ok=True)
        store = typestore()
        writer = Writer(self.path, version=9, storage_plugin=StoragePlugin.MCAP)
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
    """All messages of a bag (or of ``topics``), decoded, in stamp order.

    Raises
    ------
    BagError
        One line naming the bag and what is wrong with it.
    """
    return list(iter_bag(path, topics))


def iter_bag(path, topics: Iterable[str] | None = None) -> Iterator[BagMessage]:
    """Like :func:`read_bag`, decoding lazily (rows are sorted by stamp first)."""
    wanted = None if topics is None else {resolve(t) for t in topics}
    try:
        with _open(path) as reader:
            connections = [c for c in reader.connections if wanted is None or c.topic in wanted]
            classes = {c.id: msg_class(c.msgtype) for c in connections}
            rows = [(t, i, c.topic, c.id, data) for i, (c, t, data)
                    in enumerate(reader.messages(connections=connections))] if connections else []
    except BagError:
        raise
    except Exception as err:  # rosbags, mcap and yaml raise many types on a damaged file
        raise BagError(f"{path}: unreadable bag ({type(err).__name__}: {_first_line(err)})") \
            from None
    rows.sort(key=lambda row: row[:2])
    for t, _, topic, cid, data in rows:
        try:
            msg = deserialize_message(bytes(data), classes[cid])
        except Exception as err:
            raise BagError(f"{path}: message on {topic} at {t} ns does not decode "
                           f"({_first_line(err)})") from None
        yield BagMessage(topic, t, msg)


def _open(path):
    path = Path(path)
    if not (path / "metadata.yaml").is_file():
        raise BagError(f"{path}: not a bag folder (no metadata.yaml)")
    try:
        reader = Reader(path)
        reader.open()
    except Exception as err:
        raise BagError(f"{path}: unreadable bag ({type(err).__name__}: {_first_line(err)})") \
            from None
    return _Closing(reader)


class _Closing:
    def __init__(self, reader):
        self.reader = reader

    def __enter__(self):
        return self.reader

    def __exit__(self, *exc):
        self.reader.close()


def _first_line(err: Exception) -> str:
    text = str(err).strip().splitlines()
    return text[0] if text else type(err).__name__
