"""Broadcast navigation data from u-blox RXM-SFRBX words.

Three message formats are decoded and assembled into complete ephemerides:

* GPS LNAV subframes 1-3 (and the ionosphere parameters of subframe 4 page 18),
  IS-GPS-200 §20.3.2-20.3.3.  u-blox delivers each 30-bit word right-aligned in a 32-bit
  word, data bits already corrected for the D30* inversion, with the previous word's D29*
  D30* in bits 31-30, so the parity of every word is checked (IS-GPS-200 Table 20-XIV).
* Galileo I/NAV word types 1-5 from E1-B page pairs, Galileo OS SIS ICD §4.3.  u-blox
  delivers the even page in words 1-4 and the odd page in words 5-8, each left-aligned;
  the CRC-24Q over both pages is checked (ICD §4.3.2.3).
* BeiDou D1 subframes 1-3 of the MEO/IGSO satellites, BDS-SIS-ICD-B1I 3.0 §5.2.4.
  u-blox delivers each de-interleaved 30-bit word right-aligned (information bits first,
  BCH parity last; the receiver has checked the BCH code).  GEO satellites (D2) are skipped.
* GLONASS navigation strings 1-4, GLONASS ICD ed. 5.1 §4.4 (85-bit strings left-aligned
  in words 1-3; the Hamming code is not checked, the u-blox receiver already rejects
  strings that fail it).

A satellite's ephemeris is published only when all its parts carry the same issue of data
(GPS IODC low 8 bits = IODE in subframes 2 and 3; Galileo IODnav in words 1-4; BeiDou
subframes 1-3 of one frame, SOW 6 s apart; GLONASS strings 1-4 received within one 30 s
frame), so a data set is never mixed across an upload.
"""

from .constants import BEIDOU, GALILEO, GLONASS, GPS, SEMICIRCLE
from .ephemeris import KeplerEphemeris
from .glonass import GlonassEphemeris
from .time import BDT_MINUS_GPST_S, glonass_tod_to_gps, time_of_week_near


def bits(value, total, start, length):
    """Unsigned field of `length` bits starting `start` bits after the MSB of a
    `total`-bit big-endian integer."""
    return (value >> (total - start - length)) & ((1 << length) - 1)


def twos(value, length):
    """Interpret an unsigned `length`-bit field as two's complement (GPS, Galileo)."""
    return value - (1 << length) if value >> (length - 1) else value


def sign_magnitude(value, length):
    """Interpret an unsigned `length`-bit field as sign (MSB) and magnitude (GLONASS)."""
    magnitude = value & ((1 << (length - 1)) - 1)
    return -magnitude if value >> (length - 1) else magnitude


# ----------------------------------------------------------------------------- GPS LNAV

#: Data-bit indices (1-based, d1..d24) of the six parity equations, with the previous
#: word's parity bit (29 = D29*, 30 = D30*) that enters each (IS-GPS-200 Table 20-XIV).
_PARITY = (
    (29, (1, 2, 3, 5, 6, 10, 11, 12, 13, 14, 17, 18, 20, 23)),
    (30, (2, 3, 4, 6, 7, 11, 12, 13, 14, 15, 18, 19, 21, 24)),
    (29, (1, 3, 4, 5, 7, 8, 12, 13, 14, 15, 16, 19, 20, 22)),
    (30, (2, 4, 5, 6, 8, 9, 13, 14, 15, 16, 17, 20, 21, 23)),
    (30, (1, 3, 5, 6, 7, 9, 10, 14, 15, 16, 17, 18, 21, 22, 24)),
    (29, (3, 5, 6, 8, 9, 10, 11, 13, 15, 19, 22, 23, 24)),
)


def gps_word_parity_ok(word):
    """Check one LNAV word as u-blox delivers it (D29* D30* in bits 31-30, D1..D30 below).

    The receiver has already removed the D30* inversion of d1..d24, so the data bits
    enter the parity equations directly.
    """
    d29s, d30s = (word >> 31) & 1, (word >> 30) & 1
    for k, (star, indices) in enumerate(_PARITY):
        parity = d29s if star == 29 else d30s
        for i in indices:
            parity ^= (word >> (30 - i)) & 1
        if parity != (word >> (5 - k)) & 1:
            return False
    return True


