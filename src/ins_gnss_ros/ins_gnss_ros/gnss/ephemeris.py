"""Satellite orbit and clock from broadcast Keplerian ephemerides (GPS, Galileo), and the
geometry between a satellite and a receiver.

The orbit algorithm is the user algorithm of IS-GPS-200 Table 20-IV (with the velocity
formulas of its later revisions); the Galileo OS SIS ICD §5.1.1 uses the same algorithm
with its own gravitational constant (same Earth rotation rate, both in a WGS-84-aligned
frame: GTRF and WGS-84 agree at the centimetre level).  BeiDou MEO/IGSO satellites
(BDS-SIS-ICD-B1I 3.0 §5.2.4.12) use it with CGCS2000 constants and BDT seconds of week;
the GEO satellites, which need an extra rotation, are not supported.
"""
import math
from dataclasses import dataclass

import numpy as np

from ..nav.earth import ecef_to_enu_matrix, ecef_to_geodetic
from .constants import (BEIDOU, C_LIGHT, FREQ_B1I, FREQ_B3I, FREQ_E1, FREQ_E5A, FREQ_E5B,
                        FREQ_L1, FREQ_L2, GALILEO, GM_BDS, GM_GAL, GM_GPS, OMEGA_E, OMEGA_E_BDS)
from .glonass import GlonassEphemeris, glonass_sat_position
from .time import BDT_MINUS_GPST_S, wrap_week_difference

#: GPS/BeiDou URA index -> metres (IS-GPS-200 §20.3.3.3.1.3 upper bounds; BDS-SIS-ICD-B1I
#: §5.2.4.5 uses the same table).
_URA_M = (2.4, 3.4, 4.85, 6.85, 9.65, 13.65, 24.0, 48.0, 96.0, 192.0, 384.0, 768.0, 1536.0,
          3072.0, 6144.0)


@dataclass(frozen=True)
class KeplerEphemeris:
    """Broadcast Keplerian ephemeris and clock parameters of one GPS or Galileo satellite.

    Times are absolute GPS seconds (`gnss.time`), angles radians, rates rad/s.

    Attributes
    ----------
    system : str
        "G", "E" or "C" (BeiDou MEO/IGSO).
    prn : int
    toe, toc : float
        Ephemeris and clock reference times [GPS s].
    sqrt_a : float
        Square root of the semi-major axis [sqrt(m)].
    e : float
        Eccentricity.
    m0, delta_n, omega0, i0, omega, idot, omega_dot : float
        Mean anomaly at toe, mean-motion correction [rad/s], longitude of the ascending
        node at the week epoch, inclination, argument of perigee, inclination rate,
        node rate.
    cuc, cus, crc, crs, cic, cis : float
        Harmonic corrections [rad, rad, m, m, rad, rad].
    af0, af1, af2 : float
        Clock polynomial [s, s/s, s/s^2].
    tgd : float
        GPS: L1/L2 group delay T_GD; Galileo I/NAV: BGD(E1, E5b); BeiDou D1: TGD1 (B1I
        relative to the B3I clock reference) [s].
    bgd_e5a : float
        Galileo BGD(E1, E5a) [s] (0 for GPS).
    iode, health, accuracy_index : int
        Issue of data, health bits, URA / SISA index.
    """

    system: str
    prn: int
    toe: float
    toc: float
    sqrt_a: float
    e: float
    m0: float
    delta_n: float
    omega0: float
    i0: float
    omega: float
    idot: float
    omega_dot: float
    cuc: float
    cus: float
    crc: float
    crs: float
    cic: float
    cis: float
    af0: float
    af1: float
    af2: float
    tgd: float
    bgd_e5a: float
    iode: int
    health: int
    accuracy_index: int

    @property
    def sat_id(self):
        """RINEX satellite identifier, e.g. "E07"."""
        return f"{self.system}{self.prn:02d}"

    @property
    def gm(self):
        """Gravitational constant of this system's orbit model [m^3/s^2]."""
        return {GALILEO: GM_GAL, BEIDOU: GM_BDS}.get(self.system, GM_GPS)

    @property
    def omega_e(self):
        """Earth rotation rate of this system's orbit model [rad/s]."""
        return OMEGA_E_BDS if self.system == BEIDOU else OMEGA_E

    @property
    def toe_of_week(self):
        """toe in the system's own seconds of week (BDT for BeiDou) [s]: the node
        longitude of the ICD algorithm is referred to the system's week start."""
        offset = BDT_MINUS_GPST_S if self.system == BEIDOU else 0.0
        return (self.toe + offset) % 604800.0

    @property
    def relativistic_f(self):
        """F = -2 sqrt(mu) / c^2 [s/sqrt(m)] (IS-GPS-200 §20.3.3.3.3.1: -4.442807633e-10)."""
        return -2.0 * math.sqrt(self.gm) / C_LIGHT ** 2


