"""Broadcast navigation data decoding: GPS LNAV, Galileo I/NAV (recorded), GLONASS (synthetic)."""
import math

import pytest
from conftest import shared_path

from ins_gnss_ros.gnss.glonass import GlonassEphemeris
from ins_gnss_ros.gnss.nav_decode import (NavDataAssembler, beidou_d1_words_ok, crc24q,
                                          decode_beidou_d1, decode_galileo_word,
                                          decode_glonass_string, decode_gps_subframe,
                                          galileo_inav_word, gps_word_parity_ok)
from ins_gnss_ros.gnss.observations import NavSubframe, RawEpoch
from ins_gnss_ros.gnss.stream import Decoder
from ins_gnss_ros.gnss.time import gps_seconds


def _frames_of(data, wanted):
    """UBX frames of the given (class, id) pairs, split by the frame length field."""
    out, pos = [], 0
    while pos < len(data):
        if data[pos] == 0xB5:
            end = pos + 8 + int.from_bytes(data[pos + 4:pos + 6], "little")
            if (data[pos + 2], data[pos + 3]) in wanted:
                out.append(data[pos:end])
        else:
            end = data.index(b"\n", pos) + 1
        pos = end
    return out


@pytest.fixture(scope="module")
def nav_units():
    """First RXM-RAWX epoch (for the time) and every RXM-SFRBX of the recorded stream."""
    data = shared_path("data", "walk_0827", "gnss_1730.ubx").read_bytes()
    decoder = Decoder()
    first_raw = _frames_of(data[:20000], {(0x02, 0x15)})[0]
    epoch = decoder.feed(first_raw)[0]
    units = decoder.feed(b"".join(_frames_of(data, {(0x02, 0x13)})))
    assert isinstance(epoch, RawEpoch) and len(units) == 2328
    return epoch, units


def test_gps_parity_of_every_recorded_word(nav_units):
    _, units = nav_units
    words = [w for u in units if u.system == "G" and u.signal == "1C" for w in u.words]
    assert len(words) == 800
    assert all(gps_word_parity_ok(w) for w in words)
    # A single flipped data bit breaks parity (IS-GPS-200 parity detects all odd errors).
    assert not any(gps_word_parity_ok(w ^ (1 << 17)) for w in words[:50])


def test_gps_subframe_time_matches_receiver_time(nav_units):
    """HOW time of week (of the next subframe) lies 0-6 s after the subframe's reception and
    the 10-bit week number is GPS week 2381 modulo 1024."""
    epoch, units = nav_units
    for unit in (u for u in units if u.system == "G" and u.signal == "1C"):
        sub = decode_gps_subframe(unit.words)
        assert sub is not None and 1 <= sub["id"] <= 5
        assert 0 <= (sub["tow"] - epoch.tow) % 6 < 6
        if sub["id"] == 1:
            assert sub["week10"] == 2381 % 1024


def test_crc24q_check_value():
    # CRC-24Q catalogue check value: CRC of ASCII "123456789" is 0xCDE703.
    value = int.from_bytes(b"123456789", "big")
    assert crc24q(value, 72) == 0xCDE703


def test_galileo_pages_pass_crc_and_flipped_bits_fail(nav_units):
    _, units = nav_units
    pages = [u for u in units if u.system == "E" and u.signal == "1B"]
    assert len(pages) == 396
    assert all(galileo_inav_word(u.words) is not None for u in pages)
    damaged = list(pages[0].words)
    damaged[1] ^= 1 << 5
    assert galileo_inav_word(damaged) is None


