"""UBX + NMEA stream decoder: the recorded u-blox stream, framing invariants, corruption."""
import math
import random

import numpy as np
import pytest
from conftest import shared_path
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from receiver_frames import nmea_sentence, ubx_frame

from ins_gnss_ros.gnss.observations import (NavSubframe, NmeaCourse, NmeaDop, NmeaErrors,
                                            NmeaFix, NmeaHeading, NmeaRecommended,
                                            NmeaSatellites, PvtFix, RawEpoch, RelPosNed,
                                            TimePulse)
from ins_gnss_ros.gnss.stream import (Decoder, decode_file, nmea_checksum_ok, split_frames,
                                     ubx_checksum)


def _accounted(decoder):
    s = decoder.stats
    return s["frame_bytes"] + s["garbage_bytes"] + decoder.buffered == s["bytes_in"]


@pytest.fixture(scope="module")
def ubx_bytes():
    return shared_path("data", "walk_0827", "gnss_1730.ubx").read_bytes()


@pytest.fixture(scope="module")
def decoded():
    return decode_file(shared_path("data", "walk_0827", "gnss_1730.ubx"))


def test_recorded_stream_decodes_completely(decoded):
    records, stats = decoded
    # README of the data set: RXM-RAWX 536, RXM-SFRBX 2,328, NAV-PVT 536, NMEA interleaved.
    assert stats["identities"]["RXM-RAWX"] == 536
    assert stats["identities"]["RXM-SFRBX"] == 2328
    assert stats["identities"]["NAV-PVT"] == 536
    assert stats["garbage_bytes"] == stats["checksum_errors"] == stats["malformed"] == 0
    assert stats["frame_bytes"] == stats["bytes_in"] == 1551471
    epochs = [r for r in records if isinstance(r, RawEpoch)]
    assert len(epochs) == 536
    assert sum(isinstance(r, NavSubframe) for r in records) == 2328
    # 4 Hz epochs, GPS week 2381 (2025-08-28), 18 leap seconds.
    tows = np.array([e.tow for e in epochs])
    assert np.allclose(np.diff(tows), 0.25, atol=1e-3)
    assert {e.week for e in epochs} == {2381} and {e.leap_s for e in epochs} == {18}
    first = epochs[0].obs[0]
    assert (first.system, first.prn, first.signal) == ("G", 10, "5Q")
    assert first.pseudorange_m == pytest.approx(20576395.4955, abs=1e-3)
    assert first.frequency_hz == 1176.45e6


def test_pvt_matches_nmea_gga(decoded):
    """NAV-PVT and GGA of the same epoch: same position; ellipsoidal height = MSL + geoid."""
    records, _ = decoded
    pvt = next(r for r in records if isinstance(r, PvtFix))
    gga = next(r for r in records if isinstance(r, NmeaFix))
    assert math.degrees(pvt.lat) == pytest.approx(40.0966916, abs=1e-7)
    assert math.degrees(gga.lat) == pytest.approx(40.096691595, abs=1e-9)
    assert math.degrees(gga.lon) == pytest.approx(-105.14716649, abs=1e-9)
    assert pvt.h == pytest.approx(gga.h_msl + gga.geoid_sep, abs=2e-3)
    # NAV-PVT velN=1, velE=-2, velD=-27 mm/s -> ENU (-0.002, 0.001, 0.027).
    assert np.allclose(pvt.vel_enu, [-0.002, 0.001, 0.027])
    # GPS time: 2025-08-28 17:30:21.75 UTC + 18 s, GPS week 2381.
    assert pvt.t_gps == pytest.approx(2381 * 604800 + 408639.75, abs=1e-6)
    assert pvt.carr_soln == 2 and pvt.fix_type == 3


def test_any_split_gives_same_records(ubx_bytes):
    data = ubx_bytes[:60000]
    whole = Decoder().feed(data)
    rng = random.Random(1)
    decoder = Decoder()
    parts, pos = [], 0
    while pos < len(data):
        step = rng.randint(1, 700)
        parts.extend(decoder.feed(data[pos:pos + step]))
        pos += step
    assert len(parts) == len(whole)
    assert [type(r) for r in parts] == [type(r) for r in whole]
    assert _accounted(decoder)


