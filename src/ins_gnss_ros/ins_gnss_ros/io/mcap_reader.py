"""The messages of an MCAP file, read record by record, also from a file cut short.

MCAP (specification: https://mcap.dev/spec) is a magic, then records: an opcode byte, a uint64
length and the content. The data section holds schemas (id, name = ROS type ``pkg/msg/Name``),
channels (id, schema id, topic, message encoding), messages (channel id u16, sequence u32, log
time u64, publish time u64, payload) and chunks (start and end time, uncompressed size and CRC,
compression, compressed records); a summary and the footer follow. This walks the data section
in file order and never needs the summary, so a recording that was killed (no summary or
footer, the file ending inside a chunk or a record) is read up to its last complete message:
the complete records of a cut chunk are recovered by decompressing what there is of it. The
messages stream out in log-time order a chunk at a time (:class:`McapReader`), so reading an
hours-long recording costs the memory of its overlapping chunks, not of the whole file.

Why not a library reader: ``mcap``'s and rosbags' readers build a Python object per record (and
rosbags merges chunks through a heap), several microseconds per message, about twice what this
costs, which was a sizeable part of the offline replay (docs/results/replay.md); both also need
the summary or footer of a complete file. Chunks are decompressed with ``zstandard`` and ``lz4``.
"""
from __future__ import annotations

import math
import mmap
import os
import struct
from binascii import crc32
from bisect import bisect_right
from operator import itemgetter
from pathlib import Path
from typing import Iterator, NamedTuple

import lz4.frame
import zstandard

#: File magic and the record opcodes read here (MCAP specification, "Records").
MAGIC = b"\x89MCAP0\r\n"
_OP_HEADER, _OP_FOOTER, _OP_SCHEMA, _OP_CHANNEL, _OP_MESSAGE, _OP_CHUNK, _OP_DATA_END = \
    0x01, 0x02, 0x03, 0x04, 0x05, 0x06, 0x0F
#: Largest header record taken for one (it holds a profile and a library name): a file whose
#: first record is not a header of at most this size is not MCAP, whatever its magic says.
_MAX_HEADER = 1 << 16


class McapError(ValueError):
    """A file that is not MCAP, or a damaged record (not a cut: cuts are reported)."""


class RawMessage(NamedTuple):
    """One undecoded message: absolute topic, log time (ns), type name and CDR payload (a
    named tuple: a bag has a few hundred thousand of them)."""

    topic: str
    t_ns: int
    msgtype: str
    data: bytes


