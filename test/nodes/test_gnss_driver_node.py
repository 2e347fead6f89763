"""gnss_driver node: the recorded u-blox walk through file, pty (real subprocess) and TCP sources,
checked against an independent struct-level parse of the UBX frames (u-blox interface
description layouts), and bad input (garbage, corrupted frames, a vanished port) on /diagnostics."""

from __future__ import annotations

import calendar
import datetime as dt
import math
import os
import random
import socket
import struct
import threading
import time
import tty
from collections import defaultdict

import numpy as np
import pymap3d
import pytest
import rclpy
from diagnostic_msgs.msg import DiagnosticStatus
from rclpy.parameter import Parameter

from conftest import shared_path
from receiver_frames import nmea_sentence, ubx_frame
from rosutil import NodeProcess, spin_until, wait_for_endpoints

C = 299792458.0
GPS_EPOCH = dt.datetime(1980, 1, 6)
TOPICS = ["/gnss/fix", "/gnss/vel", "/gnss/observations", "/gnss/ephemeris", "/gnss/heading",
          "/gnss/time_reference"]
# docs/results/gnss.md: complete broadcast ephemerides in the 134 s walk.
EXPECTED_EPHEMERIDES = {"G10", "G23", "G27", "G32", "E07", "E08", "E13", "E14", "E26", "E29",
                        "E33", "C11", "C21", "C22", "C34", "C42", "C43", "C44", "C50"}
LETTER = {0: "G", 2: "E", 3: "C", 6: "R"}
NO_SOURCE = "file:///nonexistent?pace=fast"  # never polled: the tests feed bytes directly


def _frames(data):
    """(class, id, payload) of every UBX frame with a valid checksum, by the frame layout."""
    out, pos = [], data.find(b"\xb5\x62")
    while 0 <= pos <= len(data) - 8:
        n = int.from_bytes(data[pos + 4:pos + 6], "little")
        frame = data[pos:pos + n + 8]
        if len(frame) == n + 8 and ubx_frame(frame[2], frame[3], frame[6:-2]) == frame:
            out.append((frame[2], frame[3], frame[6:-2]))
            pos = data.find(b"\xb5\x62", pos + n + 8)
        else:
            pos = data.find(b"\xb5\x62", pos + 1)
    return out


def _rawx(payload):
    """RXM-RAWX payload -> dict of header fields and per-measurement arrays."""
    tow, week, leap, num = struct.unpack_from("<dHbB", payload, 0)
    rec_stat = payload[12]
    meas = [struct.unpack_from("<ddfBBBBHBBBBB", payload, 16 + 32 * i) for i in range(num)]
    return {"tow": tow, "week": week, "leap": leap, "leap_valid": bool(rec_stat & 1),
            "gnss": [m[3] for m in meas], "sv": [m[4] for m in meas], "sig": [m[5] for m in meas],
            "pr": [m[0] if m[12] & 1 else math.nan for m in meas],
            "cp": [m[1] if (m[12] & 2) and (m[12] & 4) else math.nan for m in meas],
            "doppler": [m[2] for m in meas], "lock_s": [m[7] / 1000.0 for m in meas],
            "cno": [m[8] for m in meas]}


def _pvt(payload):
    itow, year, month, day, hour, minute, sec = struct.unpack_from("<IHBBBBB", payload, 0)
    nano, fix_type, flags = struct.unpack_from("<iBB", payload, 16)
    lon, lat, height, hmsl, hacc, vacc, vn, ve, vd = struct.unpack_from("<iiiiIIiii", payload, 24)
    sacc = struct.unpack_from("<I", payload, 68)[0]
    utc = dt.datetime(year, month, day, hour, minute, sec) + dt.timedelta(microseconds=nano / 1e3)
    return {"itow": itow, "utc": utc, "lat": lat * 1e-7, "lon": lon * 1e-7, "h": height / 1e3,
            "h_msl": hmsl / 1e3, "h_acc": hacc / 1e3, "v_acc": vacc / 1e3, "s_acc": sacc / 1e3,
            "vel_enu": np.array([ve, vn, -vd]) / 1e3, "carr": flags >> 6, "fix_ok": flags & 1}


