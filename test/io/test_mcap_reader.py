"""io/mcap_reader.py against the reference readers (rosbags' public Reader, the ``mcap`` library)
and on files cut short the way a killed recording leaves them."""
import logging
import shutil
from pathlib import Path

import numpy as np
import pytest

from conftest import REPO
from ins_gnss_ros import io as bagio
from ins_gnss_ros.io import cdr
from ins_gnss_ros.io.mcap_reader import McapError, McapReader
from ins_gnss_ros.trial import contract_messages as msgs

RNG = np.random.default_rng(7)
BUNDLED = REPO / "bags" / "walk_0827"


@pytest.fixture(scope="module")
def chunked_bag(tmp_path_factory):
    """Several zstd chunks (the writer's chunks hold about 1 MB), ties in stamp across topics."""
    path = tmp_path_factory.mktemp("mcap") / "bag"
    n = 15_000
    payloads = cdr.encode_columns("ins_gnss_msgs/msg/ImuDelta", {
        "header.stamp.sec": 1_767_225_600 + np.arange(n) // 200,
        "header.stamp.nanosec": (np.arange(n) % 200) * 5_000_000,
        **{f"{v}.{c}": RNG.normal(size=n) for v in ("delta_angle", "delta_velocity")
           for c in "xyz"}, "dt": 0.005, "bridged_angle_variance": 0.0,
        "bridged_velocity_variance": 0.0}, {"header.frame_id": "base_link"})
    with bagio.BagWriter(path) as writer:
        for k, data in enumerate(payloads):
            t = (1_767_225_600 + k // 200) * 1_000_000_000 + (k % 200) * 5_000_000
            writer.write_raw("imu/delta", "ins_gnss_msgs/msg/ImuDelta", t, data)
            if k % 40 == 0:
                writer.write("gnss/fix", msgs.fix_msg(t, 0.1, 0.2, k, [1, 1, 1]))
    return path


def test_reads_what_rosbags_and_mcap_read(chunked_bag):
    from mcap.reader import make_reader
    from rosbags.rosbag2 import Reader

    mcap_file = next(chunked_bag.glob("*.mcap"))
    with open(mcap_file, "rb") as f:
        reader = make_reader(f)
        assert len(reader.get_summary().chunk_indexes) >= 2
        by_mcap = [(channel.topic, message.log_time, message.data)
                   for _, channel, message in reader.iter_messages(log_time_order=False)]
    direct = bagio.read_raw(chunked_bag)
    with Reader(chunked_bag) as reader:
        by_rosbags = [bagio.RawMessage(c.topic, t, c.msgtype, data)
                      for c, t, data in reader.messages()]
    assert direct == sorted(by_rosbags, key=lambda m: m.t_ns)
    assert [(m.topic, m.t_ns, m.data) for m in McapReader(mcap_file)] == by_mcap
    assert len(direct) == 15_000 + 15_000 // 40
    assert [m.topic for m in direct[:2]] == ["/imu/delta", "/gnss/fix"]  # tie: writing order
    assert bagio.read_raw(chunked_bag, ["gnss/fix"]) == [m for m in direct
                                                         if m.topic == "/gnss/fix"]


def test_a_cut_file_is_read_up_to_where_it_ends(tmp_path, caplog):
    """A recording killed at any point: every complete message before the cut is read (also
    from a cut chunk), in file order, with one warning saying how much; nothing after it."""
    mcap_file = next(BUNDLED.glob("*.mcap"))
    data = mcap_file.read_bytes()
    whole = McapReader(mcap_file)
    messages = list(whole)
    n = len(messages)
    assert whole.cut_at is None and n == 22_967
    cut_bag = tmp_path / "cut"
    cut_bag.mkdir()
    shutil.copy(BUNDLED / "metadata.yaml", cut_bag)
    counts = []
    for size in (0, 5, 8, 30, 1000, 100_000, 250_000, 429_776, 500_000, 700_000, 900_000,
                 len(data) - 300, len(data) - 1):
        (cut_bag / mcap_file.name).write_bytes(data[:size])
        contents = McapReader(cut_bag / mcap_file.name)
        read = list(contents)
        assert read == messages[:len(read)], size
        counts.append(len(read))
        caplog.clear()
        with caplog.at_level(logging.WARNING, logger="ins_gnss_ros.io.bag"):
            rows = bagio.read_raw(cut_bag)
        assert sorted(rows, key=lambda m: (m.t_ns, m.topic, m.data)) == \
            sorted(read, key=lambda m: (m.t_ns, m.topic, m.data))
        if contents.cut_at is None:   # cut in the summary, after the data: nothing lost
            assert len(rows) == n and not caplog.records
        else:
            (record,) = caplog.records
            assert f"read {len(rows):,} of the {n:,} messages" in record.getMessage()
            assert "cut short" in record.getMessage() and "\n" not in record.getMessage()
    assert counts == sorted(counts) and counts[0] == 0 and counts[-1] == n
    assert 0 < counts[5] < counts[6] < counts[8] < counts[10] < n   # cut chunks recovered


def test_damage_that_is_not_a_cut_is_an_error(tmp_path):
    mcap_file = next(BUNDLED.glob("*.mcap"))
    data = bytearray(mcap_file.read_bytes())
    bad = tmp_path / "x.mcap"
    for garbage in (b"not an mcap file at all", data[:8] + RNG.bytes(3000)):
        bad.write_bytes(garbage)
        with pytest.raises(McapError, match="not an MCAP file"):
            list(McapReader(bad))
    # The first chunk (at byte 43) says it holds one byte more than it does (the writer leaves
    # the chunk checksums out, so a size is what can be checked).
    at = 43 + 9 + 16
    data[at:at + 8] = (int.from_bytes(data[at:at + 8], "little") + 1).to_bytes(8, "little")
    bad.write_bytes(bytes(data))
    with pytest.raises(McapError, match="chunk"):
        list(McapReader(bad))


def test_chunks_out_of_time_order_still_stream_in_stamp_order(tmp_path):
    """A file whose chunks overlap in time and come back in time (written by the ``mcap``
    library, not by this project): the reader holds them until nothing earlier can follow."""
    from mcap.writer import CompressionType, Writer

    path = tmp_path / "x.mcap"
    stamps = [*range(500, 1000), *range(0, 500, 2), *range(1, 500, 2), *range(1000, 1500)]
    with open(path, "wb") as f:
        writer = Writer(f, chunk_size=2000, compression=CompressionType.ZSTD)
        writer.start("ros2", "test")
        schema = writer.register_schema("std_msgs/msg/UInt32", "ros2msg", b"uint32 data")
        channel = writer.register_channel("/n", "cdr", schema)
        for seq, t in enumerate(stamps):
            writer.add_message(channel, t, t.to_bytes(8, "little"), t, seq)
        writer.finish()
    reader = McapReader(path)
    rows = list(reader)
    assert [r.t_ns for r in rows] == sorted(stamps)
    assert all(int.from_bytes(r.data, "little") == r.t_ns for r in rows)
    assert reader.cut_at is None and reader.channels == {("/n", "std_msgs/msg/UInt32")}


def test_a_recording_in_time_order_is_read_a_chunk_at_a_time(chunked_bag, monkeypatch):
    """Memory bounded by a chunk: the first message comes out after one decompression."""
    from ins_gnss_ros.io import mcap_reader

    calls = []
    decompress = mcap_reader._decompress
    monkeypatch.setattr(mcap_reader, "_decompress", lambda *a: calls.append(1) or decompress(*a))
    stream = iter(McapReader(next(chunked_bag.glob("*.mcap"))))
    next(stream)
    assert len(calls) == 1
    assert sum(1 for _ in stream) == 15_000 + 15_000 // 40 - 1 and len(calls) >= 2