def gps_subframe_bits(words):
    """Pack the 24 data bits of the ten LNAV words into one 240-bit integer, or None when
    a word fails parity or the TLM preamble (0x8B, IS-GPS-200 §20.3.3.1) is missing."""
    if len(words) != 10 or not all(gps_word_parity_ok(w) for w in words):
        return None
    value = 0
    for word in words:
        value = (value << 24) | ((word >> 6) & 0xFFFFFF)
    if bits(value, 240, 0, 8) != 0x8B:
        return None
    return value


def _g(value, start, length, scale, signed=False):
    raw = bits(value, 240, start, length)
    return (twos(raw, length) if signed else raw) * scale


def decode_gps_subframe(words):
    """Decode the fields of one LNAV subframe (IS-GPS-200 Figures 20-1, 20-2, Table 20-III).

    Returns
    -------
    dict or None
        "id" (subframe 1-5), "tow" (time of week of the next subframe start [s]) and the
        subframe's parameters in SI units (angles in rad, rates in rad/s); None when the
        words fail parity.  Subframe 4 is decoded only for page 18 (ionosphere, UTC).
    """
    sf = gps_subframe_bits(words)
    if sf is None:
        return None
    out = {"id": bits(sf, 240, 43, 3), "tow": bits(sf, 240, 24, 17) * 6.0}
    sc = SEMICIRCLE
    if out["id"] == 1:
        out.update(
            week10=bits(sf, 240, 48, 10), ura=bits(sf, 240, 60, 4), health=bits(sf, 240, 64, 6),
            iodc=(bits(sf, 240, 70, 2) << 8) | bits(sf, 240, 168, 8),
            tgd=_g(sf, 160, 8, 2.0**-31, True), toc=_g(sf, 176, 16, 16.0),
            af2=_g(sf, 192, 8, 2.0**-55, True), af1=_g(sf, 200, 16, 2.0**-43, True),
            af0=_g(sf, 216, 22, 2.0**-31, True))
    elif out["id"] == 2:
        out.update(
            iode=bits(sf, 240, 48, 8), crs=_g(sf, 56, 16, 2.0**-5, True),
            delta_n=_g(sf, 72, 16, 2.0**-43 * sc, True),
            m0=twos((bits(sf, 240, 88, 8) << 24) | bits(sf, 240, 96, 24), 32) * 2.0**-31 * sc,
            cuc=_g(sf, 120, 16, 2.0**-29, True),
            e=((bits(sf, 240, 136, 8) << 24) | bits(sf, 240, 144, 24)) * 2.0**-33,
            cus=_g(sf, 168, 16, 2.0**-29, True),
            sqrt_a=((bits(sf, 240, 184, 8) << 24) | bits(sf, 240, 192, 24)) * 2.0**-19,
            toe=_g(sf, 216, 16, 16.0), fit_flag=bits(sf, 240, 232, 1))
    elif out["id"] == 3:
        out.update(
            cic=_g(sf, 48, 16, 2.0**-29, True),
            omega0=twos((bits(sf, 240, 64, 8) << 24) | bits(sf, 240, 72, 24), 32) * 2.0**-31 * sc,
            cis=_g(sf, 96, 16, 2.0**-29, True),
            i0=twos((bits(sf, 240, 112, 8) << 24) | bits(sf, 240, 120, 24), 32) * 2.0**-31 * sc,
            crc=_g(sf, 144, 16, 2.0**-5, True),
            omega=twos((bits(sf, 240, 160, 8) << 24) | bits(sf, 240, 168, 24), 32) * 2.0**-31 * sc,
            omega_dot=_g(sf, 192, 24, 2.0**-43 * sc, True),
            iode=bits(sf, 240, 216, 8), idot=_g(sf, 224, 14, 2.0**-43 * sc, True))
    elif out["id"] == 4 and bits(sf, 240, 50, 6) == 56:
        # Page 18 (SV ID 56): Klobuchar coefficients, IS-GPS-200 §20.3.3.5.1.7.
        # alpha_n in s/semicircle^n, beta_n in s/semicircle^n.
        out.update(
            page=18,
            alpha=[_g(sf, 56, 8, 2.0**-30, True), _g(sf, 64, 8, 2.0**-27, True),
                   _g(sf, 72, 8, 2.0**-24, True), _g(sf, 80, 8, 2.0**-24, True)],
            beta=[_g(sf, 88, 8, 2.0**11, True), _g(sf, 96, 8, 2.0**14, True),
                  _g(sf, 104, 8, 2.0**16, True), _g(sf, 112, 8, 2.0**16, True)],
            leap_s=twos(bits(sf, 240, 192, 8), 8))
    return out