def _nth_rawx_offset(data, n):
    """Offset of the n-th (from 0) RXM-RAWX frame start (a frame boundary to cut at)."""
    pos = -1
    for _ in range(n + 1):
        pos = data.find(b"\xb5\x62\x02\x15", pos + 1)
    return pos


def _write_all(fd, data):
    """Write everything to a blocking descriptor (a tty write may be partial)."""
    view = memoryview(data)
    while view:
        view = view[os.write(fd, view):]


def _posix(t):
    return t.sec + t.nanosec * 1e-9


def _utc_posix(utc):
    return calendar.timegm(utc.timetuple()) + utc.microsecond * 1e-6


@pytest.fixture(scope="module")
def walk():
    path = shared_path("data", "walk_0827", "gnss_1730.ubx")
    data = path.read_bytes()
    frames = _frames(data)
    return {"path": path, "bytes": data,
            "rawx": [_rawx(p) for c, i, p in frames if (c, i) == (0x02, 0x15)],
            "pvt": [_pvt(p) for c, i, p in frames if (c, i) == (0x01, 0x07)]}


@pytest.fixture(scope="module")
def context():
    ctx = rclpy.Context()
    rclpy.init(context=ctx)
    yield ctx
    ctx.try_shutdown()


def _bus_node(context, **params):
    from ins_gnss_ros.nodes.base import InProcessBus
    from ins_gnss_ros.nodes.gnss_driver_node import GnssDriverNode

    bus = InProcessBus()
    out = defaultdict(list)
    bus.recorders.append(lambda topic, msg: out[topic].append(msg))
    node = GnssDriverNode(context=context, bus=bus, parameter_overrides=[
        Parameter(k.replace("__", "."), value=v) for k, v in params.items()])
    return node, bus, out


#: In-process runs use the first 240 epochs (60 s, 17 of the 19 ephemerides) to save CPU; the
#: process test below streams the whole walk.
BUS_EPOCHS = 240


@pytest.fixture(scope="module")
def bus_run(walk, context, tmp_path_factory):
    path = tmp_path_factory.mktemp("walk") / "first_minute.ubx"
    path.write_bytes(walk["bytes"][:_nth_rawx_offset(walk["bytes"], BUS_EPOCHS)])
    node, bus, out = _bus_node(context, source=f"file://{path}?pace=fast")
    while not node.source.finished:
        node.poll()
        bus.drain()
    yield node, out
    node.destroy_node()


# -- the recorded walk, file source on the bus ---------------------------------------------------

def test_every_rawx_epoch_becomes_observations(bus_run, walk):
    node, out = bus_run
    msgs = out["/gnss/observations"]
    assert len(walk["rawx"]) == 536 and len(msgs) == BUS_EPOCHS
    for msg, raw in zip(msgs, walk["rawx"]):
        assert (msg.gps_week, msg.time_of_week, msg.leap_seconds) == (raw["week"], raw["tow"], 18)
        assert msg.antenna_id == 0 and msg.header.frame_id == "gnss_antenna_0"
        # GPS time -> UTC POSIX with the receiver's leap seconds, to the nanosecond.
        t_utc = GPS_EPOCH + dt.timedelta(weeks=raw["week"], seconds=raw["tow"] - raw["leap"])
        assert _posix(msg.header.stamp) == pytest.approx(_utc_posix(t_utc), abs=1e-6)
        # The decoder keeps the signals it knows (all of this receiver's): same order.
        assert list(msg.system) == raw["gnss"] and list(msg.prn) == raw["sv"]
        assert list(msg.signal) == raw["sig"]
        np.testing.assert_array_equal(msg.pseudorange, raw["pr"])
        np.testing.assert_array_equal(msg.carrier_phase, raw["cp"])
        np.testing.assert_allclose(msg.doppler, raw["doppler"], rtol=1e-7)
        np.testing.assert_allclose(msg.lock_time, raw["lock_s"], rtol=1e-6)
        np.testing.assert_array_equal(msg.cn0, raw["cno"])
    # A lock time shorter than the epoch spacing is a re-lock since the previous epoch.
    for prev, msg in zip(msgs, msgs[1:]):
        seen = set(zip(prev.system, prev.prn, prev.signal))
        for key, lock, lol in zip(zip(msg.system, msg.prn, msg.signal), msg.lock_time,
                                  msg.loss_of_lock):
            if key not in seen or lock < 0.249:
                assert lol
    assert sum(node.diag.counts[k] for k in ("bad checksum", "unknown message",
                                              "malformed message")) == 0


