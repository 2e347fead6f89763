"""io/mcap_writer.py (through BagWriter) against three independent readers and the MCAP
specification's checks.

Truth: the messages of the bundled walk bag (written by rosbags' writer, decoded by the
project's reader) and hand-made ones with strings and sequences of messages, written anew and
read back by (1) ``mcap`` with the ``mcap-ros2-support`` decoder, which parses the CDR with the
schemas stored in the file; (2) rosbags' rosbag2 Reader and typestore deserialiser; (3) the
project's reader: every message's decoded values must equal the original's. ``mcap``'s own
checks: chunk and data section CRCs (``validate_crcs``), the summary's statistics and chunk
indexes, reading a time window through the indexes; the message indexes and the summary CRC
are checked against the specification's definitions here. metadata.yaml is compared with what
rosbags' writer makes of the same messages.
"""
import array
import math
import struct
import zlib

import numpy as np
import pytest
import yaml
import zstandard
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from geometry_msgs.msg import TransformStamped
from tf2_msgs.msg import TFMessage

from conftest import REPO
from ins_gnss_ros import io as bagio
from ins_gnss_ros.io import messages_equal, ns_to_stamp
from ins_gnss_ros.io.mcap_writer import McapWriter

WALK = REPO / "bags" / "walk_0827"


def _extra_messages(t0):
    """Strings, sequences of messages with strings, two channels of one type."""
    out = []
    for k in range(30):
        diag = DiagnosticArray()
        diag.header.stamp = ns_to_stamp(t0 + k * 1_000_000_000)
        diag.status = [DiagnosticStatus(level=bytes([k % 3]), name=f"node{j}", message="ok" * j,
                                        hardware_id="", values=[KeyValue(key="n", value=str(k))])
                       for j in range(k % 4)]
        out.append(("/diagnostics", t0 + k * 1_000_000_000, diag))
        tf = TFMessage(transforms=[TransformStamped(child_frame_id="base_link")])
        tf.transforms[0].header.frame_id = "map"
        tf.transforms[0].transform.translation.x = k * 0.5
        tf.transforms[0].transform.rotation.w = 1.0
        out.append(("/tf", t0 + k * 1_000_000_000, tf))
        out.append(("/tf_static", t0, tf))
    return out


@pytest.fixture(scope="module")
def originals():
    """(topic, log time, rclpy message) in the order written: the walk bag (several chunks),
    then the hand-made messages, interleaved in time by the writer's sort."""
    walk = bagio.read_bag(WALK)
    rows = [(m.topic, m.t_ns, m.msg) for m in walk] + _extra_messages(walk[0].t_ns + 3)
    return rows


def _write(path, rows, ordered=False):
    if ordered:
        rows = sorted(rows, key=lambda r: r[1])
    with bagio.BagWriter(path, ordered=ordered) as writer:
        for topic, t, msg in rows:
            writer.write(topic, msg, t)
    return path


@pytest.fixture(scope="module", params=[False, True], ids=["sorted_at_close", "ordered"])
def written(request, originals, tmp_path_factory):
    return _write(tmp_path_factory.mktemp("w") / "bag", originals, request.param)


def _in_stamp_order(rows):
    # The writer's order: by log time, ties in writing order (a stable sort).
    return sorted(rows, key=lambda r: r[1])


def _same(ref, other, path="msg"):
    """Decoded values equal, field by field, whatever the reader's Python types (NaN = NaN)."""
    if hasattr(ref, "get_fields_and_field_types"):
        for name in ref.get_fields_and_field_types():
            _same(getattr(ref, name), getattr(other, name), f"{path}.{name}")
    elif isinstance(ref, (list, tuple, array.array, np.ndarray)) or \
            (isinstance(ref, bytes) and len(ref) != 1):
        ref, other = list(ref), list(bytes(other) if isinstance(other, (bytes, bytearray))
                                     else other)
        assert len(ref) == len(other), path
        for k, (a, b) in enumerate(zip(ref, other)):
            _same(a, b, f"{path}[{k}]")
    else:
        a, b = (_scalar(v) for v in (ref, other))
        assert a == b or (isinstance(a, float) and math.isnan(a) and math.isnan(b)), \
            f"{path}: {a!r} != {b!r}"


def _scalar(value):
    if isinstance(value, (bytes, bytearray)):   # an octet: rclpy's one-byte bytes
        return value[0]
    return value.item() if isinstance(value, np.generic) else value


