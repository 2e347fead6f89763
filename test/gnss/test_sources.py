"""Byte sources: URL selection, serial (pseudo-terminal), TCP client and server on loopback, file,
reconnection backoff and replay pacing (with a fake clock: no timing assertions), the reader
thread (what it hands over and in which order; waits only as lower bounds)."""

from __future__ import annotations

import os
import queue
import socket
import threading
import time
import tty

import pytest

from ins_gnss_ros.gnss.sources import (FileSource, Pacer, SerialSource, SourceReader,
                                       TcpClientSource, TcpServerSource, open_source)

PAYLOAD = bytes(range(256)) * 40  # 10 KiB, every byte value (binary UBX-safe)


class FakeClock:
    def __init__(self):
        self.t = 0.0

    def __call__(self):
        return self.t


def _read_all(source, n, timeout=10.0):
    """Read until ``n`` bytes arrived (bounded by a wall-clock deadline)."""
    out = bytearray()
    deadline = time.monotonic() + timeout
    while len(out) < n and time.monotonic() < deadline:
        out += source.read(65536, 0.05)
    return bytes(out)


def test_urls_select_sources_and_defaults():
    s = open_source("serial:///dev/ttyACM0?baud=460800")
    assert isinstance(s, SerialSource) and (s.port, s.baud) == ("/dev/ttyACM0", 460800)
    assert open_source("serial:///dev/ttyUSB1").baud == 115200
    c = open_source("tcp://192.168.1.5:5000")
    assert isinstance(c, TcpClientSource) and c.address == ("192.168.1.5", 5000)
    srv = open_source("tcp-listen://:5001")
    assert isinstance(srv, TcpServerSource) and srv.address == ("127.0.0.1", 5001)
    f = open_source("file:///data/x.ubx?pace=fast")
    assert isinstance(f, FileSource) and (f.path, f.pace) == ("/data/x.ubx", "fast")
    assert open_source("file:///data/x.ubx").pace == "recorded"
    for bad in ("udp://1.2.3.4:5", "tcp://host", "file:///x?pace=slow", "serial://",
                "tcp://h:notaport", "serial:///dev/ttyS0?baud=0"):
        with pytest.raises(ValueError, match="source"):
            open_source(bad)


def test_file_source_reads_everything_and_reports_end_once(tmp_path):
    path = tmp_path / "rec.ubx"
    path.write_bytes(PAYLOAD)
    events = []
    src = FileSource(str(path), "fast", notify=lambda e, d: events.append(e))
    chunks = [src.read(1000) for _ in range(12)]
    assert b"".join(chunks) == PAYLOAD
    assert src.finished and src.read(1000) == b""
    assert events == ["connected", "end of file"]


def test_missing_file_retries_with_doubling_backoff_then_connects(tmp_path):
    clock = FakeClock()
    events = []
    path = tmp_path / "later.ubx"
    src = FileSource(str(path), "fast", notify=lambda e, d: events.append((clock.t, e)),
                     clock=clock, retry_initial_s=0.5, retry_max_s=2.0)
    for t in (0.0, 0.1, 0.5, 1.0, 1.5, 2.5, 3.4, 3.5, 5.5):
        clock.t = t
        assert src.read() == b""
    # attempts at 0 (wait 0.5), 0.5 (wait 1), 1.5 (wait 2), 3.5 (wait 2, the cap), 5.5
    assert [t for t, e in events] == [0.0, 0.5, 1.5, 3.5, 5.5]
    assert {e for _, e in events} == {"connect failed"}
    path.write_bytes(b"abc")
    clock.t = 7.5
    assert src.read() == b"abc"
    assert events[-1] == (7.5, "connected")


def test_serial_pty_reads_and_survives_vanished_port():
    master, slave = os.openpty()
    tty.setraw(slave)
    events = []
    src = SerialSource(os.ttyname(slave), 115200, notify=lambda e, d: events.append(e),
                       retry_initial_s=0.01)
    try:
        assert src.read(100, 0.0) == b"" and events == ["connected"]
        writer = threading.Thread(target=os.write, args=(master, PAYLOAD[:3000]))
        writer.start()
        assert _read_all(src, 3000) == PAYLOAD[:3000]
        writer.join()
        os.close(master)  # the receiver vanishes
        master = None
        deadline = time.monotonic() + 5.0
        while "lost" not in events and time.monotonic() < deadline:
            assert src.read(100, 0.05) == b""
        assert "lost" in events and not src.connected
    finally:
        if master is not None:
            os.close(master)
        os.close(slave)
    time.sleep(0.02)  # let the 10 ms backoff pass: the device node is gone now
    assert src.read(100, 0.0) == b""
    assert events[-1] == "connect failed"


def test_tcp_client_reads_loopback_server_and_reconnects():
    server = socket.create_server(("127.0.0.1", 0))
    port = server.getsockname()[1]
    events = []
    src = TcpClientSource("127.0.0.1", port, notify=lambda e, d: events.append(e),
                          retry_initial_s=0.01)

    def serve_once(data):
        conn, _ = server.accept()
        conn.sendall(data)
        conn.close()

    try:
        for data in (PAYLOAD, PAYLOAD[::-1]):
            t = threading.Thread(target=serve_once, args=(data,))
            t.start()
            assert _read_all(src, len(data)) == data
            t.join(5.0)
            deadline = time.monotonic() + 5.0
            while src.connected and time.monotonic() < deadline:
                src.read(100, 0.05)  # the peer closed: reported as lost
            time.sleep(0.02)  # the 10-20 ms backoff before the next connection
        assert events == ["connected", "lost", "connected", "lost"]
    finally:
        src.close()
        server.close()