def test_garbage_and_bad_checksums_are_counted_and_skipped():
    good = nmea_sentence("GPHDT,123.4,T")
    bad_nmea = good.replace(b"123.4", b"123.5")
    tp = ubx_frame(0x0D, 0x01, (1000).to_bytes(4, "little") + bytes(4) + (5).to_bytes(4, "little", signed=True)
              + (2381).to_bytes(2, "little") + bytes(2))
    corrupted_tp = bytearray(tp)
    corrupted_tp[10] ^= 0xFF
    stream = b"\x00\xb5junk$$" + bytes(corrupted_tp) + bad_nmea + tp + b"\xb5" + good
    decoder = Decoder()
    records = decoder.feed(stream)
    assert [type(r) for r in records] == [TimePulse, NmeaHeading]
    assert records[1].azimuth == pytest.approx(math.radians(123.4))
    assert records[0].week == 2381 and records[0].tow == pytest.approx(1.0)
    assert records[0].q_err_s == pytest.approx(5e-12)
    assert decoder.stats["checksum_errors"] == 2
    assert decoder.stats["frames_ok"] == 2
    assert _accounted(decoder) and decoder.buffered == 0


def test_oversize_length_is_garbage_and_stream_recovers():
    hdt = nmea_sentence("GNHDT,10.0,T")
    decoder = Decoder(max_ubx_payload=1000)
    records = decoder.feed(b"\xb5\x62\x02\x15\xff\xff" + hdt)
    assert [type(r) for r in records] == [NmeaHeading]
    assert decoder.buffered == 0


def test_partial_frame_waits_then_completes():
    hdt = nmea_sentence("GNHDT,10.0,T")
    decoder = Decoder()
    assert decoder.feed(hdt[:7]) == [] and decoder.buffered == 7
    assert len(decoder.feed(hdt[7:])) == 1


def test_unknown_messages_counted():
    decoder = Decoder()
    records = decoder.feed(ubx_frame(0x7F, 0x7F, b"abc") + nmea_sentence("GPXYZ,1,2"))
    assert records == [] and decoder.stats["unknown"] == 2
    assert decoder.stats["frames_ok"] == 2


def test_known_type_with_wrong_length_is_malformed():
    decoder = Decoder()
    assert decoder.feed(ubx_frame(0x01, 0x07, bytes(10))) == []  # NAV-PVT needs 92 bytes
    assert decoder.stats["malformed"] == 1


def test_nmea_sentences_to_records():
    sentences = [
        "GPRMC,123519,A,4807.038,N,01131.000,E,022.4,084.4,230394,003.1,W",
        "GPVTG,054.7,T,034.4,M,005.5,N,010.2,K,A",
        "GPGST,172814.0,0.006,0.023,0.020,273.6,0.023,0.020,0.031",
        "GNGSA,A,3,10,23,27,32,,,,,,,,,1.2,0.7,1.0,1",
        "GPGSV,3,1,11,03,03,111,00,04,15,270,00,06,01,010,00,13,06,292,00",
    ]
    records = Decoder().feed(b"".join(nmea_sentence(s) for s in sentences))
    rmc, vtg, gst, gsa, gsv = records
    assert isinstance(rmc, NmeaRecommended) and rmc.valid
    # NMEA example values: 48 deg 07.038' N, 22.4 knots, course 84.4 deg.
    assert math.degrees(rmc.lat) == pytest.approx(48 + 7.038 / 60)
    assert rmc.speed_mps == pytest.approx(22.4 * 1852 / 3600)
    assert rmc.course == pytest.approx(math.radians(84.4))
    assert rmc.utc.year == 1994 and rmc.utc.hour == 12
    assert isinstance(vtg, NmeaCourse) and vtg.speed_mps == pytest.approx(10.2 / 3.6)
    assert isinstance(gst, NmeaErrors) and gst.std_alt == pytest.approx(0.031)
    assert isinstance(gsa, NmeaDop) and gsa.svids == [10, 23, 27, 32] and gsa.hdop == 0.7
    assert isinstance(gsv, NmeaSatellites) and gsv.svid == [3, 4, 6, 13]
    assert gsv.azimuth[1] == pytest.approx(math.radians(270))


