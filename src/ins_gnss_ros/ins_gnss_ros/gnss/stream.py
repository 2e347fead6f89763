"""Incremental decoder for a receiver byte stream mixing u-blox UBX and NMEA 0183.

The decoder does its own framing and resynchronisation, so that a serial line that drops,
corrupts or splices bytes never stops it: garbage, bad checksums, oversize length fields
and unknown messages are counted and skipped, and the next valid frame decodes.  Valid
frames are handed to pyubx2 / pynmeagps for field parsing, and the message types the
navigation system uses become the plain records of `gnss.observations`.

Framing rules
-------------
UBX (u-blox interface description, "UBX frame structure"): sync 0xB5 0x62, class, id,
little-endian uint16 payload length, payload, 8-bit Fletcher checksum over class..payload.
NMEA 0183: "$", printable ASCII, "*", two hex digits of the XOR of the characters between
"$" and "*", CR LF.

Every byte that enters is accounted for exactly once: either in a valid frame
(`frame_bytes`), or as `garbage_bytes`, or still buffered (`buffered`).  A candidate frame
whose checksum fails costs only its first byte, so a real frame that starts inside it is
still found.

Example
-------
>>> decoder = Decoder()
>>> for record in decoder.feed(chunk):
...     publish(record)
"""
import math
from collections import Counter

import numpy as np
from pynmeagps import NMEAReader
from pynmeagps.nmeatypes_get import NMEA_PAYLOADS_GET
from pyubx2 import UBXReader
from pyubx2.ubxtypes_decodes import GNSSLIST, SIGID

from . import observations as obs
from .constants import GLONASS, UBX_GNSS_ID, UBX_SIGNALS, carrier_frequency
from .time import gps_seconds, utc_to_gps

UBX_SYNC = b"\xb5\x62"
_NMEA_ALLOWED = bytes(range(0x20, 0x7F)) + b"\r"
_GNSS_ID_BY_NAME = {name: gid for gid, name in GNSSLIST.items()}
_SIG_ID_BY_NAME = {(gid, name): sid for (gid, sid), name in SIGID.items()}


def ubx_checksum(body):
    """8-bit Fletcher checksum (CK_A, CK_B) of a UBX frame's class..payload bytes."""
    ck_a = ck_b = 0
    for byte in body:
        ck_a = (ck_a + byte) & 0xFF
        ck_b = (ck_b + ck_a) & 0xFF
    return bytes((ck_a, ck_b))


def nmea_checksum_ok(line):
    """Whether an NMEA sentence (bytes from "$" to LF) has a matching "*hh" checksum."""
    text = line.rstrip(b"\r\n")
    star = text.rfind(b"*")
    if star < 1 or len(text) != star + 3:
        return False
    try:
        expected = int(text[star + 1:], 16)
    except ValueError:
        return False
    value = 0
    for byte in text[1:star]:
        value ^= byte
    return value == expected