def test_tcp_server_binds_loopback_and_serves_successive_clients():
    events = []
    src = TcpServerSource("127.0.0.1", 0, notify=lambda e, d: events.append(e))
    try:
        assert src.read(100, 0.0) == b""  # opens the listener
        assert src._listener.getsockname()[0] == "127.0.0.1"
        for data in (PAYLOAD, b"second client"):
            with socket.create_connection(("127.0.0.1", src.port), timeout=5.0) as client:
                client.sendall(data)
                assert _read_all(src, len(data)) == data
            deadline = time.monotonic() + 5.0
            while events[-1] != "client disconnected" and time.monotonic() < deadline:
                src.read(100, 0.05)
        assert events == ["connected", "client connected", "client disconnected",
                          "client connected", "client disconnected"]
        assert src.connected  # still listening
    finally:
        src.close()


def test_port_in_use_is_a_connect_failure_not_an_exception():
    with socket.create_server(("127.0.0.1", 0)) as taken:
        events = []
        src = TcpServerSource("127.0.0.1", taken.getsockname()[1],
                              notify=lambda e, d: events.append(e))
        assert src.read() == b""
        assert events == ["connect failed"]


def test_pacer_releases_at_the_recorded_spacing():
    clock = FakeClock()
    pacer = Pacer(clock, max_gap_s=10.0)
    clock.t = 100.0
    assert pacer.wait_s(5000.0) == 0.0  # the first item anchors
    pacer.released(5000.0)
    assert pacer.wait_s(5000.25) == pytest.approx(0.25)
    clock.t = 100.3
    assert pacer.wait_s(5000.25) == 0.0
    pacer.released(5000.25)
    assert pacer.wait_s(5001.0) == pytest.approx(0.7)
    # A jump (new recording) re-anchors instead of waiting an hour or running ahead.
    assert pacer.wait_s(8600.0) == 0.0
    pacer.released(8600.0)
    assert pacer.wait_s(4000.0) == 0.0


class Driver:
    """The driver's side of a SourceReader: posted functions run on the test's thread, in
    :meth:`run_until`; what it was handed is logged in order."""

    def __init__(self, hold_first_s=None):
        self.posted: queue.Queue = queue.Queue()
        self.log: list = []
        self._hold = hold_first_s  # the first chunk's records held back this long

    def feed(self, data):
        self.log.append(("feed", data, time.monotonic()))
        hold, self._hold = self._hold, None
        return hold

    def release(self):
        self.log.append(("release", None, time.monotonic()))
        return None

    def run_until(self, done, timeout=10.0):
        deadline = time.monotonic() + timeout
        while not done() and time.monotonic() < deadline:
            try:
                self.posted.get(timeout=0.05)()
            except queue.Empty:
                pass
        assert done()


def _reader(source, driver, max_bytes=65536, **kwargs):
    return SourceReader(source, driver.posted.put, driver.feed, driver.release, max_bytes,
                        **kwargs)


def test_reader_hands_over_only_what_arrives():
    server = socket.create_server(("127.0.0.1", 0))
    source = TcpClientSource("127.0.0.1", server.getsockname()[1])
    driver = Driver()
    reader = _reader(source, driver, wait_s=0.05)
    reader.start()
    conn, _ = server.accept()
    try:
        time.sleep(0.3)  # connected, nothing sent: nothing is posted
        assert driver.posted.empty() and driver.log == []
        conn.sendall(PAYLOAD)
        driver.run_until(lambda: sum(len(d) for _, d, _ in driver.log) == len(PAYLOAD))
        assert b"".join(d for _, d, _ in driver.log) == PAYLOAD
        assert {kind for kind, _, _ in driver.log} == {"feed"}
    finally:
        reader.stop()
        conn.close()
        server.close()
        source.close()
    assert not reader._thread.is_alive()


def test_reader_waits_for_held_back_records_before_reading_on(tmp_path):
    path = tmp_path / "stream.bin"
    path.write_bytes(PAYLOAD)
    driver = Driver(hold_first_s=0.2)
    reader = _reader(FileSource(str(path), "recorded"), driver, max_bytes=1024)
    reader.start()
    driver.run_until(lambda: not reader._thread.is_alive() and driver.posted.empty())
    kinds = [kind for kind, _, _ in driver.log]
    # 1 KiB chunks: the second is read only after the records of the first were released
    assert kinds[:3] == ["feed", "release", "feed"] and kinds.count("release") == 1
    assert driver.log[1][2] - driver.log[0][2] >= 0.2
    assert b"".join(d for kind, d, _ in driver.log if kind == "feed") == PAYLOAD


def test_reader_of_a_missing_source_sleeps_until_the_retry(tmp_path):
    source = FileSource(str(tmp_path / "missing.bin"), retry_initial_s=30.0)
    reads = []
    source_read = source.read
    source.read = lambda *args: reads.append(1) or source_read(*args)
    reader = _reader(source, Driver())
    reader.start()
    time.sleep(0.3)
    reader.stop()
    assert len(reads) == 1  # one failed open, then asleep until the retry in 30 s
