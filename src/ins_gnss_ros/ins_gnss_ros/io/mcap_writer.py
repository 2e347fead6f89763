"""An MCAP file written a chunk of messages at a time, to the MCAP specification.

MCAP format specification (https://mcap.dev/spec, major version 0): the file is the magic
``89 4D 43 41 50 30 0D 0A``, a Header record, the data section, the summary section, the
summary offset section, a Footer record and the magic again. Every record is an opcode byte,
a uint64 content length and the content, little endian; a string is a uint32 byte length and
UTF-8, a map a uint32 byte length and its entries, a byte array a uint32 (schema data) or
uint64 (chunk records) length and the bytes. What this writes:

* data section: Schema (0x03) and Channel (0x04) records as they are added, before the first
  chunk that uses them; Chunk records (0x06: message start and end time, uncompressed size and
  CRC-32, compression ``zstd`` or ``""``, the Message records (0x05) in the order given), each
  followed by one Message Index record (0x07: (log time, offset in the chunk's records) pairs)
  per channel it holds; Metadata records (0x0C); Data End (0x0F) with the CRC-32 of every byte
  before it (magic included, as the specification's reference readers check it);
* summary section: the schemas and channels again, a Chunk Index (0x08) per chunk, a Metadata
  Index (0x0D) per metadata record and the Statistics (0x0B: counts, message time span, the
  message count of each channel); then a Summary Offset record (0x0E) per group and the Footer
  (0x02) with the CRC-32 of the summary up to and including its own offset fields.

:class:`McapWriter` takes messages in bulk (:meth:`McapWriter.write_messages`: channel ids, log
times, payloads) and assembles each chunk's records at once: the 31-byte message record heads
(opcode, length, channel, sequence, log and publish time) as one numpy structured array, joined
with the payloads, and the message indexes as numpy arrays, instead of a few Python writes per
message (the output bag of a car replay holds ~200k messages). The publish time is the log
time and the sequence 0, what rosbag2 writes for recorded messages without either.
"""
from __future__ import annotations

import struct
from binascii import crc32
from pathlib import Path

import numpy as np
import zstandard

from .mcap_reader import MAGIC

#: Record opcodes (MCAP specification, "Records").
OP_HEADER, OP_FOOTER, OP_SCHEMA, OP_CHANNEL, OP_MESSAGE, OP_CHUNK, OP_MESSAGE_INDEX, \
    OP_CHUNK_INDEX, OP_STATISTICS, OP_METADATA, OP_METADATA_INDEX, OP_SUMMARY_OFFSET, \
    OP_DATA_END = 0x01, 0x02, 0x03, 0x04, 0x05, 0x06, 0x07, 0x08, 0x0B, 0x0C, 0x0D, 0x0E, 0x0F
#: Uncompressed bytes of message records after which a chunk is closed (rosbag2's default
#: chunk size; readers hold a chunk at a time).
CHUNK_SIZE = 1 << 20
#: Head of a Message record: opcode, content length, channel id, sequence, log time, publish
#: time (packed: 31 bytes).
_MESSAGE_HEAD = np.dtype([("op", "u1"), ("length", "<u8"), ("channel", "<u2"),
                          ("sequence", "<u4"), ("log_time", "<u8"), ("publish_time", "<u8")])
#: Bytes of a Message record besides its payload.
MESSAGE_HEAD_SIZE = _MESSAGE_HEAD.itemsize
#: A Message Index entry: log time, offset of the message record in the chunk's records.
_INDEX_ENTRY = np.dtype([("log_time", "<u8"), ("offset", "<u8")])
_RECORD_HEAD = struct.Struct("<BQ")