class Decoder:
    """Never-crashing, bounded-memory decoder of a UBX + NMEA byte stream.

    Parameters
    ----------
    max_ubx_payload : int
        Largest UBX payload accepted [bytes]; a length field above it is taken as
        garbage.  8192 covers RXM-RAWX with its maximum of 255 measurements (8176 bytes).
    max_nmea_length : int
        Longest NMEA sentence accepted [bytes] (the standard allows 82; receivers exceed it).
    chunk_size : int
        `feed` appends at most this many bytes to its buffer at a time, which bounds
        memory to about chunk_size + max_ubx_payload whatever the caller passes.

    Attributes
    ----------
    stats : dict
        bytes_in, frame_bytes, garbage_bytes, frames_ok, checksum_errors, unknown,
        malformed (known type with an unusable payload), records, and `identities`
        (a Counter of decoded message identities, e.g. "RXM-RAWX", "GNGGA").
    """

    def __init__(self, max_ubx_payload=8192, max_nmea_length=256, chunk_size=65536):
        self.max_ubx_payload = max_ubx_payload
        self.max_nmea_length = max_nmea_length
        self.chunk_size = chunk_size
        self._buf = bytearray()
        self.stats = {
            "bytes_in": 0, "frame_bytes": 0, "garbage_bytes": 0, "frames_ok": 0,
            "checksum_errors": 0, "unknown": 0, "malformed": 0, "records": 0,
            "identities": Counter(),
        }

    @property
    def buffered(self):
        """Bytes held while waiting for the rest of a frame."""
        return len(self._buf)

    def feed(self, data):
        """Consume bytes and return the records decoded from every frame they complete.

        Parameters
        ----------
        data : bytes-like
            Any number of bytes, cut anywhere.

        Returns
        -------
        list
            Records from `gnss.observations`, in stream order.
        """
        data = bytes(data)
        self.stats["bytes_in"] += len(data)
        records = []
        for start in range(0, len(data), self.chunk_size):
            self._buf += data[start:start + self.chunk_size]
            self._drain(records)
        self.stats["records"] += len(records)
        return records

    def _drain(self, records):
        buf = self._buf
        pos = 0
        while pos < len(buf):
            lead = buf[pos]
            if lead == 0xB5:
                step = self._try_ubx(buf, pos, records)
            elif lead == 0x24:
                step = self._try_nmea(buf, pos, records)
            else:
                step = self._skip_garbage(buf, pos)
            if step == 0:
                break
            pos += step
        del buf[:pos]

    def _skip_garbage(self, buf, pos):
        candidates = [i for i in (buf.find(b"\xb5", pos), buf.find(b"$", pos)) if i >= 0]
        end = min(candidates) if candidates else len(buf)
        self.stats["garbage_bytes"] += end - pos
        return end - pos

    def _garbage_byte(self):
        self.stats["garbage_bytes"] += 1
        return 1

    def _try_ubx(self, buf, pos, records):
        """Frame a UBX message at `pos`; return bytes consumed (0 = wait for more data)."""
        available = len(buf) - pos
        if available < 2:
            return 0
        if buf[pos + 1] != 0x62:
            return self._garbage_byte()
        if available < 6:
            return 0
        length = buf[pos + 4] | (buf[pos + 5] << 8)
        if length > self.max_ubx_payload:
            return self._garbage_byte()
        if available < length + 8:
            return 0
        frame = bytes(buf[pos:pos + length + 8])
        if ubx_checksum(frame[2:-2]) != frame[-2:]:
            self.stats["checksum_errors"] += 1
            return self._garbage_byte()
        self._accept(len(frame))
        self._handle(frame, records)
        return len(frame)

    def _try_nmea(self, buf, pos, records):
        """Frame an NMEA sentence at `pos`; return bytes consumed (0 = wait for more data)."""
        limit = min(len(buf), pos + self.max_nmea_length)
        end = buf.find(b"\n", pos, limit)
        body = buf[pos:end if end >= 0 else limit]
        # A byte that cannot occur in NMEA ends the candidate at once, so a binary frame
        # that follows a stray "$" is not held up waiting for a line feed.
        if body.translate(None, _NMEA_ALLOWED):
            return self._garbage_byte()
        if end < 0:
            return self._garbage_byte() if limit - pos >= self.max_nmea_length else 0
        line = bytes(buf[pos:end + 1])
        if not nmea_checksum_ok(line):
            self.stats["checksum_errors"] += 1
            return self._garbage_byte()
        self._accept(len(line))
        self._handle(line, records)
        return len(line)

    def _accept(self, size):
        self.stats["frames_ok"] += 1
        self.stats["frame_bytes"] += size

    def _handle(self, frame, records):
        """Parse a checksum-checked UBX or NMEA frame and append its record (if its type is one
        the navigation system uses); count unknown and malformed messages."""
        ubx = frame[0] == 0xB5
        try:
            msg = UBXReader.parse(frame) if ubx else NMEAReader.parse(frame)
        except Exception:  # the parsers raise several types on odd payloads: count, never crash
            self.stats["malformed"] += 1
            return
        if ubx:
            unknown = msg.identity.startswith("UNKNOWN")
        else:
            unknown = msg is None or msg.msgID not in NMEA_PAYLOADS_GET
        if unknown:
            self.stats["unknown"] += 1
            return
        self.stats["identities"][msg.identity] += 1
        convert = _UBX_CONVERTERS.get(msg.identity) if ubx else _NMEA_CONVERTERS.get(msg.msgID)
        if convert is None:
            return
        try:
            record = convert(msg, len(frame) - 8) if ubx else convert(msg)
        except (AttributeError, TypeError, ValueError, KeyError, OverflowError):
            record = None
        if record is None:
            self.stats["malformed"] += 1
        else:
            records.append(record)