class McapReader:
    """The messages of an MCAP file with CDR payloads (or of ``topics``), streamed in log-time
    order (ties in file order), holding in memory only the chunks whose time spans overlap.

    A first pass walks the data section's top-level records (the file is memory-mapped, so
    this touches only record headers); each chunk header gives the earliest log time in it.
    The second pass decompresses chunk by chunk and hands on every message earlier than the
    earliest start of the chunks still to come: a recording whose chunks follow each other
    in time (what rosbag2 and ``BagWriter`` write) keeps one chunk in memory, any other is
    still returned in order. A chunk that holds a message earlier than its header says is an
    error (the order could not be kept).

    Example
    -------
    >>> reader = McapReader("bag/bag_0.mcap", {"/imu/data_raw"})
    >>> rows = list(reader)          # RawMessage list in stamp order
    >>> reader.cut_at is None        # the file was complete

    Parameters
    ----------
    path : path
        The ``.mcap`` file.
    topics : set of str, optional
        Only these (absolute) topics.
    on_channel : callable, optional
        ``on_channel(topic, type name)`` for each channel read, before any of its messages.

    Attributes (complete once the messages have been read)
    ----------
    channels : set of (str, str)
        (topic, type name) of the channels read.
    cut_at : int or None
        When the file ends before its data section does (a recording cut short): the offset
        of the record it ends in, or its size when it ends between records (the complete
        messages of a cut chunk are read). None for a complete file.
    size : int
        File size, bytes.
    count, last_ns : int
        Messages handed on, and the latest log time among them (0 without any).

    Raises (while iterating)
    ------
    McapError
        Not an MCAP file, a channel without a schema or not CDR, an unknown compression, a
        chunk whose size or checksum does not match.
    """

    def __init__(self, path, topics=None, on_channel=None):
        self.path, self.topics, self.on_channel = Path(path), topics, on_channel
        self.channels: set = set()
        self.cut_at: int | None = None
        self.size = self.count = self.last_ns = 0
        self._schemas: dict[int, str] = {}
        self._channels: dict[int, tuple[str, str]] = {}

    def __iter__(self) -> Iterator[RawMessage]:
        with open(self.path, "rb") as f:
            self.size = os.fstat(f.fileno()).st_size
            if self.size == 0:
                self.cut_at = 0
                return
            buf = mmap.mmap(f.fileno(), 0, access=mmap.ACCESS_READ)
        try:
            yield from self._messages(buf)
        finally:
            buf.close()

    def _messages(self, buf) -> Iterator[RawMessage]:
        name, size = self.path.name, self.size
        if size <= len(MAGIC) and MAGIC.startswith(buf[:size]):  # cut before its first record
            self.cut_at = 0
            return
        if buf[:len(MAGIC)] != MAGIC or (size >= len(MAGIC) + 9 and (
                buf[len(MAGIC)] != _OP_HEADER
                or struct.unpack_from("<Q", buf, len(MAGIC) + 1)[0] > _MAX_HEADER)):
            raise McapError(f"{name}: not an MCAP file")
        records, cut = _records(buf, len(MAGIC), size)
        cut_chunk = None   # body offset of a chunk the file ends in
        if cut is not None and cut + 9 <= size and buf[cut] == _OP_CHUNK:
            cut_chunk = cut + 9
            records.append((_OP_CHUNK, cut_chunk, size))
        self.cut_at = cut
        units = _units(buf, records)
        # Earliest log time of the units after each one: what may still come.
        later = [math.inf] * len(units)
        for i in range(len(units) - 2, -1, -1):
            later[i] = min(units[i + 1][0], later[i + 1])
        pending: list = []
        t_of = itemgetter(1)
        for (start, unit), bound in zip(units, later):
            rows = []
            for op, body, stop in unit:
                if op == _OP_CHUNK:
                    rows += self._chunk(buf, body, stop, start, cut=body == cut_chunk)
                else:
                    self._record(buf, op, body, stop, rows)
            if rows:
                rows.sort(key=t_of)
                pending += rows
                pending.sort(key=t_of)   # two sorted runs: linear, stable
            k = bisect_right(pending, bound, key=t_of)
            if k:
                ready, pending = pending[:k], pending[k:]
                self.count += k
                self.last_ns = max(self.last_ns, ready[-1].t_ns)
                yield from ready

    def _record(self, buf, op, body, stop, rows) -> None:
        """Take one non-chunk record: a message into ``rows``, a schema or channel noted."""
        unpack = struct.unpack_from
        if op == _OP_MESSAGE:
            channel, _, t = unpack("<HIQ", buf, body)
            if channel in self._channels:
                topic, msgtype = self._channels[channel]
                rows.append(RawMessage(topic, t, msgtype, buf[body + 22:stop]))
        elif op == _OP_CHANNEL:
            channel, schema, size = unpack("<HHI", buf, body)
            topic = buf[body + 8:body + 8 + size].decode()
            if self.topics is None or topic in self.topics:
                (n,) = unpack("<I", buf, body + 8 + size)
                encoding = buf[body + 12 + size:body + 12 + size + n].decode()
                if schema not in self._schemas or encoding != "cdr":
                    raise McapError(f"{self.path.name}: channel {topic} has "
                                    f"{'no schema' if schema not in self._schemas else encoding}"
                                    " (a rosbag2 channel has a ROS type and CDR payloads)")
                self._channels[channel] = topic, self._schemas[schema]
                self.channels.add(self._channels[channel])
                if self.on_channel is not None:
                    self.on_channel(topic, self._schemas[schema])
        elif op == _OP_SCHEMA:
            schema, size = unpack("<HI", buf, body)
            self._schemas[schema] = buf[body + 6:body + 6 + size].decode()

    def _chunk(self, buf, body, stop, start, cut) -> list:
        """The messages of the chunk at ``body`` (of a ``cut`` one, whose data ends at
        ``stop``: those of its complete records)."""
        if body + 32 > stop:
            return []
        _, _, size, crc, n = struct.unpack_from("<QQQII", buf, body)
        compression = buf[body + 32:body + 32 + n].decode()
        first = body + 32 + n + 8
        if first > stop:
            return []
        length = struct.unpack_from("<Q", buf, first - 8)[0]
        data = _decompress(self.path, buf[first:min(first + length, stop)], compression, size,
                           None if cut else crc)
        inner, end = _records(data, 0, len(data))
        if end != len(data) and not cut:
            raise McapError(f"{self.path.name}: a chunk ends inside a record")
        rows: list = []
        for op, b, s in inner:
            self._record(data, op, b, s, rows)
        if rows and min(r.t_ns for r in rows) < start:
            raise McapError(f"{self.path.name}: a chunk holds a message earlier than its "
                            "header's message start time")
        return rows