def accuracy_m(system: str, index: int) -> float:
    """Broadcast user range accuracy [m] from the URA index (GPS, BeiDou, QZSS) or SISA index
    (Galileo OS SIS ICD §5.1.12); NaN for 'no accuracy prediction available'."""
    if system == GALILEO:
        if index < 50:
            return index * 0.01
        if index < 75:
            return 0.5 + (index - 50) * 0.02
        if index < 100:
            return 1.0 + (index - 75) * 0.04
        if index < 126:
            return 2.0 + (index - 100) * 0.16
        return math.nan
    return _URA_M[index] if 0 <= index < len(_URA_M) else math.nan


def eccentric_anomaly(mean_anomaly, e, tol=1e-13):
    """Solve Kepler's equation M = E - e sin E by Newton iteration [rad]."""
    ecc = mean_anomaly
    for _ in range(20):
        step = (ecc - e * math.sin(ecc) - mean_anomaly) / (1.0 - e * math.cos(ecc))
        ecc -= step
        if abs(step) < tol:
            break
    return ecc


def sat_position(eph, t):
    """Satellite position, clock, velocity and clock drift at GPS time `t`.

    Implements IS-GPS-200 Table 20-IV; the clock includes the relativistic term
    F e sqrt(A) sin E (§20.3.3.3.3.1) but no group delay (see `group_delay`).

    Parameters
    ----------
    eph : KeplerEphemeris
    t : float
        GPS time of signal transmission [s] (system time, i.e. already corrected for the
        satellite clock).

    Returns
    -------
    xyz : numpy.ndarray, shape (3,)
        ECEF position at `t` in the ECEF frame of epoch `t` [m].
    clock_bias : float
        Satellite clock offset [s] (subtract c * clock_bias from the range).
    vel : numpy.ndarray, shape (3,)
        ECEF velocity (time derivative in the rotating frame) [m/s].
    clock_drift : float
        Clock rate [s/s].
    """
    a = eph.sqrt_a ** 2
    n = math.sqrt(eph.gm / a ** 3) + eph.delta_n
    tk = wrap_week_difference(t - eph.toe)
    ecc = eccentric_anomaly(eph.m0 + n * tk, eph.e)
    sin_e, cos_e = math.sin(ecc), math.cos(ecc)
    one_minus = 1.0 - eph.e * cos_e
    nu = math.atan2(math.sqrt(1.0 - eph.e ** 2) * sin_e, cos_e - eph.e)
    phi = nu + eph.omega
    s2, c2 = math.sin(2 * phi), math.cos(2 * phi)
    u = phi + eph.cus * s2 + eph.cuc * c2
    r = a * one_minus + eph.crs * s2 + eph.crc * c2
    inc = eph.i0 + eph.cis * s2 + eph.cic * c2 + eph.idot * tk
    x_orb, y_orb = r * math.cos(u), r * math.sin(u)
    node_rate = eph.omega_dot - eph.omega_e
    node = eph.omega0 + node_rate * tk - eph.omega_e * eph.toe_of_week
    sin_o, cos_o, sin_i, cos_i = math.sin(node), math.cos(node), math.sin(inc), math.cos(inc)
    xyz = np.array([x_orb * cos_o - y_orb * cos_i * sin_o,
                    x_orb * sin_o + y_orb * cos_i * cos_o,
                    y_orb * sin_i])

    ecc_dot = n / one_minus
    nu_dot = ecc_dot * math.sqrt(1.0 - eph.e ** 2) / one_minus
    u_dot = nu_dot * (1.0 + 2.0 * (eph.cus * c2 - eph.cuc * s2))
    r_dot = a * eph.e * sin_e * ecc_dot + 2.0 * nu_dot * (eph.crs * c2 - eph.crc * s2)
    inc_dot = eph.idot + 2.0 * nu_dot * (eph.cis * c2 - eph.cic * s2)
    vx_orb = r_dot * math.cos(u) - y_orb * u_dot
    vy_orb = r_dot * math.sin(u) + x_orb * u_dot
    vel = np.array([
        vx_orb * cos_o - vy_orb * cos_i * sin_o + y_orb * sin_i * sin_o * inc_dot
        - xyz[1] * node_rate,
        vx_orb * sin_o + vy_orb * cos_i * cos_o - y_orb * sin_i * cos_o * inc_dot
        + xyz[0] * node_rate,
        vy_orb * sin_i + y_orb * cos_i * inc_dot])

    dt = wrap_week_difference(t - eph.toc)
    f_rel = eph.relativistic_f
    clock_bias = eph.af0 + eph.af1 * dt + eph.af2 * dt ** 2 + f_rel * eph.e * eph.sqrt_a * sin_e
    clock_drift = eph.af1 + 2.0 * eph.af2 * dt + f_rel * eph.e * eph.sqrt_a * cos_e * ecc_dot
    return xyz, clock_bias, vel, clock_drift