# ------------------------------------------------------------------------ Galileo I/NAV

def crc24q(value, nbits):
    """CRC-24Q (polynomial 0x1864CFB, zero initial value) of the `nbits`-bit integer
    `value`, MSB first (Galileo OS SIS ICD §4.3.2.3, shared with RTCM 3)."""
    crc = 0
    for i in range(nbits - 1, -1, -1):
        crc ^= ((value >> i) & 1) << 23
        crc = ((crc << 1) ^ 0x1864CFB) & 0xFFFFFF if crc & 0x800000 else (crc << 1) & 0xFFFFFF
    return crc


def galileo_inav_word(words):
    """Extract the 128-bit I/NAV word from an E1-B even/odd page pair.

    Page layout (OS SIS ICD Table 39-40): even page = even/odd flag, page type, 112 bits
    of data; odd page = flag, page type, 16 bits of data, 40 reserved, 22 SAR, 2 spare,
    24 CRC.  Returns (word type, 128-bit integer) or None when the flags, alert bit or
    CRC reject the pair.
    """
    if len(words) != 8:
        return None
    even = (words[0] << 96) | (words[1] << 64) | (words[2] << 32) | words[3]
    odd = (words[4] << 96) | (words[5] << 64) | (words[6] << 32) | words[7]
    if bits(even, 128, 0, 1) != 0 or bits(odd, 128, 0, 1) != 1:
        return None
    if bits(even, 128, 1, 1) or bits(odd, 128, 1, 1):  # alert pages carry no ephemeris
        return None
    protected = (bits(even, 128, 0, 114) << 82) | bits(odd, 128, 0, 82)
    if crc24q(protected, 196) != bits(odd, 128, 82, 24):
        return None
    word = (bits(even, 128, 2, 112) << 16) | bits(odd, 128, 2, 16)
    return bits(word, 128, 0, 6), word


def _w(word, start, length, scale, signed=False):
    raw = bits(word, 128, start, length)
    return (twos(raw, length) if signed else raw) * scale


def decode_galileo_word(words):
    """Decode I/NAV word types 1-5 (Galileo OS SIS ICD §4.3.5, Tables 60-63, 71-73).

    Returns
    -------
    dict or None
        "type" and the parameters in SI units, or None for a rejected page pair or a word
        type that carries no ephemeris.
    """
    extracted = galileo_inav_word(words)
    return None if extracted is None else galileo_word_fields(*extracted)


