"""Plain, ROS-free records of what a GNSS receiver reports.

`stream.Decoder` turns UBX and NMEA frames into these dataclasses; a ROS node maps them
onto messages one-to-one.  Conventions: angles in radians, velocities ENU [m/s],
positions geodetic (lat, lon [rad], h [m] above the WGS-84 ellipsoid), times as GPS
seconds (see `gnss.time`) where the receiver gives GNSS time, UTC datetimes where it
only gives UTC (NMEA).  Azimuths (headings) are clockwise from north, as in the
project's Heading message.  NaN marks a value the receiver did not provide.
"""
import datetime as _dt
import math
from dataclasses import dataclass, field

import numpy as np


@dataclass
class SatObs:
    """One signal tracked from one satellite in a raw-measurement epoch (UBX RXM-RAWX).

    Attributes
    ----------
    system : str
        RINEX system letter ("G", "E", "C", "R", "S", "J").
    prn : int
        Satellite number within the system (GLONASS: slot number).
    freq_slot : int
        GLONASS FDMA frequency number k (-7..+6), 0 for CDMA systems.
    signal : str
        RINEX 3 observation code of the signal, e.g. "1C", "5Q".
    frequency_hz : float
        Carrier frequency [Hz].
    pseudorange_m, doppler_hz, carrier_cycles : float
        Measurements; NaN when the receiver flags them invalid.  The Doppler sign is the
        receiver's: positive for an approaching satellite.
    cn0_dbhz : float
        Carrier-to-noise density ratio [dB-Hz].
    lock_ms : float
        Carrier-phase lock time [ms]; it drops when the phase loop slips.
    pr_std_m, cp_std_cycles, doppler_std_hz : float
        Receiver-estimated 1-sigma noise.
    half_cycle_valid : bool
        The half-cycle ambiguity is resolved (u-blox trkStat bit 2).
    half_cycle_subtracted : bool
        Half a cycle has been subtracted from the phase (u-blox trkStat bit 3).
    """

    system: str
    prn: int
    freq_slot: int
    signal: str
    frequency_hz: float
    pseudorange_m: float
    doppler_hz: float
    carrier_cycles: float
    cn0_dbhz: float
    lock_ms: float
    pr_std_m: float
    cp_std_cycles: float
    doppler_std_hz: float
    half_cycle_valid: bool
    half_cycle_subtracted: bool

    @property
    def sat_id(self):
        """Satellite identifier as in RINEX, e.g. "G07"."""
        return f"{self.system}{self.prn:02d}"


@dataclass
class RawEpoch:
    """All raw measurements of one receiver epoch (UBX RXM-RAWX).

    Attributes
    ----------
    week : int
        Full GPS week number.
    tow : float
        Receiver time of week [s] (GPS time scale, includes the receiver clock error).
    leap_s : int
        GPST - UTC [s] as the receiver knows it.
    leap_valid : bool
        Whether `leap_s` has been received from the navigation data.
    clock_reset : bool
        The receiver clock was reset (jumped): carrier-phase continuity is lost.
    obs : list of SatObs
    """

    week: int
    tow: float
    leap_s: int
    leap_valid: bool
    clock_reset: bool
    obs: list = field(default_factory=list)

    @property
    def t_gps(self):
        """Receiver time as GPS seconds since the GPS epoch."""
        return self.week * 604800.0 + self.tow


@dataclass
class NavSubframe:
    """One broadcast navigation data unit (UBX RXM-SFRBX): a GPS subframe, a Galileo
    I/NAV page pair, a GLONASS string, a BeiDou subframe.

    `words` are the 32-bit words exactly as the receiver delivers them; `gnss.nav_decode`
    interprets them.
    """

    system: str
    prn: int
    signal: str
    freq_slot: int
    words: tuple


@dataclass
class PvtFix:
    """The receiver's own navigation solution (UBX NAV-PVT).

    Attributes
    ----------
    t_gps : float
        Solution epoch as GPS seconds (NaN when the receiver has no valid time).
    utc : datetime.datetime or None
    lat, lon, h : float
        Geodetic position [rad, rad, m above ellipsoid].
    h_msl : float
        Height above mean sea level [m].
    vel_enu : numpy.ndarray, shape (3,)
        Velocity east, north, up [m/s] (converted from the receiver's NED).
    h_acc, v_acc, s_acc : float
        Horizontal, vertical position and speed accuracy estimates [m, m, m/s].
    fix_type : int
        0 no fix, 1 dead reckoning, 2 2D, 3 3D, 4 GNSS + DR, 5 time only.
    gnss_fix_ok : bool
    carr_soln : int
        0 none, 1 RTK float, 2 RTK fixed.
    num_sv : int
    pdop : float
    """

    t_gps: float
    utc: object
    lat: float
    lon: float
    h: float
    h_msl: float
    vel_enu: np.ndarray
    h_acc: float
    v_acc: float
    s_acc: float
    fix_type: int
    gnss_fix_ok: bool
    carr_soln: int
    num_sv: int
    pdop: float