def test_beidou_d1_time_matches_receiver_time(nav_units):
    """D1 seconds of week are BDT = GPST - 14 s, the 13-bit week is GPS week - 1356."""
    epoch, units = nav_units
    d1 = [(u, decode_beidou_d1(u.words)) for u in units if u.system == "C" and u.signal == "6I"]
    assert len(d1) == 153
    assert all(beidou_d1_words_ok(u.words) for u, _ in d1)
    # One C36 subframe passes BCH but carries SOW 639861 (> one week): it is rejected.
    assert [u.prn for u, sub in d1 if sub is None] == [36]
    damaged = list(d1[0][0].words)
    damaged[4] ^= 1 << 12
    assert not beidou_d1_words_ok(damaged)
    for _, sub in (pair for pair in d1 if pair[1] is not None):
        assert 1 <= sub["id"] <= 5 and sub["sow"] % 6 == 0
        assert -6.0 <= sub["sow"] - (epoch.tow - 14) < 200.0  # SOW: start of the 6 s subframe
        if sub["id"] == 1:
            assert sub["week"] == 2381 - 1356


def test_galileo_word5_time_matches_receiver_time(nav_units):
    """Word 5 GST week + 1024 = GPS week; its TOW lies within the 30 s before reception."""
    epoch, units = nav_units
    fives = [(u.prn, decode_galileo_word(u.words)) for u in units
             if u.system == "E" and u.signal == "1B"]
    fives = [(prn, w) for prn, w in fives if w and w["type"] == 5]
    assert len(fives) == 27
    for prn, w in fives:
        assert w["week"] + 1024 == epoch.week
        assert abs(w["tow"] - epoch.tow) < 200.0
        # E14 (eccentric-orbit satellite) broadcasts E5b/E1-B health status 1 (out of
        # service) in 2025; every other satellite is healthy.
        assert w["health"] == (0b010100 if prn == 14 else 0)
        assert abs(w["bgd_e5a"]) < 10e-9 and abs(w["bgd_e5b"]) < 10e-9


def test_assembled_ephemerides(nav_units):
    epoch, units = nav_units
    assembler = NavDataAssembler()
    for unit in units:
        assembler.add(unit, epoch.t_gps)
    ephs = assembler.ephemerides
    assert sorted(ephs) == ["C11", "C21", "C22", "C34", "C42", "C43", "C44", "C50",
                            "E07", "E08", "E13", "E14", "E26", "E29", "E33",
                            "G10", "G23", "G27", "G32"]
    assert assembler.stats["rejected"] == 1  # the C36 subframe with an impossible SOW
    for eph in ephs.values():
        # GPS orbits a = 26,560 km; Galileo 29,600 km; E14 is one of the two Galileo
        # satellites left in an eccentric orbit (e ~ 0.16, a ~ 27,977 km).
        a_km = eph.sqrt_a ** 2 / 1e3
        if eph.system == "G":
            assert a_km == pytest.approx(26560, abs=30) and eph.e < 0.03
            assert math.degrees(eph.i0) == pytest.approx(55, abs=3)
        elif eph.system == "C":
            # BeiDou-3 MEO: a = 27,906 km, i = 55 deg (BDS-OS-PS-3.0).
            assert a_km == pytest.approx(27906, abs=30) and eph.e < 0.01
            assert math.degrees(eph.i0) == pytest.approx(55, abs=2)
        elif eph.sat_id == "E14":
            assert eph.e == pytest.approx(0.16, abs=0.01) and a_km == pytest.approx(27977, abs=30)
        else:
            assert a_km == pytest.approx(29600, abs=30) and eph.e < 0.002
            assert math.degrees(eph.i0) == pytest.approx(56, abs=2)
        # toe within the 2 h validity window of the data (4 h for GPS fit intervals).
        assert abs(eph.toe - epoch.t_gps) < 4 * 3600
        # toe units: GPS 16 s, Galileo 60 s, BeiDou 8 s of BDT (= GPST - 14 s).
        step = {"G": 16, "E": 60, "C": 8}[eph.system]
        assert (eph.toe - (14 if eph.system == "C" else 0)) % step == 0
        assert eph.toc == eph.toe
        assert abs(eph.tgd) < 50e-9 and abs(eph.af0) < 2e-3
    # Health: E14 (see word 5) and C50 (SatH1 = 1) are flagged.
    assert sorted(k for k, e in ephs.items() if e.health) == ["C50", "E14"]