def galileo_word_fields(wtype, w):
    """Fields of a 128-bit I/NAV word of type `wtype` (1-5), None for other types."""
    sc = SEMICIRCLE
    if wtype == 1:
        return dict(type=1, iod=bits(w, 128, 6, 10), toe=_w(w, 16, 14, 60.0),
                    m0=_w(w, 30, 32, 2.0**-31 * sc, True), e=_w(w, 62, 32, 2.0**-33),
                    sqrt_a=_w(w, 94, 32, 2.0**-19))
    if wtype == 2:
        return dict(type=2, iod=bits(w, 128, 6, 10), omega0=_w(w, 16, 32, 2.0**-31 * sc, True),
                    i0=_w(w, 48, 32, 2.0**-31 * sc, True),
                    omega=_w(w, 80, 32, 2.0**-31 * sc, True),
                    idot=_w(w, 112, 14, 2.0**-43 * sc, True))
    if wtype == 3:
        return dict(type=3, iod=bits(w, 128, 6, 10),
                    omega_dot=_w(w, 16, 24, 2.0**-43 * sc, True),
                    delta_n=_w(w, 40, 16, 2.0**-43 * sc, True),
                    cuc=_w(w, 56, 16, 2.0**-29, True), cus=_w(w, 72, 16, 2.0**-29, True),
                    crc=_w(w, 88, 16, 2.0**-5, True), crs=_w(w, 104, 16, 2.0**-5, True),
                    sisa=bits(w, 128, 120, 8))
    if wtype == 4:
        return dict(type=4, iod=bits(w, 128, 6, 10), svid=bits(w, 128, 16, 6),
                    cic=_w(w, 22, 16, 2.0**-29, True), cis=_w(w, 38, 16, 2.0**-29, True),
                    toc=_w(w, 54, 14, 60.0), af0=_w(w, 68, 31, 2.0**-34, True),
                    af1=_w(w, 99, 21, 2.0**-46, True), af2=_w(w, 120, 6, 2.0**-59, True))
    if wtype == 5:
        return dict(type=5, ai=[_w(w, 6, 11, 2.0**-2), _w(w, 17, 11, 2.0**-8, True),
                                _w(w, 28, 14, 2.0**-15, True)],
                    bgd_e5a=_w(w, 47, 10, 2.0**-32, True), bgd_e5b=_w(w, 57, 10, 2.0**-32, True),
                    health=bits(w, 128, 67, 6), week=bits(w, 128, 73, 12),
                    tow=float(bits(w, 128, 85, 20)))
    return None


# ---------------------------------------------------------------------------- BeiDou D1

#: BeiDou GEO satellites broadcast D2 and need a different orbit transformation.
BDS_GEO_PRNS = frozenset(range(1, 6)) | frozenset(range(59, 64))


def _bch15_parity(info):
    """4 parity bits of the BeiDou BCH(15,11,1) code, generator x^4 + x + 1: the remainder
    of info(x) x^4 divided by g(x) (BDS-SIS-ICD-B1I 3.0 §5.1.3)."""
    value = info << 4
    for i in range(14, 3, -1):
        if (value >> i) & 1:
            value ^= 0b10011 << (i - 4)
    return value


def beidou_d1_words_ok(words):
    """BCH check of the ten de-interleaved D1 words: word 1 = 15 plain bits, 11 information
    bits, 4 parity; words 2-10 = two 11-bit information blocks, then their two 4-bit parities."""
    first = words[0] & 0x3FFFFFFF
    if _bch15_parity((first >> 4) & 0x7FF) != first & 0xF:
        return False
    for word in words[1:]:
        if (_bch15_parity((word >> 19) & 0x7FF) != (word >> 4) & 0xF
                or _bch15_parity((word >> 8) & 0x7FF) != word & 0xF):
            return False
    return True


def _d1(value, pieces, scale=None, signed=False):
    """Field made of (start, length) pieces of the 300-bit D1 subframe, MSB piece first."""
    raw, length = 0, 0
    for start, size in pieces:
        raw = (raw << size) | bits(value, 300, start, size)
        length += size
    number = twos(raw, length) if signed else raw
    return number if scale is None else number * scale