def test_fix_and_velocity_from_nav_pvt(bus_run, walk):
    from sensor_msgs.msg import NavSatFix, NavSatStatus

    _, out = bus_run
    fixes, vels = out["/gnss/fix"], out["/gnss/vel"]
    # One fix per NAV-PVT (the GGA of the same epochs is not doubled in).
    assert len(walk["pvt"]) == 536 and len(fixes) == len(vels) == BUS_EPOCHS
    for fix, vel, pvt in zip(fixes, vels, walk["pvt"]):
        assert _posix(fix.header.stamp) == pytest.approx(_utc_posix(pvt["utc"]), abs=1e-3)
        assert (fix.latitude, fix.longitude) == pytest.approx((pvt["lat"], pvt["lon"]), abs=1e-9)
        assert fix.altitude == pytest.approx(pvt["h"], abs=1e-6)  # ellipsoidal, not hMSL
        assert fix.altitude != pytest.approx(pvt["h_msl"], abs=1.0)
        assert fix.position_covariance[0] == pytest.approx(pvt["h_acc"] ** 2)
        assert fix.position_covariance[8] == pytest.approx(pvt["v_acc"] ** 2)
        assert fix.position_covariance_type == NavSatFix.COVARIANCE_TYPE_DIAGONAL_KNOWN
        # carrSoln 2 RTK fixed, 1 float (no NavSatStatus of its own: SBAS_FIX), 0 none
        assert fix.status.status == {2: NavSatStatus.STATUS_GBAS_FIX,
                                     1: NavSatStatus.STATUS_SBAS_FIX}.get(
                                         pvt["carr"], NavSatStatus.STATUS_FIX)
        lin = vel.twist.twist.linear
        np.testing.assert_allclose([lin.x, lin.y, lin.z], pvt["vel_enu"], atol=1e-9)
        assert vel.twist.covariance[0] == pytest.approx(pvt["s_acc"] ** 2)
        assert vel.header.frame_id == "enu"
    assert fixes[0].status.service & NavSatStatus.SERVICE_GALILEO