# ---------------------------------------------------------------------- GLONASS strings

def _glonass_string(fields):
    """Build an 85-bit GLONASS string from {(hi, lo): (value, signed)} using the ICD bit
    numbering (bit 85 first), sign-magnitude for signed fields, then left-align it in
    four 32-bit words as u-blox does."""
    value = 0
    for (hi, lo), (number, signed) in fields.items():
        length = hi - lo + 1
        raw = (abs(number) | ((1 << (length - 1)) if number < 0 else 0)) if signed else number
        assert raw < (1 << length)
        value |= raw << (lo - 1)
    packed = value << (128 - 85)
    return tuple((packed >> (96 - 32 * i)) & 0xFFFFFFFF for i in range(4))


def test_glonass_strings_decode_and_assemble():
    # Values in ICD units: km scaled by 2^-11, km/s by 2^-20, km/s^2 by 2^-30.
    px, vx, ax = -14060.9511719, -1.1405029297, 9.31322574615e-10 * 2
    s1 = _glonass_string({(84, 81): (1, False), (76, 72): (10, False), (71, 66): (15, False),
                          (65, 65): (1, False), (64, 41): (round(vx * 2**20), True),
                          (40, 36): (round(ax * 2**30), True), (35, 9): (round(px * 2**11), True)})
    s2 = _glonass_string({(84, 81): (2, False), (80, 78): (0, False), (76, 70): (42, False),
                          (64, 41): (round(2.5 * 2**20), True), (40, 36): (0, True),
                          (35, 9): (round(-8000.5 * 2**11), True)})
    s3 = _glonass_string({(84, 81): (3, False), (79, 69): (round(-1.8e-12 * 2**40), True),
                          (64, 41): (round(-2.25 * 2**20), True), (40, 36): (-3, True),
                          (35, 9): (round(19000.25 * 2**11), True)})
    s4 = _glonass_string({(84, 81): (4, False), (80, 59): (round(-1.2e-4 * 2**30), True),
                          (53, 49): (0, False), (15, 11): (5, False)})
    one = decode_glonass_string(s1)
    assert one["string"] == 1 and one["tk"] == 10 * 3600 + 15 * 60 + 30
    assert one["px"] == pytest.approx(px * 1e3, abs=0.5) and one["vx"] == pytest.approx(vx * 1e3, abs=1e-3)
    assert one["ax"] == pytest.approx(ax * 1e3, rel=1e-9)
    assert decode_glonass_string(s2)["tb"] == 42 * 900
    three = decode_glonass_string(s3)
    assert three["gamma"] == pytest.approx(-1.8e-12, abs=1e-12) and three["az"] < 0
    assert decode_glonass_string(s4)["tau"] == pytest.approx(-1.2e-4, abs=1e-9)

    assembler = NavDataAssembler()
    t_ref = gps_seconds(2381, 408639.0)
    out = []
    for words in (s1, s2, s3, s4):
        out += assembler.add(NavSubframe("R", 5, "1C", -4, words), t_ref, leap_s=18)
    assert len(out) == 1 and isinstance(out[0], GlonassEphemeris)
    eph = out[0]
    assert eph.pos[1] == pytest.approx(-8000.5e3, abs=0.5) and eph.vel[2] == pytest.approx(-2250.0, abs=1e-3)
    assert eph.tau_n == pytest.approx(-1.2e-4, abs=1e-9) and eph.freq_slot == -4
    # tb = 10:30 Moscow time = 07:30 UTC = 07:30:18 GPST on the reference day (Thursday).
    assert eph.toe == gps_seconds(2381, 4 * 86400 + 7.5 * 3600 + 18)


# ------------------------------------------------------------ GPS subframe 4, page 18