# --------------------------------------------------------------------------- UBX records

def _numeric_gnss_id(value):
    return value if isinstance(value, int) else _GNSS_ID_BY_NAME[value]


def _numeric_sig_id(gnss_id, value):
    return value if isinstance(value, int) else _SIG_ID_BY_NAME[(gnss_id, value)]


def _nav_pvt(msg, payload_len):
    if payload_len != 92:
        return None
    utc = None
    t_gps = math.nan
    if msg.validDate and msg.validTime:
        utc = obs.utc_datetime(msg.year, msg.month, msg.day, msg.hour, msg.min,
                               msg.second, msg.nano)
    if utc is not None:
        # NAV-PVT carries no week number: take it from the UTC date, the time of week
        # from iTOW, which is exact GPS time.
        tow = msg.iTOW / 1000.0
        week = round((utc_to_gps(utc) - tow) / 604800.0)
        t_gps = gps_seconds(week, tow)
    ned_to_enu = np.array([msg.velE, msg.velN, -msg.velD], dtype=float) / 1000.0
    return obs.PvtFix(
        t_gps=t_gps, utc=utc, lat=math.radians(msg.lat), lon=math.radians(msg.lon),
        h=msg.height / 1000.0, h_msl=msg.hMSL / 1000.0, vel_enu=ned_to_enu,
        h_acc=msg.hAcc / 1000.0, v_acc=msg.vAcc / 1000.0, s_acc=msg.sAcc / 1000.0,
        fix_type=int(msg.fixType), gnss_fix_ok=bool(msg.gnssFixOk),
        carr_soln=int(msg.carrSoln), num_sv=int(msg.numSV), pdop=float(msg.pDOP))


def _nav_relposned(msg, payload_len):
    if payload_len != 64:  # version 0x01 (F9 and later); version 0 has 40 bytes
        return None
    # pyubx2 already folds the 0.1 mm high-precision parts into the cm fields.
    ned_cm = np.array([msg.relPosN, msg.relPosE, msg.relPosD], dtype=float)
    return obs.RelPosNed(
        itow_s=msg.iTOW / 1000.0, rel_pos_ned=ned_cm / 100.0,
        length=msg.relPosLength / 100.0,
        azimuth=math.radians(msg.relPosHeading) % (2 * math.pi),
        acc_length=msg.accLength / 1000.0, acc_azimuth=math.radians(msg.accHeading),
        gnss_fix_ok=bool(msg.gnssFixOK), diff_soln=bool(msg.diffSoln),
        rel_pos_valid=bool(msg.relPosValid), heading_valid=bool(msg.relPosHeadingValid),
        is_moving=bool(msg.isMoving), carr_soln=int(msg.carrSoln))