def test_ephemerides_explain_the_pseudoranges(bus_run, walk):
    """Satellite positions from the published fields (in the message's own week numbering)
    against the recorded pseudoranges at the receiver's NAV-PVT position: after the common
    receiver clock, the residuals are atmosphere-sized (a mis-mapped field gives kilometres)."""
    from ins_gnss_ros.gnss.ephemeris import KeplerEphemeris, sat_position

    _, out = bus_run
    ephs = {f"{LETTER[m.system]}{m.prn:02d}": m for m in out["/gnss/ephemeris"]}
    assert set(ephs) == EXPECTED_EPHEMERIDES - {"E14", "G27"}  # those complete after 60 s
    week_offset = {"G": 0, "E": 1024, "C": 1356}
    time_offset = {"G": 0.0, "E": 0.0, "C": 14.0}  # BDT = GPST - 14 s
    raw, pvt = walk["rawx"][BUS_EPOCHS - 1], walk["pvt"][BUS_EPOCHS - 1]
    rx = np.array(pymap3d.geodetic2ecef(pvt["lat"], pvt["lon"], pvt["h"]))
    t_rx = raw["week"] * 604800.0 + raw["tow"]
    # Clock-reference signals: GPS L1 C/A (sigId 0), Galileo E1 B (1), BeiDou B3I (4).
    wanted = {(0, 0), (2, 1), (3, 4)}
    residuals = []
    for g, sv, sig, pr in zip(raw["gnss"], raw["sv"], raw["sig"], raw["pr"]):
        sat = f"{LETTER.get(g, '?')}{sv:02d}"
        if (g, sig) not in wanted or sat not in ephs or not math.isfinite(pr):
            continue
        m = ephs[sat]
        base = (m.week + week_offset[sat[0]]) * 604800.0 + time_offset[sat[0]]
        eph = KeplerEphemeris(
            system=sat[0], prn=m.prn, toe=base + m.toe, toc=base + m.toc, sqrt_a=m.sqrt_a,
            e=m.eccentricity, m0=m.m0, delta_n=m.delta_n, omega0=m.omega0, i0=m.i0,
            omega=m.omega, idot=m.idot, omega_dot=m.omega_dot, cuc=m.cuc, cus=m.cus, crc=m.crc,
            crs=m.crs, cic=m.cic, cis=m.cis, af0=m.af0, af1=m.af1, af2=m.af2, tgd=m.tgd,
            bgd_e5a=0.0, iode=m.iode, health=m.health, accuracy_index=0)
        t_tx = t_rx - pr / C
        xyz, clock, _, _ = sat_position(eph, t_tx)
        # Earth rotation during the flight time (Sagnac), first order.
        flight = np.linalg.norm(xyz - rx) / C
        theta = 7.2921151467e-5 * flight
        xyz = np.array([xyz[0] + theta * xyz[1], xyz[1] - theta * xyz[0], xyz[2]])
        residuals.append(pr + C * clock - np.linalg.norm(xyz - rx))
    residuals = np.array(residuals)
    assert len(residuals) >= 10
    spread = residuals - np.median(residuals)
    assert np.max(np.abs(spread)) < 60.0, spread


def test_file_at_recorded_pace_releases_one_epoch_per_quarter_second(walk, context, tmp_path):
    from ins_gnss_ros.gnss.sources import Pacer

    path = tmp_path / "first_epochs.ubx"
    path.write_bytes(walk["bytes"][:_nth_rawx_offset(walk["bytes"], 8)])
    node, bus, out = _bus_node(context, source=f"file://{path}")  # pace=recorded by default
    clock = [0.0]
    node.pacer = Pacer(lambda: clock[0])
    released = []
    for _ in range(8):
        for _ in range(5):  # polling more often than epochs are due releases nothing more
            node.poll()
            bus.drain()
        released.append(len(out["/gnss/observations"]))
        clock[0] += 0.25    # the recording's 4 Hz epoch spacing
    assert released == [1, 2, 3, 4, 5, 6, 7, 8]
    # NAV-PVT is tagged 2 ms after its RXM-RAWX (receiver clock offset): the 8th is still held.
    assert len(out["/gnss/fix"]) == 7
    node.poll()
    bus.drain()
    assert len(out["/gnss/fix"]) == 8
    node.destroy_node()