def _records(buf, pos, end) -> tuple[list, int | None]:
    """The complete records of ``buf[pos:end]`` as (opcode, body offset, end offset), and
    where they stop: None at the end of the data section (DataEnd or Footer), else the offset
    of the first record cut by ``end`` (``end`` itself when none is)."""
    records = []
    while pos < end:
        if pos + 9 > end:
            return records, pos
        op = buf[pos]
        body = pos + 9
        stop = body + struct.unpack_from("<Q", buf, pos + 1)[0]
        if stop > end:
            return records, pos
        if op in (_OP_DATA_END, _OP_FOOTER):
            return records, None
        records.append((op, body, stop))
        pos = stop
    return records, pos


def _units(buf, records) -> list:
    """The top-level records grouped into what is read at once: each chunk alone, each run of
    records between chunks together; with the earliest log time each may hold (a chunk's
    from its header, a run's from its messages)."""
    units: list = []
    run: list = []
    for op, body, stop in records:
        if op == _OP_CHUNK:
            if run:
                units.append((_earliest(buf, run), run))
                run = []
            start = struct.unpack_from("<Q", buf, body)[0] if body + 8 <= stop else math.inf
            units.append((start, [(op, body, stop)]))
        else:
            run.append((op, body, stop))
    if run:
        units.append((_earliest(buf, run), run))
    return units


def _earliest(buf, run) -> float:
    times = [struct.unpack_from("<Q", buf, body + 6)[0] for op, body, _ in run
             if op == _OP_MESSAGE]
    return min(times, default=math.inf)


def _decompress(path: Path, data: bytes, compression: str, size: int, crc: int | None) -> bytes:
    """The records of a chunk; ``crc`` None: the chunk is cut, decompress what there is."""
    try:
        if compression == "":
            raw = data
        elif compression == "zstd":
            raw = zstandard.ZstdDecompressor().decompressobj().decompress(data) \
                if crc is None else zstandard.ZstdDecompressor().decompress(
                    data, max_output_size=size)
        elif compression == "lz4":
            raw = lz4.frame.LZ4FrameDecompressor().decompress(data)
        else:
            raise McapError(f"{path.name}: unknown chunk compression {compression!r}")
    except McapError:
        raise
    except Exception as err:  # zstandard and lz4 raise their own types on damaged data
        if crc is None:
            return b""
        raise McapError(f"{path.name}: a chunk does not decompress ({err})") from None
    if crc is not None and (len(raw) != size or (crc and crc32(raw) != crc)):
        raise McapError(f"{path.name}: a chunk's size or checksum does not match")
    return raw