def group_delay(eph, frequency_hz):
    """Group delay a single-frequency user subtracts from the broadcast clock [s].

    GPS (IS-GPS-200 §20.3.3.3.3.2): the clock refers to the L1/L2 P(Y) ionosphere-free
    combination; L1 users subtract T_GD, L2 users gamma T_GD with gamma = (f_L1/f_L2)^2
    (the L2C inter-signal correction of CNAV is not decoded, and is taken as zero).

    Galileo I/NAV (OS SIS ICD §5.1.5): the clock refers to the E1/E5b combination; E1 users
    subtract BGD(E1,E5b), E5b users gamma_b BGD(E1,E5b).  For E5a the ICD gives
    gamma_a BGD(E1,E5a) relative to the F/NAV (E1/E5a) clock.  From the BGD definition,
    the E1 delay is T_E1 = T_IF(E1,x) + BGD(E1,x) for x = E5a and E5b alike, so the F/NAV
    clock equals the I/NAV clock - BGD(E1,E5b) + BGD(E1,E5a), and the E5a delay relative
    to the I/NAV clock is BGD(E1,E5b) + (gamma_a - 1) BGD(E1,E5a).

    BeiDou D1 (BDS-SIS-ICD-B1I 3.0 §5.2.4.10): the clock refers to B3I; B1I users subtract
    TGD1.

    Returns NaN for a frequency the ephemeris does not serve.
    """
    if eph.system == BEIDOU:
        table = {FREQ_B3I: 0.0, FREQ_B1I: eph.tgd}
    elif eph.system == GALILEO:
        gamma_a = (FREQ_E1 / FREQ_E5A) ** 2
        table = {FREQ_E1: eph.tgd, FREQ_E5B: (FREQ_E1 / FREQ_E5B) ** 2 * eph.tgd,
                 FREQ_E5A: eph.tgd + (gamma_a - 1.0) * eph.bgd_e5a}
    else:
        table = {FREQ_L1: eph.tgd, FREQ_L2: (FREQ_L1 / FREQ_L2) ** 2 * eph.tgd}
    return table.get(frequency_hz, math.nan)


def sat_state(eph, t):
    """`sat_position` for either ephemeris type (Keplerian or GLONASS)."""
    if isinstance(eph, GlonassEphemeris):
        return glonass_sat_position(eph, t)
    return sat_position(eph, t)


def earth_rotation_correction(xyz, vel, flight_time):
    """Express a satellite state computed in the ECEF frame of transmission in the ECEF
    frame of reception (Sagnac correction): rotate about z by -omega_e * tau
    (Groves, "Principles of GNSS...", 2nd ed., eq. 8.36)."""
    angle = OMEGA_E * flight_time
    c, s = math.cos(angle), math.sin(angle)
    rot = np.array([[c, s, 0.0], [-s, c, 0.0], [0.0, 0.0, 1.0]])
    return rot @ xyz, rot @ vel


def satellite_at_reception(eph, t_rx, pseudorange, rx_xyz=None):
    """Satellite state for a pseudorange measured at receiver time `t_rx`.

    The transmission time in satellite clock time is t_rx - P/c exactly (the receiver clock
    error cancels); the satellite clock then gives system time.  The result is rotated
    into the ECEF frame of the reception instant using the geometric flight time (from
    `rx_xyz` when given, else P/c).

    Returns
    -------
    xyz, clock_bias, vel, clock_drift : as `sat_position`, xyz and vel in the ECEF frame
        at reception.
    """
    t_sv = t_rx - pseudorange / C_LIGHT
    _, clock, _, _ = sat_state(eph, t_sv)
    xyz, clock, vel, drift = sat_state(eph, t_sv - clock)
    flight = pseudorange / C_LIGHT if rx_xyz is None else np.linalg.norm(xyz - rx_xyz) / C_LIGHT
    xyz, vel = earth_rotation_correction(xyz, vel, flight)
    return xyz, clock, vel, drift


def elevation_azimuth(rx_xyz, sat_xyz):
    """Elevation and azimuth of a satellite seen from a receiver.

    Parameters
    ----------
    rx_xyz, sat_xyz : array_like, shape (3,)
        ECEF positions [m].

    Returns
    -------
    elevation : float
        Above the local horizontal (ellipsoid normal) [rad].
    azimuth : float
        Clockwise from north, in [0, 2 pi) [rad].
    """
    lat, lon, _ = ecef_to_geodetic(np.asarray(rx_xyz, dtype=float))
    los = np.asarray(sat_xyz, dtype=float) - np.asarray(rx_xyz, dtype=float)
    east, north, up = ecef_to_enu_matrix(lat, lon) @ los
    elevation = math.atan2(up, math.hypot(east, north))
    return elevation, math.atan2(east, north) % (2 * math.pi)
