"""One receiver's decoded records (:mod:`.stream`) -> what a GNSS driver publishes.

A record alone does not say everything its output needs: the GNSS time reached so far dates
navigation data and NMEA times of day, the receiver's GPST - UTC stamps every GNSS-timed output,
GST error statistics give the next GGA fix its covariance, HDT headings take the latest epoch's
stamp, and of two record kinds that give the same output (NAV-PVT or GGA fixes, NAV-RELPOSNED or
HDT headings) one is chosen.  :class:`ReceiverStream` keeps that state and turns each record into
outputs (:class:`ReceiverOutputs`), stamped with :class:`Stamp`: GNSS time on the ROS (UTC POSIX)
axis, ``t_gps + 315964800 - leap`` with the receiver's leap seconds (RXM-RAWX leapS when valid,
else the built-in table), never receive time.
"""
from __future__ import annotations

import datetime as _dt
import math
from collections import deque
from dataclasses import dataclass
from typing import Protocol

import numpy as np

from .heading import GnssHeading, receiver_heading
from .lock import LockTracker
from .nav_decode import NavDataAssembler
from .observations import (NavSubframe, NmeaErrors, NmeaFix, NmeaHeading, NmeaRecommended,
                           PvtFix, RawEpoch, RelPosNed, TimePulse)
from .time import gps_seconds, gps_to_utc, leap_seconds, time_of_week_near, utc_near, \
    utc_to_gps, week_tow

#: Largest GST-to-GGA time difference for using the GST errors as the fix covariance [s].
GST_MAX_AGE_S = 1.5
#: Navigation data units kept while no GNSS time is known yet (they need it for week numbers).
MAX_EARLY_UNITS = 1024
#: Vertical velocity variance when NMEA gives none [m^2/s^2] (RMC is horizontal only).
UNOBSERVED_VAR = 1.0e4


class ReceiverTime:
    """The GNSS time a receiver stream has reached and its GPST - UTC.

    Attributes
    ----------
    t_gps : float or None
        Latest epoch [GPS s]; None before the first.
    receiver_leap : int or None
        GPST - UTC [s] as the receiver reports it (RXM-RAWX leapS when valid); None: unknown.
    utc_ref : datetime.datetime or None
        Latest UTC date and time of an NMEA RMC sentence.
    """

    def __init__(self):
        self.t_gps: float | None = None
        self.receiver_leap: int | None = None
        self.utc_ref: _dt.datetime | None = None

    def leap(self, t_gps: float) -> int:
        """GPST - UTC [s]: the receiver's, else the built-in table's at ``t_gps`` [GPS s]."""
        if self.receiver_leap is not None:
            return self.receiver_leap
        return leap_seconds(gps_to_utc(t_gps, 18))

    def advance(self, t_gps: float) -> bool:
        """Advance the latest GNSS time to ``t_gps`` [GPS s] if later; True for the first time
        known."""
        first = self.t_gps is None
        if first or t_gps > self.t_gps:
            self.t_gps = t_gps
        return first

    def utc(self, time_of_day: _dt.time | None) -> _dt.datetime | None:
        """UTC datetime of an NMEA time of day, dated by the latest RMC, else by the latest
        GNSS time; None without a time of day or before either."""
        ref = self.utc_ref
        if ref is None and self.t_gps is not None:
            ref = gps_to_utc(self.t_gps, self.leap(self.t_gps))
        if ref is None or time_of_day is None:
            return None
        return utc_near(time_of_day, ref)


def errors_at(gst: NmeaErrors | None, utc: _dt.datetime,
              max_age_s: float = GST_MAX_AGE_S) -> NmeaErrors | None:
    """The GST error statistics if they were taken within ``max_age_s`` [s] of ``utc`` (the
    time of a GGA fix), else None."""
    if gst is None or gst.utc_time is None:
        return None
    gap = abs((utc_near(gst.utc_time, utc) - utc).total_seconds())
    return gst if gap <= max_age_s else None


class RecordSources:
    """Which record kinds feed an output that a UBX or an NMEA record kind can give.

    The choice per output: ``"ubx"``, ``"nmea"``, or ``"auto"``: NMEA until the first record of
    the UBX kind arrives, so a receiver sending both gives one output per epoch.  Kinds are
    record class names ("PvtFix", "NmeaFix", ...).
    """

    def __init__(self):
        self.seen: set[str] = set()

    def use(self, kind: str, ubx_kind: str, choice: str) -> bool:
        """Whether a record of ``kind`` feeds the output of UBX kind ``ubx_kind`` under
        ``choice`` (and remember that ``kind`` has been seen)."""
        self.seen.add(kind)
        if choice == "auto":
            return kind == ubx_kind or ubx_kind not in self.seen
        return (kind == ubx_kind) == (choice == "ubx")


# -- outputs ------------------------------------------------------------------------------------
@dataclass(frozen=True)
class Stamp:
    """When an output is stamped: a GPS week, time of week [s] and GPST - UTC [s] (kept apart so
    that the receiver's time tag keeps its nanoseconds; ``leap`` 0 for a UTC week and time of
    week), or, for NMEA outputs, a naive UTC datetime ``utc``."""

    week: int = 0
    tow: float = 0.0
    leap: int = 0
    utc: _dt.datetime | None = None