def test_the_mcap_library_decodes_every_message(written, originals):
    from mcap.reader import make_reader
    from mcap_ros2.decoder import DecoderFactory

    expected = _in_stamp_order(originals)
    with open(next(written.glob("*.mcap")), "rb") as f:
        reader = make_reader(f, decoder_factories=[DecoderFactory()])
        assert reader.get_header().profile == "ros2"
        got = list(reader.iter_decoded_messages(log_time_order=False))
    assert len(got) == len(expected)
    for (topic, t, msg), (schema, channel, message, decoded) in zip(expected, got):
        assert (channel.topic, message.log_time, message.publish_time) == (topic, t, t)
        assert schema.name == bagio.msgtype_of(msg) and schema.encoding == "ros2msg"
        assert channel.message_encoding == "cdr"
        _same(msg, decoded)


def test_rosbags_reads_and_deserialises_every_message(written, originals):
    from rosbags.rosbag2 import Reader

    store = bagio.typestore()
    expected = _in_stamp_order(originals)
    with Reader(written) as reader:
        got = [(c.topic, t, store.deserialize_cdr(data, c.msgtype))
               for c, t, data in reader.messages()]
        assert reader.message_count == len(expected)
    assert len(got) == len(expected)
    for (topic, t, msg), (topic2, t2, decoded) in zip(expected, got):
        assert (topic2, t2) == (topic, t)
        _same(msg, decoded)


def test_the_project_reader_gives_the_messages_back(written, originals):
    got = bagio.read_bag(written)
    expected = _in_stamp_order(originals)
    assert [(m.topic, m.t_ns) for m in got] == [(topic, t) for topic, t, _ in expected]
    assert all(messages_equal(m.msg, msg) for m, (_, _, msg) in zip(got, expected))


def test_crcs_statistics_and_chunk_indexes(written, originals):
    from mcap.reader import make_reader
    from mcap.records import DataEnd, Footer
    from mcap.stream_reader import StreamReader

    mcap_file = next(written.glob("*.mcap"))
    data = mcap_file.read_bytes()
    # Chunk CRCs and the data section CRC, recomputed by mcap's stream reader.
    records = list(StreamReader(str(mcap_file), validate_crcs=True).records)
    assert any(isinstance(r, DataEnd) and r.data_section_crc for r in records)
    footer = next(r for r in records if isinstance(r, Footer))
    # Summary CRC (spec, "Footer"): from the summary's start to the footer's
    # summary_offset_start field, included.
    assert footer.summary_crc == zlib.crc32(data[footer.summary_start:len(data) - 8 - 4])
    with open(mcap_file, "rb") as f:
        summary = make_reader(f).get_summary()
    stats = summary.statistics
    times = [t for _, t, _ in originals]
    assert stats.message_count == len(originals)
    assert (stats.message_start_time, stats.message_end_time) == (min(times), max(times))
    by_topic = {c.topic: stats.channel_message_counts[c.id] for c in summary.channels.values()}
    assert by_topic == {topic: sum(r[0] == topic for r in originals) for topic in by_topic}
    assert len(by_topic) == len({r[0] for r in originals})
    assert stats.schema_count == len(summary.schemas) == len({bagio.msgtype_of(r[2])
                                                               for r in originals})
    assert stats.chunk_count == len(summary.chunk_indexes) >= 3
    assert stats.metadata_count == len(summary.metadata_indexes) == 1
    chunks = sorted(summary.chunk_indexes, key=lambda c: c.chunk_start_offset)
    assert all(a.message_end_time <= b.message_start_time for a, b in zip(chunks, chunks[1:]))
    _check_message_indexes(data, chunks, summary)


