"""The messages of an MCAP file, read record by record, also from a file cut short.

MCAP (specification: https://mcap.dev/spec) is a magic, then records: an opcode byte, a uint64
length and the content. The data section holds schemas (id, name = ROS type ``pkg/msg/Name``),
channels (id, schema id, topic, message encoding), messages (channel id u16, sequence u32, log
time u64, publish time u64, payload) and chunks (start and end time, uncompressed size and CRC,
compression, compressed records); a summary and the footer follow. This walks the data section
in file order and never needs the summary, so a recording that was killed (no summary or
footer, the file ending inside a chunk or a record) is read up to its last complete message:
the complete records of a cut chunk are recovered by decompressing what there is of it.

Why not a library reader: ``mcap``'s and rosbags' readers build a Python object per record (and
rosbags merges chunks through a heap), several microseconds per message, about twice what this
costs, which was a sizeable part of the offline replay (docs/results/replay.md); both also need
the summary or footer of a complete file. Chunks are decompressed with ``zstandard`` and ``lz4``.
"""
from __future__ import annotations

import struct
from binascii import crc32
from pathlib import Path
from typing import NamedTuple

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


class McapContents(NamedTuple):
    """What :func:`read_mcap` found.

    Attributes
    ----------
    messages : list of RawMessage
        In file order.
    channels : set of (str, str)
        (topic, type name) of the channels read.
    cut_at : int or None
        When the file ends before its data section does (a recording cut short): the offset
        of the record it ends in, or its size when it ends between records (the complete
        messages of a cut chunk are read). None for a complete file.
    size : int
        File size, bytes.
    """

    messages: list
    channels: set
    cut_at: int | None
    size: int


def read_mcap(path, topics=None) -> McapContents:
    """The messages of an MCAP file with CDR payloads (or of ``topics``), in file order.

    Parameters
    ----------
    path : path
        The ``.mcap`` file.
    topics : set of str, optional
        Only these (absolute) topics.

    Raises
    ------
    McapError
        Not an MCAP file, a channel without a schema or not CDR, an unknown compression, a
        chunk whose size or checksum does not match.
    """
    path = Path(path)
    data = path.read_bytes()
    if MAGIC.startswith(data):   # cut before its first record (empty, or part of the magic)
        return McapContents([], set(), 0, len(data))
    if not data.startswith(MAGIC) or (len(data) >= len(MAGIC) + 9 and (
            data[len(MAGIC)] != _OP_HEADER
            or struct.unpack_from("<Q", data, len(MAGIC) + 1)[0] > _MAX_HEADER)):
        raise McapError(f"{path.name}: not an MCAP file")
    schemas: dict[int, str] = {}
    channels: dict[int, tuple[str, str]] = {}
    rows: list = []
    unpack = struct.unpack_from

    def walk(buf, pos, end):
        """Read the records of buf[pos:end]: the offset of the first one cut by ``end``
        (``end``: none is), or None when the data section ends (the file is complete)."""
        while pos < end:
            if pos + 9 > end:
                return pos
            op = buf[pos]
            body = pos + 9
            stop = body + unpack("<Q", buf, pos + 1)[0]
            if stop > end:
                if op == _OP_CHUNK:
                    chunk(buf, body, end, cut=True)
                return pos
            if op == _OP_MESSAGE:
                channel, _, t = unpack("<HIQ", buf, body)
                if channel in channels:
                    topic, msgtype = channels[channel]
                    rows.append(RawMessage(topic, t, msgtype, buf[body + 22:stop]))
            elif op == _OP_CHANNEL:
                channel, schema, size = unpack("<HHI", buf, body)
                topic = buf[body + 8:body + 8 + size].decode()
                if topics is None or topic in topics:
                    (n,) = unpack("<I", buf, body + 8 + size)
                    encoding = buf[body + 12 + size:body + 12 + size + n].decode()
                    if schema not in schemas or encoding != "cdr":
                        raise McapError(f"{path.name}: channel {topic} has "
                                        f"{'no schema' if schema not in schemas else encoding}"
                                        " (a rosbag2 channel has a ROS type and CDR payloads)")
                    channels[channel] = topic, schemas[schema]
            elif op == _OP_SCHEMA:
                schema, size = unpack("<HI", buf, body)
                schemas[schema] = buf[body + 6:body + 6 + size].decode()
            elif op == _OP_CHUNK:
                chunk(buf, body, stop)
            elif op in (_OP_DATA_END, _OP_FOOTER):
                return None
            pos = stop
        return pos

    def chunk(buf, body, stop, cut=False):
        """Read the records of the chunk at ``body``; of a ``cut`` one (the file ends at
        ``stop``) the complete records in what there is of its data."""
        if body + 32 > stop:
            return
        _, _, size, crc, n = unpack("<QQQII", buf, body)
        compression = buf[body + 32:body + 32 + n].decode()
        start = body + 32 + n + 8
        if start > stop:
            return
        length = unpack("<Q", buf, start - 8)[0]
        records = _decompress(path, buf[start:min(start + length, stop)], compression, size,
                              None if cut else crc)
        if walk(records, 0, len(records)) != len(records) and not cut:
            raise McapError(f"{path.name}: a chunk ends inside a record")

    cut = walk(data, len(MAGIC), len(data))
    return McapContents(rows, set(channels.values()), cut, len(data))


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
