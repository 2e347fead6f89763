"""GNSS time scales.

The project keeps GNSS time as one float: seconds of GPS time since the GPS epoch
(1980-01-06 00:00:00 UTC).  A float64 near 1.4e9 s resolves 0.24 us, which moves a
satellite by under 1 mm, so it is fine for positioning; code that needs more (carrier
phase time tags) keeps week and time-of-week separately.

Relations used (each system's ICD):

* GPST is continuous, UTC = GPST - leap seconds (IS-GPS-200 §20.3.3.5.2.4).
* Galileo System Time has the GPS rate and epoch aligned to GPST at 1999-08-22;
  the GST week number is GPS week - 1024 (Galileo OS SIS ICD §5.1.2).  The small
  GGTO offset (a few ns) is ignored.
* BeiDou Time BDT = GPST - 14 s, BDT week = GPS week - 1356 (BDS-SIS-ICD-B1I §3.3).
* GLONASS time = UTC(SU) + 3 h (GLONASS ICD ed. 5.1 §3.3.3).

The ROS time axis of the project is UTC as POSIX time, derived from GPS time with the
receiver's leap seconds: ``posix = t_gps + 315964800 - leap`` (315964800 s = 1980-01-06
00:00:00 UTC in POSIX time; POSIX time ignores leap seconds, so GPST - UTC is subtracted once).
NMEA times are UTC already and map directly.
"""
import datetime as _dt
import math

from . import observations as _obs
from .constants import BEIDOU, GALILEO, HALF_WEEK, SECONDS_PER_WEEK

GPS_EPOCH = _dt.datetime(1980, 1, 6)
#: POSIX time of the GPS epoch 1980-01-06 00:00:00 UTC [s].
GPS_EPOCH_POSIX = 315964800.0
_POSIX_EPOCH = _dt.datetime(1970, 1, 1)
GST_WEEK_OFFSET = 1024
BDT_WEEK_OFFSET = 1356
BDT_MINUS_GPST_S = -14.0
GLONASS_MINUS_UTC_S = 3 * 3600.0

#: UTC dates (inclusive) from which GPST - UTC takes the given value [s] (IERS Bulletin C).
_LEAP_SECONDS = (
    (_dt.datetime(1981, 7, 1), 1), (_dt.datetime(1982, 7, 1), 2), (_dt.datetime(1983, 7, 1), 3),
    (_dt.datetime(1985, 7, 1), 4), (_dt.datetime(1988, 1, 1), 5), (_dt.datetime(1990, 1, 1), 6),
    (_dt.datetime(1991, 1, 1), 7), (_dt.datetime(1992, 7, 1), 8), (_dt.datetime(1993, 7, 1), 9),
    (_dt.datetime(1994, 7, 1), 10), (_dt.datetime(1996, 1, 1), 11), (_dt.datetime(1997, 7, 1), 12),
    (_dt.datetime(1999, 1, 1), 13), (_dt.datetime(2006, 1, 1), 14), (_dt.datetime(2009, 1, 1), 15),
    (_dt.datetime(2012, 7, 1), 16), (_dt.datetime(2015, 7, 1), 17), (_dt.datetime(2017, 1, 1), 18),
)


def gps_seconds(week, tow):
    """Seconds of GPS time since the GPS epoch from full week number and time of week [s]."""
    return week * SECONDS_PER_WEEK + tow