def _check_message_indexes(data, chunks, summary):
    """Every Message Index entry (spec, "Message Index") points at a Message record of its
    channel and log time in the decompressed chunk, each message once."""
    for chunk in chunks:
        op, length = struct.unpack_from("<BQ", data, chunk.chunk_start_offset)
        assert op == 0x06 and 9 + length == chunk.chunk_length
        body = chunk.chunk_start_offset + 9
        _, _, size, _, n = struct.unpack_from("<QQQII", data, body)
        compression = data[body + 32:body + 32 + n].decode()
        assert compression == chunk.compression == "zstd"
        (stored,) = struct.unpack_from("<Q", data, body + 32 + n)
        records = zstandard.ZstdDecompressor().decompress(
            data[body + 40 + n:body + 40 + n + stored], max_output_size=size)
        assert (stored, size) == (chunk.compressed_size, chunk.uncompressed_size)
        seen = set()
        end = chunk.chunk_start_offset + chunk.chunk_length
        assert min(chunk.message_index_offsets.values()) == end
        total = 0
        for channel, at in chunk.message_index_offsets.items():
            op, length, ch, nbytes = struct.unpack_from("<BQHI", data, at)
            assert (op, ch) == (0x07, channel)
            total += 9 + length
            entries = np.frombuffer(data, "<u8", nbytes // 8, at + 15).reshape(-1, 2)
            assert np.all(np.diff(entries[:, 0].astype(np.int64)) >= 0)
            for t, offset in entries.tolist():
                op, _, ch, _, log_time = struct.unpack_from("<BQHIQ", records, offset)
                assert (op, ch, log_time) == (0x05, channel, t)
                assert chunk.message_start_time <= t <= chunk.message_end_time
                seen.add(offset)
        assert total == chunk.message_index_length
        count = 0   # every message record of the chunk is indexed
        pos = 0
        while pos < len(records):
            op, length = struct.unpack_from("<BQ", records, pos)
            count += op == 0x05
            assert op != 0x05 or pos in seen
            pos += 9 + length
        assert count == len(seen)
    assert set(summary.channels) >= {ch for c in chunks for ch in c.message_index_offsets}


def test_a_time_window_through_the_indexes(written, originals):
    """mcap's seeking reader takes the chunk indexes to a window of one topic."""
    from mcap.reader import SeekingReader

    times = sorted(t for _, t, _ in originals)
    start, stop = times[len(times) // 3], times[len(times) // 2]
    expected = [(topic, t) for topic, t, _ in _in_stamp_order(originals)
                if topic == "/imu/data_raw" and start <= t < stop]
    with open(next(written.glob("*.mcap")), "rb") as f:
        got = [(c.topic, m.log_time) for _, c, m in SeekingReader(f).iter_messages(
            topics=["/imu/data_raw"], starting_at=start, ending_before=stop)]
    assert got == expected and len(expected) > 1000


def test_metadata_yaml_is_what_rosbags_writes(written, originals, tmp_path):
    """rosbags' writer on the same messages: the same metadata.yaml but for ros_distro, which
    names the writer."""
    from rosbags.rosbag2 import CompressionFormat, CompressionMode, StoragePlugin, Writer

    reference = tmp_path / "bag"   # the same folder name: the file name is derived from it
    writer = Writer(reference, version=9, storage_plugin=StoragePlugin.MCAP)
    writer.set_compression(CompressionMode.STORAGE, CompressionFormat.ZSTD)
    with writer:
        connections = {}
        for topic, t, msg in _in_stamp_order(originals):
            if topic not in connections:
                connections[topic] = writer.add_connection(topic, bagio.msgtype_of(msg),
                                                           typestore=bagio.typestore())
            writer.write(connections[topic], t, bagio.serialize(msg))

    def info(path):
        out = yaml.safe_load((path / "metadata.yaml").read_text())["rosbag2_bagfile_information"]
        out.pop("ros_distro")
        out["topics_with_message_count"].sort(key=lambda e: e["topic_metadata"]["name"])
        return out

    assert info(written) == info(reference)
    assert yaml.safe_load((written / "metadata.yaml").read_text())[
        "rosbag2_bagfile_information"]["ros_distro"] == "jazzy"


def test_an_empty_bag_is_a_valid_file(tmp_path):
    from mcap.reader import make_reader
    from mcap.stream_reader import StreamReader

    bagio.BagWriter(tmp_path / "empty").close()
    assert bagio.read_bag(tmp_path / "empty") == []
    mcap_file = tmp_path / "empty" / "empty.mcap"
    list(StreamReader(str(mcap_file), validate_crcs=True).records)
    with open(mcap_file, "rb") as f:
        assert make_reader(f).get_summary().statistics.message_count == 0


def test_chunks_close_past_the_chunk_size(tmp_path):
    """One message per chunk past a tiny chunk size; messages across calls and channels."""
    from mcap.reader import make_reader

    path = tmp_path / "small.mcap"
    with McapWriter(path, profile="", library="test", compression="", chunk_size=10) as mcap:
        schema = mcap.add_schema("x", "ros2msg", b"")
        a = mcap.add_channel("/a", schema, "cdr", {})
        b = mcap.add_channel("/b", schema, "cdr", {"k": "v"})
        mcap.write_messages([a, b, a], [5, 5, 7], [b"1", b"22", b"333"])
        mcap.write_messages([b], [9], [b"4444"])
    with open(path, "rb") as f:
        reader = make_reader(f)
        summary = reader.get_summary()
        got = [(c.topic, m.log_time, m.data) for _, c, m in reader.iter_messages()]
    assert got == [("/a", 5, b"1"), ("/b", 5, b"22"), ("/a", 7, b"333"), ("/b", 9, b"4444")]
    assert len(summary.chunk_indexes) == 4
    assert summary.channels[b].metadata == {"k": "v"}
    with McapWriter(tmp_path / "other.mcap", profile="", library="") as other, \
            pytest.raises(ValueError, match="not added"):
        other.write_messages([1], [0], [b""])