def test_glonass_ephemeris_message_carries_tb_in_moscow_time():
    from builtin_interfaces.msg import Time

    from ins_gnss_ros.gnss.glonass import GlonassEphemeris
    from ins_gnss_ros.nodes.gnss_messages import ephemeris_msg

    # tb = 2025-08-28 21:15:00 UTC(SU) + 3 h = 00:15:00 Moscow time on the 29th.
    utc = dt.datetime(2025, 8, 28, 21, 15, 0)
    t_gps = (utc - GPS_EPOCH).total_seconds() + 18
    eph = GlonassEphemeris(prn=5, freq_slot=-3, toe=t_gps, pos=(1.0e7, -2.0e7, 0.5e7),
                           vel=(100.0, 200.0, -3000.0), acc=(1e-6, 0.0, -2e-6), tau_n=1e-5,
                           gamma_n=1e-12, health=0, age_days=0)
    msg = ephemeris_msg(eph, Time(sec=1), 18)
    assert (msg.system, msg.prn, msg.frequency_slot) == (6, 5, -3)
    assert msg.tb == 15 * 60.0 and msg.iode == 1
    assert msg.week * 604800 + msg.toe == t_gps
    assert list(msg.position) == [1.0e7, -2.0e7, 0.5e7] and msg.velocity[2] == -3000.0
    assert (msg.acceleration[2], msg.tau_n, msg.gamma_n) == (-2e-6, 1e-5, 1e-12)


# -- bad input ------------------------------------------------------------------------------------

def test_bad_bytes_mid_stream_are_counted_and_later_frames_decode(walk, context):
    data = walk["bytes"]
    starts = [_nth_rawx_offset(data, k) for k in range(12)]
    corrupted = bytearray(data[:starts[11]])   # 11 RAWX epochs
    corrupted[starts[6] + 20] ^= 0xFF          # epoch 7: checksum fails
    garbage = bytes(random.Random(1).randrange(256) for _ in range(3000))
    stream = bytes(corrupted[:starts[3]]) + garbage + bytes(corrupted[starts[3]:])
    node, bus, out = _bus_node(context, source=NO_SOURCE)
    for k in range(0, len(stream), 777):        # arbitrary cuts through frames
        node.feed(stream[k:k + 777])
        bus.drain()
    tows = [m.time_of_week for m in out["/gnss/observations"]]
    expected = [r["tow"] for i, r in enumerate(walk["rawx"][:11]) if i != 6]
    assert tows == expected
    assert node.diag.counts["garbage bytes skipped"] >= 1
    assert node.diag.counts["bad checksum"] >= 1
    node.diag.publish()
    bus.drain()
    status = out["/diagnostics"][-1].status[0]
    values = {kv.key: kv.value for kv in status.values}
    assert int(values["garbage_bytes"]) >= 3000 and status.level == DiagnosticStatus.WARN
    node.destroy_node()


def test_vanished_serial_port_is_reported_and_node_stays_up(walk, context):
    master, slave = os.openpty()
    tty.setraw(slave)
    node, bus, out = _bus_node(context, source=f"serial://{os.ttyname(slave)}",
                               reconnect__initial_s=0.01)
    try:
        node.poll()
        assert node.diag.counts["source connected"] == 1
        os.write(master, walk["bytes"][:3000])
        deadline = time.monotonic() + 10.0
        while node.decoder.stats["bytes_in"] < 3000 and time.monotonic() < deadline:
            node.poll()
        os.close(master)
        master = None
        deadline = time.monotonic() + 10.0
        while not node.diag.counts["source lost"] and time.monotonic() < deadline:
            node.poll()
        assert node.diag.counts["source lost"] == 1
    finally:
        if master is not None:
            os.close(master)
        os.close(slave)
    deadline = time.monotonic() + 10.0
    while node.diag.counts["source connect failed"] < 2 and time.monotonic() < deadline:
        node.poll()  # reconnection attempts with backoff, never an exception
    assert node.diag.counts["source connect failed"] >= 2
    node.diag.publish()
    bus.drain()
    status = out["/diagnostics"][-1].status[0]
    assert status.level == DiagnosticStatus.WARN
    assert "source lost" in {kv.key for kv in status.values}
    node.destroy_node()


def test_bad_source_url_is_one_clear_error(context):
    from ins_gnss_ros.nodes.base import ParameterError

    with pytest.raises(ParameterError, match="source"):
        _bus_node(context, source="udp://127.0.0.1:5000")