def _rxm_rawx(msg, payload_len):
    if payload_len != 16 + 32 * msg.numMeas:
        return None
    epoch = obs.RawEpoch(week=int(msg.week), tow=float(msg.rcvTow), leap_s=int(msg.leapS),
                         leap_valid=bool(msg.leapSec), clock_reset=bool(msg.clkReset))
    for i in range(1, msg.numMeas + 1):
        sfx = f"_{i:02d}"
        gnss_id = _numeric_gnss_id(getattr(msg, "gnssId" + sfx))
        sig_id = _numeric_sig_id(gnss_id, getattr(msg, "sigId" + sfx))
        system = UBX_GNSS_ID.get(gnss_id)
        signal = UBX_SIGNALS.get((gnss_id, sig_id))
        if system is None or signal is None:
            continue
        slot = getattr(msg, "freqId" + sfx) - 7 if system == GLONASS else 0
        pr_valid = getattr(msg, "prValid" + sfx)
        cp_valid = getattr(msg, "cpValid" + sfx)
        # Standard deviations are coded (u-blox RXM-RAWX): pr 0.01 m * 2^n,
        # carrier phase 0.004 cycles * n, Doppler 0.002 Hz * 2^n.
        epoch.obs.append(obs.SatObs(
            system=system, prn=int(getattr(msg, "svId" + sfx)), freq_slot=slot,
            signal=signal[0], frequency_hz=carrier_frequency(system, signal[0], slot),
            pseudorange_m=getattr(msg, "prMes" + sfx) if pr_valid else math.nan,
            doppler_hz=float(getattr(msg, "doMes" + sfx)),
            carrier_cycles=getattr(msg, "cpMes" + sfx) if cp_valid else math.nan,
            cn0_dbhz=float(getattr(msg, "cno" + sfx)),
            lock_ms=float(getattr(msg, "locktime" + sfx)),
            pr_std_m=0.01 * 2 ** getattr(msg, "prStd" + sfx),
            cp_std_cycles=0.004 * getattr(msg, "cpStd" + sfx),
            doppler_std_hz=0.002 * 2 ** getattr(msg, "doStd" + sfx),
            half_cycle_valid=bool(getattr(msg, "halfCyc" + sfx)),
            half_cycle_subtracted=bool(getattr(msg, "subHalfCyc" + sfx))))
    return epoch


def _rxm_sfrbx(msg, payload_len):
    if payload_len != 8 + 4 * msg.numWords:
        return None
    gnss_id = _numeric_gnss_id(msg.gnssId)
    system = UBX_GNSS_ID.get(gnss_id)
    if system is None:
        return None
    sig_id = _numeric_sig_id(gnss_id, msg.sigId)
    signal = UBX_SIGNALS.get((gnss_id, sig_id), ("", math.nan))[0]
    words = tuple(int(getattr(msg, f"dwrd_{i:02d}")) for i in range(1, msg.numWords + 1))
    slot = msg.freqId - 7 if system == GLONASS else 0
    return obs.NavSubframe(system=system, prn=int(msg.svId), signal=signal,
                           freq_slot=slot, words=words)


def _tim_tp(msg, payload_len):
    if payload_len != 16:
        return None
    tow = msg.towMS / 1000.0 + msg.towSubMS / 1000.0
    return obs.TimePulse(week=int(msg.week), tow=tow, q_err_s=msg.qErr * 1e-12,
                         time_base=int(msg.timeBase))


_UBX_CONVERTERS = {"NAV-PVT": _nav_pvt, "NAV-RELPOSNED": _nav_relposned,
                   "RXM-RAWX": _rxm_rawx, "RXM-SFRBX": _rxm_sfrbx, "TIM-TP": _tim_tp}


# -------------------------------------------------------------------------- NMEA records

def _num(value):
    """pynmeagps leaves empty fields as "": map them to NaN."""
    return math.nan if value == "" or value is None else float(value)


def _int(value):
    return 0 if value == "" or value is None else int(value)


def _angle(value_deg):
    return math.radians(_num(value_deg))


_KNOT = 1852.0 / 3600.0


def _gga(msg):
    return obs.NmeaFix(
        talker=msg.talker, utc_time=msg.time or None, lat=_angle(msg.lat), lon=_angle(msg.lon),
        h_msl=_num(msg.alt), geoid_sep=_num(msg.sep), quality=_int(msg.quality),
        num_sv=_int(msg.numSV), hdop=_num(msg.HDOP), diff_age_s=_num(msg.diffAge))