class ReceiverOutputs(Protocol):
    """Where :class:`ReceiverStream` puts what a record gives (a driver publishes it)."""

    def publish_observations(self, raw: RawEpoch, loss_of_lock: list, stamp: Stamp) -> None:
        """A raw epoch with its loss-of-lock flags (:class:`.lock.LockTracker`)."""

    def publish_fix(self, record: PvtFix | NmeaFix, errors: NmeaErrors | None,
                    stamp: Stamp) -> None:
        """A position fix: NAV-PVT, or GGA with the GST errors of its time (None: none)."""

    def publish_velocity(self, vel_enu: np.ndarray, cov_enu: np.ndarray, stamp: Stamp) -> None:
        """ENU velocity [m/s] with its covariance (3 x 3, m^2/s^2)."""

    def publish_ephemeris(self, eph, leap: int, stamp: Stamp) -> None:
        """A new or changed broadcast ephemeris, with GPST - UTC [s] at its time."""

    def publish_heading(self, heading: GnssHeading, stamp: Stamp) -> None:
        """A baseline heading of the receiver."""

    def publish_time_reference(self, stamp: Stamp, time_ref: Stamp, source: str) -> None:
        """GNSS time ``time_ref`` at sensor time ``stamp``; ``source`` "gnss" (an epoch) or
        "gnss_pps" (a time pulse)."""

    def navigation_data(self, ephemerides: int, rejected: int) -> None:
        """After every navigation data unit dated: ephemerides held, units rejected so far."""

    def report(self, what: str, warn: bool) -> None:
        """A record that gives no output although it could, and why (``warn`` False: a normal
        condition, such as a float baseline)."""