@dataclass
class RelPosNed:
    """Moving-baseline or RTK relative position (UBX NAV-RELPOSNED).

    Attributes
    ----------
    itow_s : float
        GPS time of week of the solution [s].
    rel_pos_ned : numpy.ndarray, shape (3,)
        Rover relative to base, north, east, down [m].
    length : float
        Baseline length [m].
    azimuth : float
        Baseline azimuth, clockwise from north [rad].
    acc_length, acc_azimuth : float
        1-sigma accuracies [m, rad].
    gnss_fix_ok, diff_soln, rel_pos_valid, heading_valid, is_moving : bool
    carr_soln : int
        0 none, 1 float, 2 fixed.
    """

    itow_s: float
    rel_pos_ned: np.ndarray
    length: float
    azimuth: float
    acc_length: float
    acc_azimuth: float
    gnss_fix_ok: bool
    diff_soln: bool
    rel_pos_valid: bool
    heading_valid: bool
    is_moving: bool
    carr_soln: int

    @property
    def heading_fixed(self):
        """Whether the baseline heading is usable: valid, with carrier ambiguities fixed."""
        return self.rel_pos_valid and self.heading_valid and self.carr_soln == 2

    @property
    def elevation(self):
        """Elevation of the baseline above the horizon [rad] (up = -down)."""
        n, e, d = self.rel_pos_ned
        return math.atan2(-d, math.hypot(n, e))


@dataclass
class TimePulse:
    """Time of the next time pulse (UBX TIM-TP).

    Attributes
    ----------
    week : int
    tow : float
        Time of week of the next pulse in the pulse's time base [s].
    q_err_s : float
        Quantisation error of the pulse [s] (add it to the pulse time).
    time_base : int
        0 GNSS time, 1 UTC (u-blox timeBase).
    """

    week: int
    tow: float
    q_err_s: float
    time_base: int


@dataclass
class NmeaFix:
    """Position fix from NMEA GGA.

    `quality`: 0 invalid, 1 GPS, 2 DGPS, 4 RTK fixed, 5 RTK float, 6 dead reckoning.
    `h_msl` is the antenna height above mean sea level, `geoid_sep` the geoid height,
    so the ellipsoidal height is their sum.
    """

    talker: str
    utc_time: object
    lat: float
    lon: float
    h_msl: float
    geoid_sep: float
    quality: int
    num_sv: int
    hdop: float
    diff_age_s: float


@dataclass
class NmeaRecommended:
    """Recommended minimum data from NMEA RMC: date, time, position, ground velocity."""

    talker: str
    utc: object
    valid: bool
    lat: float
    lon: float
    speed_mps: float
    course: float
    mode: str

    @property
    def vel_enu(self):
        """ENU ground velocity [m/s] from speed and course over ground (clockwise from true
        north); the vertical is not reported (0)."""
        return np.array([self.speed_mps * math.sin(self.course),
                         self.speed_mps * math.cos(self.course), 0.0])


@dataclass
class NmeaCourse:
    """Course and speed over ground from NMEA VTG (course clockwise from true north)."""

    talker: str
    course: float
    speed_mps: float
    mode: str


@dataclass
class NmeaErrors:
    """Pseudorange error statistics from NMEA GST: 1-sigma errors [m]; `orientation` of the
    error ellipse semi-major axis clockwise from true north [rad]."""

    talker: str
    utc_time: object
    range_rms: float
    std_major: float
    std_minor: float
    orientation: float
    std_lat: float
    std_lon: float
    std_alt: float


@dataclass
class NmeaHeading:
    """True heading from NMEA HDT: azimuth clockwise from true north [rad]."""

    talker: str
    azimuth: float


@dataclass
class NmeaDop:
    """Active satellites and DOPs from NMEA GSA."""

    talker: str
    nav_mode: int
    svids: list
    pdop: float
    hdop: float
    vdop: float
    system_id: str


@dataclass
class NmeaSatellites:
    """One NMEA GSV sentence: satellites in view with elevation, azimuth [rad], C/N0 [dB-Hz]."""

    talker: str
    num_msg: int
    msg_num: int
    num_sv: int
    svid: list
    elevation: list
    azimuth: list
    cn0_dbhz: list


def utc_datetime(year, month, day, hour, minute, second, nano):
    """Naive UTC datetime from broken-down fields, or None when they are invalid."""
    try:
        base = _dt.datetime(year, month, day, hour, minute, min(second, 59))
    except ValueError:
        return None
    return base + _dt.timedelta(seconds=second - min(second, 59), microseconds=nano / 1000.0)