# -- TCP, heading, time pulse, NMEA ---------------------------------------------------------------

def test_tcp_source_against_loopback_server(walk, context):
    n_epochs = 40
    data = walk["bytes"][:_nth_rawx_offset(walk["bytes"], n_epochs)]
    server = socket.create_server(("127.0.0.1", 0))
    server.settimeout(10.0)

    def serve():
        conn, _ = server.accept()
        with conn:
            conn.sendall(data)

    thread = threading.Thread(target=serve, daemon=True)
    thread.start()
    node, bus, out = _bus_node(context, source=f"tcp://127.0.0.1:{server.getsockname()[1]}")
    try:
        deadline = time.monotonic() + 20.0
        while not node.diag.counts["source lost"] and time.monotonic() < deadline:
            node.poll()   # the server closes after sending: reported, the node keeps going
            bus.drain()
            time.sleep(0.001)
        assert node.diag.counts["source lost"] == 1
        assert len(out["/gnss/observations"]) == n_epochs
        tows = [m.time_of_week for m in out["/gnss/observations"]]
        assert tows == [r["tow"] for r in walk["rawx"][:n_epochs]]
    finally:
        thread.join(10.0)
        server.close()
        node.destroy_node()


def _pvt_frame(itow_ms, utc):
    payload = bytearray(92)
    struct.pack_into("<IHBBBBBB", payload, 0, itow_ms, utc.year, utc.month, utc.day, utc.hour,
                     utc.minute, utc.second, 0x07)
    struct.pack_into("<iBBBB", payload, 16, utc.microsecond * 1000, 3, 0x81, 0, 20)
    struct.pack_into("<iiii", payload, 24, 300_000_000, 600_000_000, 100_000, 120_000)
    return ubx_frame(0x01, 0x07, bytes(payload))


def _relposned_frame(itow_ms, ned_cm, heading_deg, acc_heading_deg, flags):
    payload = bytearray(64)
    payload[0] = 1  # version 1 (F9 and later)
    length = math.sqrt(sum(v * v for v in ned_cm))
    struct.pack_into("<IiiiiiI", payload, 4, itow_ms, *ned_cm, round(length),
                     round(heading_deg * 1e5), 0)
    struct.pack_into("<IIIII", payload, 36, 100, 100, 200, 50, round(acc_heading_deg * 1e5))
    struct.pack_into("<I", payload, 60, flags)
    return ubx_frame(0x01, 0x3C, bytes(payload))


# NAV-RELPOSNED flags: gnssFixOK 0x1, diffSoln 0x2, relPosValid 0x4, carrSoln fixed 0x10,
# float 0x08, relPosHeadingValid 0x100.
FIXED, FLOAT = 0x1 | 0x2 | 0x4 | 0x10 | 0x100, 0x1 | 0x2 | 0x4 | 0x08 | 0x100