def _rmc(msg):
    utc = None
    if msg.date and msg.time:
        utc = obs.utc_datetime(msg.date.year, msg.date.month, msg.date.day, msg.time.hour,
                               msg.time.minute, msg.time.second, msg.time.microsecond * 1000)
    return obs.NmeaRecommended(
        talker=msg.talker, utc=utc, valid=msg.status == "A", lat=_angle(msg.lat),
        lon=_angle(msg.lon), speed_mps=_num(msg.spd) * _KNOT, course=_angle(msg.cog),
        mode=str(getattr(msg, "posMode", "")))  # NMEA 2.3+ only


def _vtg(msg):
    return obs.NmeaCourse(talker=msg.talker, course=_angle(msg.cogt),
                          speed_mps=_num(msg.sogk) / 3.6, mode=str(getattr(msg, "posMode", "")))


def _gst(msg):
    return obs.NmeaErrors(
        talker=msg.talker, utc_time=msg.time or None, range_rms=_num(msg.rangeRms),
        std_major=_num(msg.stdMajor), std_minor=_num(msg.stdMinor),
        orientation=_angle(msg.orient), std_lat=_num(msg.stdLat),
        std_lon=_num(msg.stdLong), std_alt=_num(msg.stdAlt))


def _hdt(msg):
    return obs.NmeaHeading(talker=msg.talker, azimuth=_angle(msg.headingT))


def _gsa(msg):
    svids = [_int(getattr(msg, f"svid_{i:02d}", "")) for i in range(1, 13)]
    return obs.NmeaDop(talker=msg.talker, nav_mode=_int(msg.navMode),
                       svids=[s for s in svids if s], pdop=_num(msg.PDOP),
                       hdop=_num(msg.HDOP), vdop=_num(msg.VDOP),
                       system_id=str(getattr(msg, "systemId", "")))


def _gsv(msg):
    svid, elev, azim, cn0 = [], [], [], []
    for i in range(1, 5):
        sfx = f"_{i:02d}"
        if not hasattr(msg, "svid" + sfx):
            break
        svid.append(_int(getattr(msg, "svid" + sfx)))
        elev.append(_angle(getattr(msg, "elv" + sfx)))
        azim.append(_angle(getattr(msg, "az" + sfx)))
        cn0.append(_num(getattr(msg, "cno" + sfx)))
    return obs.NmeaSatellites(talker=msg.talker, num_msg=_int(msg.numMsg),
                              msg_num=_int(msg.msgNum), num_sv=_int(msg.numSV), svid=svid,
                              elevation=elev, azimuth=azim, cn0_dbhz=cn0)


_NMEA_CONVERTERS = {"GGA": _gga, "RMC": _rmc, "VTG": _vtg, "GST": _gst, "HDT": _hdt,
                    "GSA": _gsa, "GSV": _gsv}


def decode_file(path, chunk_size=4096):
    """Decode a recorded stream file; return (records, stats)."""
    decoder = Decoder()
    records = []
    with open(path, "rb") as stream:
        while chunk := stream.read(chunk_size):
            records.extend(decoder.feed(chunk))
    return records, decoder.stats


def split_frames(data, limit=None):
    """The frames of an intact recorded stream (UBX by its length field, NMEA up to LF), the
    first ``limit`` of them (None: all), as bytes each; for building test and fuzz cases."""
    frames, pos = [], 0
    while pos < len(data) and (limit is None or len(frames) < limit):
        if data[pos] == 0xB5:
            end = pos + 8 + int.from_bytes(data[pos + 4:pos + 6], "little")
        else:
            end = data.index(b"\n", pos) + 1
        frames.append(data[pos:end])
        pos = end
    return frames


__all__ = ["Decoder", "decode_file", "nmea_checksum_ok", "split_frames", "ubx_checksum"]