def decode_beidou_d1(words):
    """Decode BeiDou D1 subframes 1-3 (BDS-SIS-ICD-B1I 3.0 §5.2.4, Figures 5-4 to 5-6).

    Word k occupies bits 30(k-1)..30k-1 of the 300-bit subframe; word 1 carries 26
    information bits, words 2-10 carry 22 followed by parity, so long fields are split.

    Returns
    -------
    dict or None
        "id", "sow" (BDT seconds of week of the subframe start) and parameters in SI units;
        None without the preamble 0x712, on a BCH failure or an impossible SOW (the
        receiver forwards such subframes: one occurs in the recorded walk).
    """
    if len(words) != 10 or not beidou_d1_words_ok(words):
        return None
    v = 0
    for word in words:
        v = (v << 30) | (word & 0x3FFFFFFF)
    sow = float(_d1(v, ((18, 8), (30, 12))))
    if bits(v, 300, 0, 11) != 0x712 or sow >= 604800.0 or sow % 6.0:
        return None
    sc = SEMICIRCLE
    out = {"id": bits(v, 300, 15, 3), "sow": sow}
    if out["id"] == 1:
        out.update(
            health=bits(v, 300, 42, 1), aodc=bits(v, 300, 43, 5), urai=bits(v, 300, 48, 4),
            week=bits(v, 300, 60, 13), toc=_d1(v, ((73, 9), (90, 8)), 8.0),
            tgd1=_d1(v, ((98, 10),), 1e-10, True), af2=_d1(v, ((214, 11),), 2.0**-66, True),
            af0=_d1(v, ((225, 7), (240, 17)), 2.0**-33, True),
            af1=_d1(v, ((257, 5), (270, 17)), 2.0**-50, True), aode=bits(v, 300, 287, 5))
    elif out["id"] == 2:
        out.update(
            delta_n=_d1(v, ((42, 10), (60, 6)), 2.0**-43 * sc, True),
            cuc=_d1(v, ((66, 16), (90, 2)), 2.0**-31, True),
            m0=_d1(v, ((92, 20), (120, 12)), 2.0**-31 * sc, True),
            e=_d1(v, ((132, 10), (150, 22)), 2.0**-33), cus=_d1(v, ((180, 18),), 2.0**-31, True),
            crc=_d1(v, ((198, 4), (210, 14)), 2.0**-6, True),
            crs=_d1(v, ((224, 8), (240, 10)), 2.0**-6, True),
            sqrt_a=_d1(v, ((250, 12), (270, 20)), 2.0**-19), toe_msb=bits(v, 300, 290, 2))
    elif out["id"] == 3:
        out.update(
            toe_lsb=_d1(v, ((42, 10), (60, 5))),
            i0=_d1(v, ((65, 17), (90, 15)), 2.0**-31 * sc, True),
            cic=_d1(v, ((105, 7), (120, 11)), 2.0**-31, True),
            omega_dot=_d1(v, ((131, 11), (150, 13)), 2.0**-43 * sc, True),
            cis=_d1(v, ((163, 9), (180, 9)), 2.0**-31, True),
            idot=_d1(v, ((189, 13), (210, 1)), 2.0**-43 * sc, True),
            omega0=_d1(v, ((211, 21), (240, 11)), 2.0**-31 * sc, True),
            omega=_d1(v, ((251, 11), (270, 21)), 2.0**-31 * sc, True))
    return out


# ----------------------------------------------------------------------- GLONASS strings

def glonass_string_bits(words):
    """The 85-bit GLONASS string (ICD bit 85 first), left-aligned in u-blox words 1-3."""
    if len(words) < 3:
        return None
    return ((words[0] << 64) | (words[1] << 32) | words[2]) >> (96 - 85)


def _s(string, hi, lo, scale=None, signed=False):
    """GLONASS field spanning ICD bits hi..lo (bit 85 = first transmitted); an integer
    when no scale is given."""
    length = hi - lo + 1
    raw = bits(string, 85, 85 - hi, length)
    value = sign_magnitude(raw, length) if signed else raw
    return value if scale is None else value * scale


def decode_glonass_string(words):
    """Decode GLONASS immediate-data strings 1-4 (GLONASS ICD ed. 5.1 Table 4.5).

    Returns
    -------
    dict or None
        "string" number and parameters in SI units (m, m/s, m/s^2, s), None for other
        strings.
    """
    s = glonass_string_bits(words)
    if s is None:
        return None
    m = _s(s, 84, 81)
    km = 1000.0
    if m in (1, 2, 3):
        axis = {1: "x", 2: "y", 3: "z"}[m]
        out = {"string": m, "p" + axis: _s(s, 35, 9, 2.0**-11 * km, True),
               "v" + axis: _s(s, 64, 41, 2.0**-20 * km, True),
               "a" + axis: _s(s, 40, 36, 2.0**-30 * km, True)}
        if m == 1:
            out["tk"] = _s(s, 76, 72) * 3600.0 + _s(s, 71, 66) * 60.0 + _s(s, 65, 65) * 30.0
        elif m == 2:
            out.update(health_bn=_s(s, 80, 78), tb=_s(s, 76, 70) * 900.0)
        else:
            out.update(gamma=_s(s, 79, 69, 2.0**-40, True), ln3=_s(s, 65, 65))
        return out
    if m == 4:
        return {"string": 4, "tau": _s(s, 80, 59, 2.0**-30, True),
                "dtau": _s(s, 58, 54, 2.0**-30, True), "age_days": _s(s, 53, 49),
                "ft": _s(s, 33, 30), "nt": _s(s, 26, 16), "slot": _s(s, 15, 11)}
    return None