def test_relposned_record():
    """NAV-RELPOSNED v1 built from the interface-description layout."""
    def i4(v):
        return int(v).to_bytes(4, "little", signed=True)

    payload = (bytes([1, 0]) + (0).to_bytes(2, "little") + i4(1000) + i4(100) + i4(-50) + i4(3)
               + i4(111) + i4(9000000) + bytes(4) + bytes([12, 0, 0, 0])
               + i4(0) + i4(0) + i4(0) + i4(25) + i4(50000) + bytes(4))
    flags = 1 | 2 | 4 | (2 << 3) | (1 << 5) | (1 << 8)
    payload += flags.to_bytes(4, "little")
    rec = Decoder().feed(ubx_frame(0x01, 0x3C, payload))[0]
    assert isinstance(rec, RelPosNed)
    assert np.allclose(rec.rel_pos_ned, [1.0012, -0.5, 0.03])
    assert rec.length == pytest.approx(1.11)
    assert rec.azimuth == pytest.approx(math.radians(90.0))
    assert rec.acc_length == pytest.approx(0.0025)
    assert rec.carr_soln == 2 and rec.heading_valid and rec.is_moving


def test_checksum_helpers():
    # UBX-ACK-ACK for CFG-PRT, checksum from the u-blox interface description example.
    assert ubx_checksum(bytes([0x05, 0x01, 0x02, 0x00, 0x06, 0x00])) == bytes([0x0E, 0x37])
    assert nmea_checksum_ok(b"$GPGLL,5057.970,N,00146.110,E,142451,A*27\r\n")
    assert not nmea_checksum_ok(b"$GPGLL,5057.970,N,00146.110,E,142451,A*28\r\n")


# ------------------------------------------------------------------------------ fuzzing

@pytest.fixture(scope="module")
def real_frames(ubx_bytes):
    return split_frames(ubx_bytes, 400)


@settings(max_examples=300, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(data=st.data())
def test_fuzz_no_exception_and_recovery(real_frames, data):
    """Random bytes, truncated, bit-flipped and spliced real frames: nothing escapes, the
    byte accounting holds, and a clean frame after the damage decodes."""
    pieces = []
    for _ in range(data.draw(st.integers(1, 4))):
        kind = data.draw(st.sampled_from(["random", "truncated", "flipped", "spliced"]))
        frame = real_frames[data.draw(st.integers(0, len(real_frames) - 1))]
        if kind == "random":
            pieces.append(data.draw(st.binary(max_size=300)))
        elif kind == "truncated":
            pieces.append(frame[:data.draw(st.integers(0, max(0, len(frame) - 1)))])
        elif kind == "flipped":
            mutated = bytearray(frame)
            for _ in range(data.draw(st.integers(1, 5))):
                mutated[data.draw(st.integers(0, len(mutated) - 1))] ^= 1 << data.draw(st.integers(0, 7))
            pieces.append(bytes(mutated))
        else:
            other = real_frames[data.draw(st.integers(0, len(real_frames) - 1))]
            cut = data.draw(st.integers(0, len(frame)))
            pieces.append(frame[:cut] + other[data.draw(st.integers(0, len(other))):])
    decoder = Decoder(max_ubx_payload=4096)
    blob = b"".join(pieces)
    decoder.feed(blob)
    # Whatever half-frame the damage left buffered, a clean frame long enough to flush it
    # (any pending UBX length is below max_ubx_payload) ends the stream decodable.
    marker = nmea_sentence("GNHDT,42.0,T")
    tail = bytes(4200) + marker
    records = decoder.feed(tail)
    assert records and isinstance(records[-1], NmeaHeading)
    assert records[-1].azimuth == pytest.approx(math.radians(42.0))
    assert _accounted(decoder)