def test_heading_from_relposned_only_when_fixed_with_mounting_offsets(context):
    from ins_gnss_msgs.msg import Heading

    node, bus, out = _bus_node(context, source=NO_SOURCE, fix_source="ubx",
                               heading__azimuth_offset_deg=90.0, heading__pitch_offset_deg=1.0)
    utc = dt.datetime(2025, 8, 28, 17, 30, 0)
    itow = 4 * 86400_000 + (17 * 3600 + 30 * 60 + 18) * 1000  # Thursday, 18 leap seconds
    # Baseline 2 m to the north-west (azimuth 315 deg), rising 5 deg, antenna pair mounted
    # across the body: baseline azimuth = body azimuth + 90 deg -> body azimuth 225 deg.
    horiz = 1000.0
    ned = (round(horiz * math.cos(math.radians(315))), round(horiz * math.sin(math.radians(315))),
           -round(horiz * math.tan(math.radians(5.0))))
    node.feed(_pvt_frame(itow, utc) + _relposned_frame(itow, ned, 315.0, 0.3, FIXED)
              + _relposned_frame(itow + 250, ned, 315.0, 0.3, FLOAT))
    bus.drain()
    (h,) = out["/gnss/heading"]
    assert math.degrees(h.azimuth) == pytest.approx(225.0, abs=1e-6)
    assert h.azimuth_variance == pytest.approx(math.radians(0.3) ** 2)
    assert math.isnan(h.pitch)  # a cross-body baseline does not observe pitch
    assert (h.source, h.reference, h.status) == (Heading.SOURCE_RECEIVER,
                                                 Heading.REFERENCE_TRUE, Heading.STATUS_FIXED)
    assert h.baseline_length == pytest.approx(math.hypot(horiz, ned[2]) / 100.0, abs=0.01)
    assert _posix(h.header.stamp) == pytest.approx(_utc_posix(utc))
    assert node.diag.counts["NAV-RELPOSNED not carrier-fixed: no heading"] == 1
    node.destroy_node()
    # Fore-aft baseline: pitch (nose up) = baseline elevation - elevation offset.
    node, bus, out = _bus_node(context, source=NO_SOURCE, heading__pitch_offset_deg=1.0)
    node.feed(_pvt_frame(itow, utc) + _relposned_frame(itow, ned, 315.0, 0.3, FIXED))
    bus.drain()
    (h,) = out["/gnss/heading"]
    elevation = math.degrees(math.atan2(-ned[2], math.hypot(ned[0], ned[1])))
    assert math.degrees(h.azimuth) == pytest.approx(315.0, abs=1e-6)
    assert math.degrees(h.pitch) == pytest.approx(elevation - 1.0, abs=1e-9)
    assert elevation == pytest.approx(5.0, abs=0.1)
    node.destroy_node()


def test_time_reference_from_tim_tp(context):
    node, bus, out = _bus_node(context, source=NO_SOURCE)
    week, tow_ms, q_err_ps = 2381, 408640000, -1500
    payload = struct.pack("<IIiHBB", tow_ms, 0, q_err_ps, week, 0, 0)  # time base GNSS
    node.feed(ubx_frame(0x0D, 0x01, payload))
    bus.drain()
    (ref,) = out["/gnss/time_reference"]
    utc = GPS_EPOCH + dt.timedelta(weeks=week, milliseconds=tow_ms) - dt.timedelta(seconds=18)
    assert (ref.header.stamp.sec, ref.header.stamp.nanosec) == (calendar.timegm(utc.timetuple()), 0)
    assert _posix(ref.time_ref) - _posix(ref.header.stamp) == pytest.approx(-1.5e-9, abs=2e-9)
    node.destroy_node()