# ------------------------------------------------------------------------------ assembly

class NavDataAssembler:
    """Collect navigation data units per satellite and emit complete ephemerides.

    Usage: pass every `NavSubframe` with the current GPS time (e.g. the last RXM-RAWX
    epoch's `t_gps`) to `add`; it returns the ephemerides completed by that unit.
    `ephemerides[sat_id]` holds the newest complete set, `klobuchar` the (alpha, beta)
    of GPS subframe 4 page 18 once seen.
    """

    def __init__(self):
        self._parts = {}
        self.ephemerides = {}
        self.klobuchar = None
        self.stats = {"rejected": 0, "ephemerides": 0}

    def add(self, unit, t_gps, leap_s=18):
        """Process one `NavSubframe`.

        Parameters
        ----------
        unit : observations.NavSubframe
        t_gps : float
            Current GPS time [s], within half a week of the data (resolves week numbers).
        leap_s : int
            GPST - UTC [s] (GLONASS time is UTC based).

        Returns
        -------
        list
            Ephemerides completed by this unit (usually empty).
        """
        if unit.system == GPS and unit.signal == "1C":
            return self._add_gps(unit, t_gps)
        if unit.system == GALILEO and unit.signal == "1B":
            return self._add_galileo(unit, t_gps)
        if unit.system == BEIDOU and unit.signal in ("2I", "6I", "7I") \
                and unit.prn not in BDS_GEO_PRNS:  # B1I, B3I, B2I carry D1 on non-GEO
            return self._add_beidou(unit, t_gps)
        if unit.system == GLONASS:
            return self._add_glonass(unit, t_gps, leap_s)
        return []

    def add_records(self, records):
        """Assemble every `NavSubframe` of a decoded stream (records in stream order), each
        with the GPS time and leap seconds of the last RXM-RAWX epoch before it (units before
        the first epoch cannot be dated and are skipped). Returns :attr:`ephemerides`."""
        from .observations import NavSubframe, RawEpoch

        t_gps, leap = None, 18
        for record in records:
            if isinstance(record, RawEpoch):
                t_gps, leap = record.t_gps, record.leap_s
            elif isinstance(record, NavSubframe) and t_gps is not None:
                self.add(record, t_gps, leap)
        return self.ephemerides

    def _store(self, key, part, value):
        parts = self._parts.setdefault(key, {})
        parts[part] = value
        return parts

    def _publish(self, eph):
        self.ephemerides[eph.sat_id] = eph
        self.stats["ephemerides"] += 1
        return [eph]

    def _add_gps(self, unit, t_gps):
        sub = decode_gps_subframe(unit.words)
        if sub is None:
            self.stats["rejected"] += 1
            return []
        if sub.get("page") == 18:
            self.klobuchar = (sub["alpha"], sub["beta"])
        if sub["id"] not in (1, 2, 3):
            return []
        parts = self._store((GPS, unit.prn), sub["id"], sub)
        if len(parts) < 3:
            return []
        sf1, sf2, sf3 = parts[1], parts[2], parts[3]
        # IS-GPS-200 §20.3.3.4.1: a data set is consistent when IODE(2) = IODE(3) = the
        # 8 LSBs of IODC(1).
        if not (sf2["iode"] == sf3["iode"] == (sf1["iodc"] & 0xFF)):
            return []
        eph = _kepler(GPS, unit.prn, t_gps, {**sf1, **sf2, **sf3}, tgd=sf1["tgd"],
                      iode=sf2["iode"], health=sf1["health"], accuracy_index=sf1["ura"])
        if self.ephemerides.get(eph.sat_id) == eph:
            return []
        return self._publish(eph)

    def _add_galileo(self, unit, t_gps):
        extracted = galileo_inav_word(unit.words)
        if extracted is None:
            self.stats["rejected"] += 1
            return []
        word = galileo_word_fields(*extracted)
        if word is None:
            return []
        parts = self._store((GALILEO, unit.prn), word["type"], word)
        if not all(k in parts for k in (1, 2, 3, 4, 5)):
            return []
        iods = {parts[k]["iod"] for k in (1, 2, 3, 4)}
        if len(iods) != 1:  # OS SIS ICD §5.1.9.2: words 1-4 must share IODnav
            return []
        merged = {**parts[1], **parts[2], **parts[3], **parts[4]}
        eph = _kepler(GALILEO, unit.prn, t_gps, merged,
                      tgd=parts[5]["bgd_e5b"], iode=iods.pop(), health=parts[5]["health"],
                      accuracy_index=parts[3]["sisa"], bgd_e5a=parts[5]["bgd_e5a"])
        if self.ephemerides.get(eph.sat_id) == eph:
            return []
        return self._publish(eph)

    def _add_beidou(self, unit, t_gps):
        sub = decode_beidou_d1(unit.words)
        if sub is None:
            self.stats["rejected"] += 1
            return []
        if sub["id"] not in (1, 2, 3):
            return []
        parts = self._store((BEIDOU, unit.prn), sub["id"], sub)
        if len(parts) < 3:
            return []
        if not parts[3]["sow"] - 6.0 == parts[2]["sow"] == parts[1]["sow"] + 6.0:
            return []  # not one frame: wait for a consistent set
        merged = {**parts[1], **parts[2], **parts[3]}
        # toe is split over subframes 2 and 3 (17 bits, 8 s units); BDT = GPST - 14 s.
        bdt_ref = t_gps + BDT_MINUS_GPST_S
        merged["toe"] = ((parts[2]["toe_msb"] << 15) | parts[3]["toe_lsb"]) * 8.0
        eph = _kepler(BEIDOU, unit.prn, bdt_ref, merged, tgd=parts[1]["tgd1"],
                      iode=parts[1]["aode"], health=parts[1]["health"],
                      accuracy_index=parts[1]["urai"], time_offset=-BDT_MINUS_GPST_S)
        if self.ephemerides.get(eph.sat_id) == eph:
            return []
        return self._publish(eph)

    def _add_glonass(self, unit, t_gps, leap_s):
        string = decode_glonass_string(unit.words)
        if string is None:
            return []
        parts = self._store((GLONASS, unit.prn), string["string"], dict(string, t_rx=t_gps))
        if not all(k in parts for k in (1, 2, 3, 4)):
            return []
        received = [parts[k]["t_rx"] for k in (1, 2, 3, 4)]
        if max(received) - min(received) > 30.0:  # not from one 30 s frame (ICD §4.3)
            return []
        s1, s2, s3, s4 = parts[1], parts[2], parts[3], parts[4]
        eph = GlonassEphemeris(
            prn=unit.prn, freq_slot=unit.freq_slot,
            toe=glonass_tod_to_gps(s2["tb"], t_gps, leap_s),
            pos=(s1["px"], s2["py"], s3["pz"]), vel=(s1["vx"], s2["vy"], s3["vz"]),
            acc=(s1["ax"], s2["ay"], s3["az"]), tau_n=s4["tau"], gamma_n=s3["gamma"],
            health=s2["health_bn"] >> 2, age_days=s4["age_days"])
        if self.ephemerides.get(eph.sat_id) == eph:
            return []
        return self._publish(eph)


def _kepler(system, prn, t_ref, p, tgd, iode, health, accuracy_index, bgd_e5a=0.0,
            time_offset=0.0):
    """KeplerEphemeris from the merged parameter dict `p` of one consistent data set.

    `t_ref` is the reception time in the system's own time scale, `time_offset` what to add
    to that scale to get GPS time (BeiDou: +14 s).
    """
    names = ("sqrt_a", "e", "m0", "delta_n", "omega0", "i0", "omega", "idot", "omega_dot",
             "cuc", "cus", "crc", "crs", "cic", "cis", "af0", "af1", "af2")
    return KeplerEphemeris(
        system=system, prn=prn, toe=time_of_week_near(p["toe"], t_ref) + time_offset,
        toc=time_of_week_near(p["toc"], t_ref) + time_offset,
        tgd=tgd, bgd_e5a=bgd_e5a, iode=iode, health=health, accuracy_index=accuracy_index,
        **{name: p[name] for name in names})