def week_tow(t_gps):
    """Split GPS seconds into (full week number, time of week [s])."""
    week = int(t_gps // SECONDS_PER_WEEK)
    return week, t_gps - week * SECONDS_PER_WEEK


def wrap_week_difference(dt):
    """Wrap a time difference into [-302400, 302400) s.

    IS-GPS-200 §20.3.3.4.3: t - toe must account for the beginning or end of week
    crossover, so a difference beyond half a week is corrected by one week.
    """
    return (dt + HALF_WEEK) % SECONDS_PER_WEEK - HALF_WEEK


def time_of_week_near(tow, t_ref):
    """Absolute GPS time [s] of a time of week, taken within half a week of `t_ref`.

    Resolves the week of broadcast times (toe, toc) from the reception time, including
    the beginning/end-of-week crossover (IS-GPS-200 §20.3.3.4.3).
    """
    _, ref_tow = week_tow(t_ref)
    return t_ref + wrap_week_difference(tow - ref_tow)


def leap_seconds(utc):
    """GPST - UTC [s] at a UTC datetime (table up to the leap second of 2017-01-01)."""
    value = 0
    for start, leap in _LEAP_SECONDS:
        if utc >= start:
            value = leap
    return value


def utc_to_gps(utc, leap=None):
    """GPS seconds from a naive UTC datetime; `leap` overrides the built-in table [s]."""
    leap = leap_seconds(utc) if leap is None else leap
    return (utc - GPS_EPOCH).total_seconds() + leap


def gps_to_utc(t_gps, leap):
    """Naive UTC datetime from GPS seconds, with GPST - UTC = `leap` [s] (e.g. RXM-RAWX leapS)."""
    return GPS_EPOCH + _dt.timedelta(seconds=t_gps - leap)


def gps_to_posix(t_gps: float, leap_s: int) -> float:
    """POSIX (UTC) seconds of a GPS time [s since the GPS epoch], with GPST - UTC = ``leap_s``."""
    return t_gps + GPS_EPOCH_POSIX - leap_s


def gps_to_posix_ns(week: int, tow: float, leap_s: int) -> tuple[int, int]:
    """POSIX (UTC) time of a GPS week and time of week [s] as whole seconds and nanoseconds.

    Whole seconds are added as integers so that the receiver's time tag keeps its nanoseconds
    (a float of POSIX seconds would resolve only 0.24 us).  ``leap_s = 0`` converts a UTC week
    and time of week (u-blox TIM-TP in the UTC time base).
    """
    whole = math.floor(tow)
    nanosec = round((tow - whole) * 1e9)
    if nanosec >= 1_000_000_000:  # rounding carried into the next second
        whole, nanosec = whole + 1, nanosec - 1_000_000_000
    return (int(GPS_EPOCH_POSIX) + int(week) * int(SECONDS_PER_WEEK) + int(whole) - leap_s,
            int(nanosec))


def utc_to_posix(utc: _dt.datetime) -> float:
    """POSIX seconds of a naive UTC datetime."""
    return (utc - _POSIX_EPOCH).total_seconds()


def utc_near(time_of_day: _dt.time, ref: _dt.datetime) -> _dt.datetime:
    """The UTC datetime with this time of day closest to ``ref`` (dates an NMEA GGA time,
    across midnight too)."""
    candidate = _dt.datetime.combine(ref.date(), time_of_day)
    shift = round((ref - candidate).total_seconds() / 86400.0)
    return candidate + _dt.timedelta(days=shift)


def stream_time(record) -> float | None:
    """GPS time [s] a decoded receiver record is tagged with, for replay pacing; None for
    untimed records."""
    if isinstance(record, _obs.RawEpoch):
        return record.t_gps
    if isinstance(record, _obs.PvtFix) and math.isfinite(record.t_gps):
        return record.t_gps
    if isinstance(record, _obs.NmeaRecommended) and record.utc is not None:
        return utc_to_gps(record.utc)
    return None


def system_week(t_gps: float, system: str) -> tuple[int, float]:
    """Week number and seconds of week of a GPS time [s] in ``system``'s own time scale (BDT
    for BeiDou, GST week numbering for Galileo, GPST otherwise)."""
    if system == BEIDOU:  # BDT = GPST - 14 s, week counted from 2006-01-01 (BDS ICD §3.3)
        week, sow = divmod(t_gps + BDT_MINUS_GPST_S, SECONDS_PER_WEEK)
        return int(week) - BDT_WEEK_OFFSET, sow
    week, sow = divmod(t_gps, SECONDS_PER_WEEK)
    return int(week) - (GST_WEEK_OFFSET if system == GALILEO else 0), sow


def glonass_time_of_day(t_gps: float, leap: int) -> float:
    """Seconds of the GLONASS (Moscow, UTC(SU) + 3 h) day of a GPS time [s], with GPST - UTC =
    ``leap`` [s] (the inverse of :func:`glonass_tod_to_gps`)."""
    return (t_gps - leap + GLONASS_MINUS_UTC_S) % 86400.0


def galileo_to_gps(gst_week, tow):
    """GPS seconds from a Galileo week number (GST, 12 bits already resolved) and TOW [s]."""
    return gps_seconds(gst_week + GST_WEEK_OFFSET, tow)


def beidou_to_gps(bdt_week, tow):
    """GPS seconds from a BeiDou week number and BDT time of week [s]."""
    return gps_seconds(bdt_week + BDT_WEEK_OFFSET, tow) - BDT_MINUS_GPST_S


def glonass_tod_to_gps(tod, t_gps_ref, leap):
    """GPS seconds from a GLONASS time of day, resolved near a reference time.

    Parameters
    ----------
    tod : float
        Seconds since the start of the GLONASS (Moscow, UTC(SU) + 3 h) day.
    t_gps_ref : float
        Any GPS time within half a day of the wanted instant [s].
    leap : int
        GPST - UTC [s].
    """
    t_glo_ref = t_gps_ref - leap + GLONASS_MINUS_UTC_S
    day_start = (t_glo_ref // 86400.0) * 86400.0
    t_glo = day_start + tod
    t_glo += 86400.0 * round((t_glo_ref - t_glo) / 86400.0)
    return t_glo - GLONASS_MINUS_UTC_S + leap