def test_nmea_only_receiver_gives_fix_velocity_and_hdt_heading(context):
    from sensor_msgs.msg import NavSatFix, NavSatStatus

    node, bus, out = _bus_node(context, source=NO_SOURCE,
                               heading__azimuth_offset_deg=-2.0)
    stream = (nmea_sentence("GNRMC,235959.50,A,5955.000,N,03018.000,E,10.0,90.0,310825,,,R,V")
              + nmea_sentence("GNGGA,000000.00,5955.000,N,03018.000,E,4,12,0.8,15.0,M,17.5,M,1.0,0000")
              + nmea_sentence("GNGST,000000.00,0.5,0.02,0.01,30.0,0.012,0.015,0.030")
              + nmea_sentence("GNGGA,000000.25,5955.000,N,03018.000,E,4,12,0.8,15.0,M,17.5,M,1.0,0000")
              + nmea_sentence("GNHDT,123.4,T"))
    node.feed(stream)
    bus.drain()
    first, second = out["/gnss/fix"]
    # GGA time after midnight, dated from the RMC of 2025-08-31 23:59:59.5: the next day.
    assert _posix(first.header.stamp) == calendar.timegm((2025, 9, 1, 0, 0, 0))
    assert first.latitude == pytest.approx(59.9166666667) and first.altitude == 32.5
    assert first.status.status == NavSatStatus.STATUS_GBAS_FIX
    assert first.position_covariance_type == NavSatFix.COVARIANCE_TYPE_APPROXIMATED
    assert first.position_covariance[0] == pytest.approx((0.8 * 5.0) ** 2)
    assert second.position_covariance_type == NavSatFix.COVARIANCE_TYPE_DIAGONAL_KNOWN
    assert list(second.position_covariance[::4]) == pytest.approx([0.015 ** 2, 0.012 ** 2,
                                                                   0.030 ** 2])
    (vel,) = out["/gnss/vel"]  # 10 kn due east
    lin = vel.twist.twist.linear
    assert (lin.x, lin.y) == pytest.approx((10 * 1852 / 3600, 0.0), abs=1e-9)
    (h,) = out["/gnss/heading"]
    assert math.degrees(h.azimuth) == pytest.approx(125.4)
    assert h.header.stamp == second.header.stamp
    node.destroy_node()


# -- the real process on a pseudo-terminal ---------------------------------------------------------

def test_driver_process_on_a_pty_publishes_the_recorded_walk(walk, probe, executor):
    from diagnostic_msgs.msg import DiagnosticArray
    from ins_gnss_msgs.msg import GnssEphemeris, GnssObservations
    from sensor_msgs.msg import NavSatFix

    from ins_gnss_ros.nodes.base import SENSOR_QOS, STATE_QOS

    master, slave = os.openpty()
    tty.setraw(slave)
    got = defaultdict(list)
    probe.create_subscription(GnssObservations, "gnss/observations",
                              lambda m: got["obs"].append(m.time_of_week), SENSOR_QOS)
    probe.create_subscription(NavSatFix, "gnss/fix", lambda m: got["fix"].append(m), SENSOR_QOS)
    probe.create_subscription(GnssEphemeris, "gnss/ephemeris",
                              lambda m: got["eph"].append(f"{LETTER[m.system]}{m.prn:02d}"),
                              STATE_QOS)
    probe.create_subscription(
        DiagnosticArray, "/diagnostics",
        lambda m: got["diag"].extend(kv.key for st in m.status for kv in st.values), 10)
    try:
        with NodeProcess("python", "-p", f"source:=serial://{os.ttyname(slave)}?baud=115200",
                         node_name="gnss_driver",
                         extra_args=("-m", "ins_gnss_ros.nodes.gnss_driver_node")) as proc:
            proc.wait_on_graph(probe, executor, timeout=60.0)
            wait_for_endpoints(probe, executor, publishes=TOPICS, timeout=60.0)
            # pyserial flushes the input when it opens the port: write only once the driver
            # says (on /diagnostics) that it has opened it.
            spin_until(executor, lambda: "source connected" in got["diag"], timeout=60.0,
                       what="the driver to open the pty")
            writer = threading.Thread(target=_write_all, args=(master, walk["bytes"]),
                                      daemon=True)
            writer.start()
            try:
                spin_until(executor, lambda: len(got["obs"]) >= 536 and len(got["fix"]) >= 536
                           and set(got["eph"]) >= EXPECTED_EPHEMERIDES, timeout=120.0,
                           what="the whole walk")
            except TimeoutError as err:
                counts = {k: len(v) for k, v in got.items() if k != "diag"}
                raise AssertionError(f"{err}: received {counts}\n{proc.output()[-3000:]}") from None
            assert got["obs"] == [r["tow"] for r in walk["rawx"]]
            assert len(got["fix"]) == 536 and set(got["eph"]) == EXPECTED_EPHEMERIDES
            assert proc.stop() == 0, proc.output()
    finally:
        os.close(master)
        os.close(slave)