class ReceiverStream:
    """Turns one receiver's records, in stream order, into outputs.

    Parameters
    ----------
    outputs : ReceiverOutputs
        Takes the outputs as they arise.
    fix_source, heading_source : str
        Fixes and velocities from NAV-PVT ("ubx"), GGA/RMC ("nmea") or "auto"; headings from
        NAV-RELPOSNED ("ubx"), HDT ("nmea") or "auto" (:class:`RecordSources`).
    azimuth_offset, pitch_offset : float
        Mounting of the antenna baseline (:func:`.heading.receiver_heading`) [rad].
    hdt_std : float
        1-sigma accuracy assumed for HDT headings [rad].
    rmc_speed_std : float
        1-sigma horizontal velocity accuracy assumed for RMC [m/s].

    Notes
    -----
    NAV-RELPOSNED gives a heading only when relPosValid, relPosHeadingValid and carrSoln = fixed;
    its vertical accuracy (accD) is not decoded, so the pitch σ is taken as twice the horizontal
    cross-baseline one, as is typical of GNSS geometry.  Navigation data units that arrive
    before any GNSS time (up to ``MAX_EARLY_UNITS``) are dated by the first one.
    """

    def __init__(self, outputs: ReceiverOutputs, fix_source: str = "auto",
                 heading_source: str = "auto", azimuth_offset: float = 0.0,
                 pitch_offset: float = 0.0, hdt_std: float = math.radians(1.0),
                 rmc_speed_std: float = 0.5):
        self.out = outputs
        self.fix_source, self.heading_source = fix_source, heading_source
        self.azimuth_offset, self.pitch_offset = azimuth_offset, pitch_offset
        self.hdt_std, self.rmc_speed_std = hdt_std, rmc_speed_std
        self.time = ReceiverTime()
        self.sources = RecordSources()
        self.lock = LockTracker()
        self.assembler = NavDataAssembler()
        self.early_units: deque = deque(maxlen=MAX_EARLY_UNITS)
        self.gst: NmeaErrors | None = None
        self.last_stamp: Stamp | None = None   # of the latest epoch (stamps HDT headings)
        self._handlers = {RawEpoch: self._raw, PvtFix: self._pvt, NavSubframe: self._subframe,
                          RelPosNed: self._relposned, TimePulse: self._time_pulse,
                          NmeaFix: self._gga, NmeaRecommended: self._rmc,
                          NmeaErrors: self._gst, NmeaHeading: self._hdt}

    def add(self, record) -> None:
        """Put out what one decoded record gives (nothing for GSA, GSV, VTG)."""
        handler = self._handlers.get(type(record))
        if handler is not None:
            handler(record)

    # -- time -------------------------------------------------------------------------------
    def _advance(self, t_gps: float) -> None:
        """Advance the latest GNSS time; the first one dates the early navigation data."""
        first = self.time.advance(t_gps)
        while first and self.early_units:
            self._subframe(self.early_units.popleft())

    def _stamp(self, t_gps: float, tow: float | None = None) -> Stamp:
        """Stamp of a GNSS time [GPS s] (exact when the time of week ``tow`` is given)."""
        week, tow_of_t = week_tow(t_gps)
        self.last_stamp = Stamp(week, tow_of_t if tow is None else tow, self.time.leap(t_gps))
        return self.last_stamp

    def _nmea_stamp(self, utc: _dt.datetime) -> Stamp:
        self.last_stamp = Stamp(utc=utc)
        return self.last_stamp

    # -- UBX --------------------------------------------------------------------------------
    def _raw(self, raw: RawEpoch) -> None:
        if raw.leap_valid:
            self.time.receiver_leap = raw.leap_s
        self._advance(raw.t_gps)
        stamp = self._stamp(raw.t_gps, raw.tow)
        self.out.publish_observations(raw, self.lock.update(raw), stamp)
        if "TimePulse" not in self.sources.seen:
            self.out.publish_time_reference(stamp, stamp, "gnss")

    def _pvt(self, pvt: PvtFix) -> None:
        if not math.isfinite(pvt.t_gps):
            self.out.report("NAV-PVT without valid date/time: dropped", True)
            return
        self._advance(pvt.t_gps)
        if not self.sources.use("PvtFix", "PvtFix", self.fix_source):
            return
        stamp = self._stamp(pvt.t_gps)
        self.out.publish_fix(pvt, None, stamp)
        self.out.publish_velocity(pvt.vel_enu, np.diag([pvt.s_acc ** 2] * 3), stamp)

    def _subframe(self, unit: NavSubframe) -> None:
        t_gps = self.time.t_gps
        if t_gps is None:
            self.early_units.append(unit)
            return
        leap = self.time.leap(t_gps)
        for eph in self.assembler.add(unit, t_gps, leap):
            self.out.publish_ephemeris(eph, leap, self._stamp(t_gps))
        self.out.navigation_data(len(self.assembler.ephemerides),
                                 self.assembler.stats["rejected"])

    def _relposned(self, rel: RelPosNed) -> None:
        if not self.sources.use("RelPosNed", "RelPosNed", self.heading_source):
            return
        if self.time.t_gps is None:
            self.out.report("NAV-RELPOSNED before any GNSS time: dropped", True)
            return
        if not rel.heading_fixed:
            self.out.report("NAV-RELPOSNED not carrier-fixed: no heading", False)
            return
        t = time_of_week_near(rel.itow_s, self.time.t_gps)
        heading = receiver_heading(rel.azimuth, rel.acc_azimuth, self.azimuth_offset,
                                   rel.elevation, self.pitch_offset, 2.0 * rel.acc_azimuth,
                                   rel.length)
        self.out.publish_heading(heading, self._stamp(t))

    def _time_pulse(self, tp: TimePulse) -> None:
        self.sources.seen.add("TimePulse")
        # time base 1: UTC week and time of week, which count from the GPS epoch without leaps
        leap = 0 if tp.time_base == 1 else self.time.leap(gps_seconds(tp.week, tp.tow))
        self.out.publish_time_reference(Stamp(tp.week, tp.tow, leap),
                                        Stamp(tp.week, tp.tow + tp.q_err_s, leap), "gnss_pps")

    # -- NMEA -------------------------------------------------------------------------------
    def _rmc(self, rmc: NmeaRecommended) -> None:
        if rmc.utc is not None:
            self.time.utc_ref = rmc.utc
        if not self.sources.use("NmeaRecommended", "PvtFix", self.fix_source) or not rmc.valid \
                or rmc.utc is None:
            return
        if not math.isfinite(rmc.course):
            self.out.report("RMC without course: no velocity", False)
            return
        var_h = self.rmc_speed_std ** 2
        self.out.publish_velocity(rmc.vel_enu, np.diag([var_h, var_h, UNOBSERVED_VAR]),
                                  self._nmea_stamp(rmc.utc))

    def _gst(self, gst: NmeaErrors) -> None:
        self.gst = gst

    def _gga(self, gga: NmeaFix) -> None:
        if not self.sources.use("NmeaFix", "PvtFix", self.fix_source):
            return
        utc = self.time.utc(gga.utc_time)
        if utc is None:
            self.out.report("GGA without a known date: dropped", True)
            return
        if not math.isfinite(gga.geoid_sep):
            self.out.report("GGA without geoid separation (no ellipsoidal height): dropped",
                            True)
            return
        stamp = self._nmea_stamp(utc)
        self._advance(utc_to_gps(utc, self.time.receiver_leap))
        self.out.publish_fix(gga, errors_at(self.gst, utc), stamp)

    def _hdt(self, hdt: NmeaHeading) -> None:
        if not self.sources.use("NmeaHeading", "RelPosNed", self.heading_source):
            return
        if not math.isfinite(hdt.azimuth) or self.last_stamp is None:
            self.out.report("HDT without heading or epoch time: dropped", True)
            return
        self.out.publish_heading(
            receiver_heading(hdt.azimuth, self.hdt_std, self.azimuth_offset), self.last_stamp)


__all__ = ["GST_MAX_AGE_S", "MAX_EARLY_UNITS", "ReceiverOutputs", "ReceiverStream",
           "ReceiverTime", "RecordSources", "Stamp", "UNOBSERVED_VAR", "errors_at"]