class McapWriter:
    """Writes one MCAP file (see the module doc); a context manager that closes it.

    Example
    -------
    >>> with McapWriter("out.mcap", profile="ros2", library="ins_gnss_ros") as mcap:
    ...     schema = mcap.add_schema("std_msgs/msg/String", "ros2msg", b"string data")
    ...     channel = mcap.add_channel("/chatter", schema, "cdr", {})
    ...     mcap.write_messages([channel], [1_000], [payload])

    Parameters
    ----------
    path : path
        New file (an existing one is refused).
    profile, library : str
        The Header record's fields (``ros2`` for rosbag2 files).
    compression : str
        ``zstd`` or ``""`` (none).
    chunk_size : int
        Uncompressed message bytes per chunk (a chunk closes at the first message past it).
    """

    def __init__(self, path, profile: str, library: str, compression: str = "zstd",
                 chunk_size: int = CHUNK_SIZE):
        if compression not in ("zstd", ""):
            raise ValueError(f"chunk compression {compression!r}: zstd or none")
        self._file = Path(path).open("xb")
        self._pos = 0
        self._crc = 0
        self._compression = compression
        self._compress = zstandard.ZstdCompressor().compress if compression else bytes
        self._chunk_size = chunk_size
        self._summary: dict[int, list[bytes]] = {OP_SCHEMA: [], OP_CHANNEL: [],
                                                 OP_CHUNK_INDEX: [], OP_METADATA_INDEX: []}
        self._counts: dict[int, int] = {}   # messages per channel id
        self._start = self._end = None      # log time span of the messages written
        self._write(MAGIC)
        self._record(OP_HEADER, _string(profile) + _string(library))

    # -- definitions --------------------------------------------------------------------------
    def add_schema(self, name: str, encoding: str, data: bytes) -> int:
        """Write a Schema record; returns its id (1, 2, ...)."""
        schema = len(self._summary[OP_SCHEMA]) + 1
        content = struct.pack("<H", schema) + _string(name) + _string(encoding) + \
            struct.pack("<I", len(data)) + data
        self._summary[OP_SCHEMA].append(self._record(OP_SCHEMA, content))
        return schema

    def add_channel(self, topic: str, schema: int, message_encoding: str,
                    metadata: dict[str, str]) -> int:
        """Write a Channel record of schema id ``schema``; returns its id (1, 2, ...)."""
        channel = len(self._summary[OP_CHANNEL]) + 1
        content = struct.pack("<HH", channel, schema) + _string(topic) + \
            _string(message_encoding) + _map(metadata)
        self._summary[OP_CHANNEL].append(self._record(OP_CHANNEL, content))
        self._counts[channel] = 0
        return channel

    def add_metadata(self, name: str, metadata: dict[str, str]) -> None:
        """Write a Metadata record (and index it in the summary)."""
        offset = self._pos
        self._record(OP_METADATA, _string(name) + _map(metadata))
        self._summary[OP_METADATA_INDEX].append(_record_bytes(
            OP_METADATA_INDEX, struct.pack("<QQ", offset, self._pos - offset) + _string(name)))

    # -- messages -----------------------------------------------------------------------------
    def write_messages(self, channels, log_times, payloads) -> None:
        """Write messages in chunks, in the order given.

        Parameters
        ----------
        channels : array_like of int
            Channel id of each message (from :meth:`add_channel`).
        log_times : array_like of int
            Log time of each message, ns (also its publish time).
        payloads : sequence of bytes-like
            The messages' data.
        """
        channels = np.asarray(channels, np.uint16)
        times = np.asarray(log_times, np.uint64)
        n = len(payloads)
        if not len(channels) == len(times) == n:
            raise ValueError(f"{len(channels)} channel ids, {len(times)} times, {n} payloads")
        if n == 0:
            return
        unknown = set(np.unique(channels).tolist()) - set(self._counts)
        if unknown:
            raise ValueError(f"channel id(s) {sorted(unknown)} not added")
        sizes = np.fromiter(map(len, payloads), np.int64, n) + MESSAGE_HEAD_SIZE
        ends = np.cumsum(sizes)
        first = 0
        while first < n:
            # The chunk ends with the first message that takes it past the chunk size.
            base = ends[first] - sizes[first]
            last = min(int(np.searchsorted(ends, base + self._chunk_size, "left")) + 1, n)
            self._chunk(channels[first:last], times[first:last], payloads[first:last],
                        sizes[first:last], ends[first:last] - sizes[first:last] - base)
            first = last

    def _chunk(self, channels, times, payloads, sizes, offsets) -> None:
        """Write one Chunk record and its Message Index records (``sizes``: of the message
        records, ``offsets``: of them in the chunk's records)."""
        n = len(payloads)
        heads = np.zeros(n, _MESSAGE_HEAD)
        heads["op"] = OP_MESSAGE
        heads["length"] = sizes - 9
        heads["channel"] = channels
        heads["log_time"] = heads["publish_time"] = times
        raw = heads.tobytes()
        size = MESSAGE_HEAD_SIZE
        parts = [b""] * (2 * n)
        parts[0::2] = [raw[k:k + size] for k in range(0, n * size, size)]
        parts[1::2] = payloads
        records = b"".join(parts)
        data = self._compress(records)
        start, end = int(times.min()), int(times.max())
        chunk_at = self._pos
        self._record(OP_CHUNK, struct.pack("<QQQI", start, end, len(records), crc32(records))
                     + _string(self._compression) + struct.pack("<Q", len(data)) + data)
        chunk_length = self._pos - chunk_at
        # One Message Index per channel, its entries in log-time order (stable: ties in
        # chunk order).
        index_offsets = []
        for channel in np.unique(channels).tolist():
            rows = np.flatnonzero(channels == channel)
            rows = rows[np.argsort(times[rows], kind="stable")]
            entries = np.empty(len(rows), _INDEX_ENTRY)
            entries["log_time"] = times[rows]
            entries["offset"] = offsets[rows]
            index_offsets.append(struct.pack("<HQ", channel, self._pos))
            self._record(OP_MESSAGE_INDEX, struct.pack("<HI", channel, entries.nbytes)
                         + entries.tobytes())
            self._counts[channel] += len(rows)
        index_length = self._pos - chunk_at - chunk_length
        offsets_map = b"".join(index_offsets)
        self._summary[OP_CHUNK_INDEX].append(_record_bytes(OP_CHUNK_INDEX, struct.pack(
            "<QQQQI", start, end, chunk_at, chunk_length, len(offsets_map)) + offsets_map
            + struct.pack("<Q", index_length) + _string(self._compression)
            + struct.pack("<QQ", len(data), len(records))))
        self._start = start if self._start is None else min(self._start, start)
        self._end = end if self._end is None else max(self._end, end)

    # -- the end ------------------------------------------------------------------------------
    def close(self) -> None:
        """Write Data End, the summary, its offsets and the footer, and close the file."""
        if self._file.closed:
            return
        self._record(OP_DATA_END, struct.pack("<I", self._crc))
        summary_start = self._pos
        self._crc = 0   # from here: the summary CRC
        groups = []
        for op, records in self._summary.items():
            if records:
                groups.append((op, self._pos))
                self._write(b"".join(records))
                groups[-1] += (self._pos - groups[-1][1],)
        counts = sorted(self._counts.items())
        statistics_at = self._pos
        self._record(OP_STATISTICS, struct.pack(
            "<QHIIIIQQI", sum(self._counts.values()), len(self._summary[OP_SCHEMA]),
            len(self._summary[OP_CHANNEL]), 0, len(self._summary[OP_METADATA_INDEX]),
            len(self._summary[OP_CHUNK_INDEX]), self._start or 0, self._end or 0,
            10 * len(counts)) + b"".join(struct.pack("<HQ", *c) for c in counts))
        groups.append((OP_STATISTICS, statistics_at, self._pos - statistics_at))
        offsets_start = self._pos
        for op, at, length in groups:
            self._record(OP_SUMMARY_OFFSET, struct.pack("<BQQ", op, at, length))
        footer = _RECORD_HEAD.pack(OP_FOOTER, 20) + struct.pack("<QQ", summary_start,
                                                                 offsets_start)
        self._write(footer + struct.pack("<I", crc32(footer, self._crc)) + MAGIC)
        self._file.close()

    def __enter__(self) -> "McapWriter":
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    def _write(self, data: bytes) -> None:
        self._file.write(data)
        self._pos += len(data)
        self._crc = crc32(data, self._crc)

    def _record(self, op: int, content: bytes) -> bytes:
        record = _record_bytes(op, content)
        self._write(record)
        return record


def _record_bytes(op: int, content: bytes) -> bytes:
    return _RECORD_HEAD.pack(op, len(content)) + content


def _string(text: str) -> bytes:
    data = text.encode()
    return struct.pack("<I", len(data)) + data


def _map(mapping: dict[str, str]) -> bytes:
    entries = b"".join(_string(k) + _string(v) for k, v in sorted(mapping.items()))
    return struct.pack("<I", len(entries)) + entries
