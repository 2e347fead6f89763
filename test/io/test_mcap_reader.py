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
from ins_gnss_ros.io.mcap_reader import McapError, read_mcap
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
           for c in "xyz"}, "dt": 0.005}, {"header.frame_id": "base_link"})
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
    assert [(m.topic, m.t_ns, m.data) for m in read_mcap(mcap_file).messages] == by_mcap
    assert len(direct) == 15_000 + 15_000 // 40
    assert [m.topic for m in direct[:2]] == ["/imu/delta", "/gnss/fix"]  # tie: writing order
    assert bagio.read_raw(chunked_bag, ["gnss/fix"]) == [m for m in direct
                                                         if m.topic == "/gnss/fix"]


def test_a_cut_file_is_read_up_to_where_it_ends(tmp_path, caplog):
    """A recording killed at any point: every complete message before the cut is read (also
    from a cut chunk), in file order, with one warning saying how much; nothing after it."""
    mcap_file = next(BUNDLED.glob("*.mcap"))
    data = mcap_file.read_bytes()
    whole = read_mcap(mcap_file)
    n = len(whole.messages)
    assert whole.cut_at is None and n == 22_967
    cut_bag = tmp_path / "cut"
    cut_bag.mkdir()
    shutil.copy(BUNDLED / "metadata.yaml", cut_bag)
    counts = []
    for size in (0, 5, 8, 30, 1000, 100_000, 250_000, 429_776, 500_000, 700_000, 900_000,
                 len(data) - 300, len(data) - 1):
        (cut_bag / mcap_file.name).write_bytes(data[:size])
        contents = read_mcap(cut_bag / mcap_file.name)
        assert contents.messages == whole.messages[:len(contents.messages)], size
        counts.append(len(contents.messages))
        caplog.clear()
        with caplog.at_level(logging.WARNING, logger="ins_gnss_ros.io.bag"):
            rows = bagio.read_raw(cut_bag)
        assert sorted(rows, key=lambda m: (m.t_ns, m.topic, m.data)) == \
            sorted(contents.messages, key=lambda m: (m.t_ns, m.topic, m.data))
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
            read_mcap(bad)
    # The first chunk (at byte 43) says it holds one byte more than it does (the writer leaves
    # the chunk checksums out, so a size is what can be checked).
    at = 43 + 9 + 16
    data[at:at + 8] = (int.from_bytes(data[at:at + 8], "little") + 1).to_bytes(8, "little")
    bad.write_bytes(bytes(data))
    with pytest.raises(McapError, match="chunk"):
        read_mcap(bad)