# IS-GPS-200 Table 20-XIV: data bits entering parity bits D25..D30, with D29* or D30*.
_ICD_PARITY = [
    ("29", [1, 2, 3, 5, 6, 10, 11, 12, 13, 14, 17, 18, 20, 23]),
    ("30", [2, 3, 4, 6, 7, 11, 12, 13, 14, 15, 18, 19, 21, 24]),
    ("29", [1, 3, 4, 5, 7, 8, 12, 13, 14, 15, 16, 19, 20, 22]),
    ("30", [2, 4, 5, 6, 8, 9, 13, 14, 15, 16, 17, 20, 21, 23]),
    ("30", [1, 3, 5, 6, 7, 9, 10, 14, 15, 16, 17, 18, 21, 22, 24]),
    ("29", [3, 5, 6, 8, 9, 10, 11, 13, 15, 19, 22, 23, 24]),
]


def _lnav_words(data_words):
    """u-blox style LNAV words from ten 24-bit data words: previous D29*, D30* in bits
    31-30, data d1..d24 in bits 29-6, parity D25..D30 in bits 5-0."""
    stars = {"29": 0, "30": 0}
    out = []
    for data in data_words:
        d = [(data >> (24 - i)) & 1 for i in range(1, 25)]
        parity = []
        for star, idx in _ICD_PARITY:
            parity.append(stars[star] ^ (sum(d[i - 1] for i in idx) & 1))
        word = (stars["29"] << 31) | (stars["30"] << 30) | (data << 6)
        for k, bit in enumerate(parity):
            word |= bit << (5 - k)
        out.append(word)
        stars = {"29": parity[4], "30": parity[5]}
    return out


def _twos(value, bits):
    return value & ((1 << bits) - 1)


def test_gps_page18_ionosphere_parameters():
    """Klobuchar coefficients at their IS-GPS-200 Figure 20-1 (sheet 8) positions and
    scale factors (Table 20-X): alpha 2^-30, 2^-27, 2^-24, 2^-24 s/semicircle^n;
    beta 2^11, 2^14, 2^16, 2^16 s/semicircle^n."""
    alpha_raw, beta_raw = (12, -4, -60, 64), (90 // 2, -1, -3, 5)
    tlm = 0x8B << 16
    how = (100 << 7) | (4 << 2)         # TOW count 100, subframe ID 4
    w3 = (1 << 22) | (56 << 16) | (_twos(alpha_raw[0], 8) << 8) | _twos(alpha_raw[1], 8)
    w4 = (_twos(alpha_raw[2], 8) << 16) | (_twos(alpha_raw[3], 8) << 8) | _twos(beta_raw[0], 8)
    w5 = (_twos(beta_raw[1], 8) << 16) | (_twos(beta_raw[2], 8) << 8) | _twos(beta_raw[3], 8)
    w9 = 18 << 16                       # delta t_LS = 18 s
    words = _lnav_words([tlm, how, w3, w4, w5, 0, 0, 0, w9, 0])
    assert all(gps_word_parity_ok(w) for w in words)
    sub = decode_gps_subframe(words)
    assert sub["id"] == 4 and sub["page"] == 18 and sub["tow"] == 600.0
    scales_a = (2.0**-30, 2.0**-27, 2.0**-24, 2.0**-24)
    scales_b = (2.0**11, 2.0**14, 2.0**16, 2.0**16)
    assert sub["alpha"] == pytest.approx([r * s for r, s in zip(alpha_raw, scales_a)])
    assert sub["beta"] == pytest.approx([r * s for r, s in zip(beta_raw, scales_b)])
    assert sub["leap_s"] == 18
    assembler = NavDataAssembler()
    assembler.add(NavSubframe("G", 5, "1C", 0, tuple(words)), gps_seconds(2381, 0.0))
    assert assembler.klobuchar == (sub["alpha"], sub["beta"])
