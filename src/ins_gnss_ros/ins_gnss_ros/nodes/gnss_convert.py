"""GNSS records (``gnss.observations``, broadcast ephemerides) <-> ROS messages.

Records -> messages for ``gnss_driver`` and ``gnss_simulator``; messages -> records
(:func:`raw_epoch_from_msg`, :func:`kepler_from_msg`) for the nodes that use raw observations
(``phase_heading``, ``ekf`` in tight coupling).

Time axis (one convention for the whole project): a ROS stamp is UTC as POSIX time, derived
from GPS time with the receiver's leap seconds, ``stamp = t_gps + 315964800 - leap_s``
(315964800 s = 1980-01-06 00:00:00 UTC in POSIX time; POSIX time ignores leap seconds, so
GPST - UTC is subtracted once).  NMEA times are UTC already and map directly.

Frames: ``gnss/fix`` and ``gnss/vel`` are the antenna's; the fix covariance and the velocity
are in ENU axes (NavSatFix defines its covariance as ENU; REP-103).
"""

from __future__ import annotations

import datetime as _dt
import math

import numpy as np
from builtin_interfaces.msg import Time
from geometry_msgs.msg import TwistWithCovarianceStamped
from ins_gnss_msgs.msg import GnssEphemeris, GnssObservations, Heading
from sensor_msgs.msg import NavSatFix, NavSatStatus
from std_msgs.msg import Header

from ..gnss.constants import (BEIDOU, GALILEO, GLONASS, GPS, SECONDS_PER_WEEK, UBX_GNSS_ID,
                              UBX_SIGNALS)
from ..gnss.ephemeris import KeplerEphemeris
from ..gnss.glonass import GlonassEphemeris
from ..gnss.observations import (NmeaErrors, NmeaFix, NmeaRecommended, PvtFix, RawEpoch,
                                 RelPosNed, SatObs)
from ..gnss.time import (BDT_MINUS_GPST_S, BDT_WEEK_OFFSET, GLONASS_MINUS_UTC_S,
                         GST_WEEK_OFFSET, time_of_week_near, utc_to_gps)
from ..nav.conventions import wrap_2pi

#: POSIX time of the GPS epoch 1980-01-06 00:00:00 UTC [s].
GPS_EPOCH_POSIX = 315964800.0
_POSIX_EPOCH = _dt.datetime(1970, 1, 1)
#: RINEX system letter -> u-blox gnssId (GnssObservations.SYSTEM_*).
SYSTEM_ID = {letter: gnss_id for gnss_id, letter in UBX_GNSS_ID.items()}
#: (system letter, RINEX signal code) -> u-blox sigId. Where u-blox has two ids for one code
#: (BeiDou B1I/B2I/B3I D1 and D2), the lower (D1) id is used.
SIGNAL_ID = {(UBX_GNSS_ID[gid], code): sid  # descending: the lowest sigId is written last
             for (gid, sid), (code, _) in sorted(UBX_SIGNALS.items(), reverse=True)}
#: GPS/BeiDou URA index -> metres (IS-GPS-200 §20.3.3.3.1.3 upper bounds; BDS-SIS-ICD-B1I
#: §5.2.4.5 uses the same table).
_URA_M = (2.4, 3.4, 4.85, 6.85, 9.65, 13.65, 24.0, 48.0, 96.0, 192.0, 384.0, 768.0, 1536.0,
          3072.0, 6144.0)
#: Baselines within this angle of the body x axis (either direction) give pitch.
FORE_AFT_TOLERANCE = math.radians(15.0)


def gps_to_posix(t_gps: float, leap_s: int) -> float:
    """POSIX (UTC) seconds of a GPS time [s since the GPS epoch], with GPST - UTC = ``leap_s``."""
    return t_gps + GPS_EPOCH_POSIX - leap_s


def gps_stamp(week: int, tow: float, leap_s: int) -> Time:
    """ROS stamp (UTC POSIX) of a GPS week and time of week [s], with GPST - UTC = ``leap_s``.

    Whole seconds are added as integers so that the receiver's time tag keeps its nanoseconds
    (a float of POSIX seconds would resolve only 0.24 us).  ``leap_s = 0`` converts a UTC week
    and time of week (u-blox TIM-TP in the UTC time base).
    """
    whole = math.floor(tow)
    nanosec = round((tow - whole) * 1e9)
    if nanosec >= 1_000_000_000:  # rounding carried into the next second
        whole, nanosec = whole + 1, nanosec - 1_000_000_000
    return Time(sec=int(GPS_EPOCH_POSIX) + int(week) * int(SECONDS_PER_WEEK) + int(whole) - leap_s,
                nanosec=int(nanosec))


def utc_to_posix(utc: _dt.datetime) -> float:
    """POSIX seconds of a naive UTC datetime."""
    return (utc - _POSIX_EPOCH).total_seconds()


def utc_near(time_of_day: _dt.time, ref: _dt.datetime) -> _dt.datetime:
    """The UTC datetime with this time of day closest to ``ref`` (dates an NMEA GGA time,
    across midnight too)."""
    candidate = _dt.datetime.combine(ref.date(), time_of_day)
    shift = round((ref - candidate).total_seconds() / 86400.0)
    return candidate + _dt.timedelta(days=shift)


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


def stream_time(record) -> float | None:
    """GPS time [s] a record is tagged with, for replay pacing; None for untimed records."""
    if isinstance(record, RawEpoch):
        return record.t_gps
    if isinstance(record, PvtFix) and math.isfinite(record.t_gps):
        return record.t_gps
    if isinstance(record, NmeaRecommended) and record.utc is not None:
        return utc_to_gps(record.utc)
    return None


class LockTracker:
    """Per-signal carrier-phase continuity from the receiver's lock time and half-cycle flag.

    A signal is flagged ``loss_of_lock`` (cycle slip possible since its previous epoch) when
    the receiver clock was reset, the signal was not tracked at the previous epoch, its lock
    time is shorter than the time since that epoch (the phase loop re-locked in between), or
    its phase became usable only now (half-cycle ambiguity just resolved: u-blox may subtract
    half a cycle at that moment, RXM-RAWX trkStat).
    """

    def __init__(self):
        self._prev: dict[tuple, tuple[float, bool]] = {}  # key -> (t_gps, phase usable)

    def update(self, raw: RawEpoch) -> list[bool]:
        """Loss-of-lock flags of ``raw.obs`` (and remember this epoch)."""
        flags, current = [], {}
        for o in raw.obs:
            key = (o.system, o.prn, o.signal)
            usable = math.isfinite(o.carrier_cycles) and o.half_cycle_valid
            prev = self._prev.get(key)
            if raw.clock_reset or prev is None:
                flags.append(True)
            else:
                elapsed_ms = (raw.t_gps - prev[0]) * 1000.0
                flags.append(o.lock_ms < elapsed_ms or (usable and not prev[1]))
            current[key] = (raw.t_gps, usable)
        self._prev = current
        return flags


def observations_msg(raw: RawEpoch, antenna_id: int, stamp: Time, frame_id: str,
                     loss_of_lock: list[bool]) -> GnssObservations:
    """GnssObservations of one RXM-RAWX epoch.

    Carrier phase is NaN unless the receiver marks it valid and its half-cycle ambiguity
    resolved (GnssObservations has no half-cycle flag); pseudorange NaN when invalid.
    Galileo/BeiDou time tags are the receiver's GPS week and time of week.
    """
    msg = GnssObservations(header=Header(stamp=stamp, frame_id=frame_id), antenna_id=antenna_id,
                           gps_week=raw.week, time_of_week=float(raw.tow),
                           leap_seconds=raw.leap_s if raw.leap_valid else -128,
                           clock_reset=raw.clock_reset)
    obs = raw.obs
    msg.system = [SYSTEM_ID[o.system] for o in obs]
    msg.prn = [o.prn for o in obs]
    msg.frequency_slot = [o.freq_slot for o in obs]
    msg.signal = [SIGNAL_ID[(o.system, o.signal)] for o in obs]
    msg.pseudorange = [float(o.pseudorange_m) for o in obs]
    msg.doppler = [float(o.doppler_hz) for o in obs]
    msg.carrier_phase = [float(o.carrier_cycles) if o.half_cycle_valid else math.nan for o in obs]
    msg.cn0 = [float(o.cn0_dbhz) for o in obs]
    msg.lock_time = [o.lock_ms / 1000.0 for o in obs]
    msg.loss_of_lock = [bool(f) for f in loss_of_lock]
    msg.pseudorange_std = [float(o.pr_std_m) for o in obs]
    msg.carrier_phase_std = [float(o.cp_std_cycles) for o in obs]
    return msg


def _week_sow(t_gps: float, system: str) -> tuple[int, float]:
    """Week number and seconds of week of a GPS time in ``system``'s own time scale."""
    if system == BEIDOU:  # BDT = GPST - 14 s, week counted from 2006-01-01 (BDS ICD §3.3)
        week, sow = divmod(t_gps + BDT_MINUS_GPST_S, SECONDS_PER_WEEK)
        return int(week) - BDT_WEEK_OFFSET, sow
    week, sow = divmod(t_gps, SECONDS_PER_WEEK)
    return int(week) - (GST_WEEK_OFFSET if system == GALILEO else 0), sow


def ephemeris_msg(eph: KeplerEphemeris | GlonassEphemeris, stamp: Time,
                  leap_s: int) -> GnssEphemeris:
    """GnssEphemeris of a decoded broadcast ephemeris.

    Keplerian sets (GPS, Galileo, BeiDou, QZSS): week, toe and toc in the system's own week
    numbering and time scale; ``iodc`` repeats the issue of data (the decoder keeps one);
    ``tgd`` is the group delay of the signal the clock is broadcast on: GPS T_GD, Galileo
    I/NAV BGD(E1, E5b), BeiDou TGD1.  GLONASS: ``tb`` in seconds of the GLONASS day,
    ``week``/``toe`` the GPS week and time of week of tb, ``iode`` = tb / 900 s (the 15-min
    index of tb), ``ura`` NaN (F_T not decoded).
    """
    header = Header(stamp=stamp, frame_id="earth")
    if isinstance(eph, GlonassEphemeris):
        week, toe = _week_sow(eph.toe, GPS)
        tb = (eph.toe - leap_s + GLONASS_MINUS_UTC_S) % 86400.0
        return GnssEphemeris(
            header=header, system=SYSTEM_ID[GLONASS], prn=eph.prn, week=week,
            iode=int(round(tb / 900.0)), iodc=int(round(tb / 900.0)), health=eph.health,
            ura=math.nan, toe=toe, toc=toe, frequency_slot=eph.freq_slot, tb=tb,
            position=[float(v) for v in eph.pos], velocity=[float(v) for v in eph.vel],
            acceleration=[float(v) for v in eph.acc], tau_n=eph.tau_n, gamma_n=eph.gamma_n)
    week, toe = _week_sow(eph.toe, eph.system)
    _, toc = _week_sow(eph.toc, eph.system)
    return GnssEphemeris(
        header=header, system=SYSTEM_ID[eph.system], prn=eph.prn, week=week,
        iode=int(eph.iode), iodc=int(eph.iode), health=int(eph.health),
        ura=accuracy_m(eph.system, eph.accuracy_index), toe=toe, toc=toc, af0=eph.af0,
        af1=eph.af1, af2=eph.af2, tgd=eph.tgd, sqrt_a=eph.sqrt_a, eccentricity=eph.e,
        i0=eph.i0, omega0=eph.omega0, omega=eph.omega, m0=eph.m0, delta_n=eph.delta_n,
        idot=eph.idot, omega_dot=eph.omega_dot, cuc=eph.cuc, cus=eph.cus, crc=eph.crc,
        crs=eph.crs, cic=eph.cic, cis=eph.cis)


def _fix(stamp: Time, frame_id: str, lat: float, lon: float, h: float, status: int,
         service: int, cov_enu, cov_type: int) -> NavSatFix:
    msg = NavSatFix(header=Header(stamp=stamp, frame_id=frame_id), latitude=math.degrees(lat),
                    longitude=math.degrees(lon), altitude=float(h))
    msg.status = NavSatStatus(status=status, service=service)
    msg.position_covariance = [float(v) for v in np.diag(cov_enu).ravel()]
    msg.position_covariance_type = cov_type
    return msg


def fix_from_pvt(pvt: PvtFix, stamp: Time, frame_id: str, service: int) -> NavSatFix:
    """NavSatFix of a NAV-PVT solution: ellipsoidal height; status NO_FIX unless the receiver
    flags gnssFixOK with a 2D/3D(/+DR) fix, GBAS_FIX for an RTK float or fixed solution;
    covariance diagonal from hAcc (east and north each) and vAcc, as u-blox's accuracy
    estimates are not split by axis."""
    if not pvt.gnss_fix_ok or pvt.fix_type not in (2, 3, 4):
        status = NavSatStatus.STATUS_NO_FIX
    elif pvt.carr_soln > 0:
        status = NavSatStatus.STATUS_GBAS_FIX
    else:
        status = NavSatStatus.STATUS_FIX
    return _fix(stamp, frame_id, pvt.lat, pvt.lon, pvt.h, status, service,
                [pvt.h_acc ** 2, pvt.h_acc ** 2, pvt.v_acc ** 2],
                NavSatFix.COVARIANCE_TYPE_DIAGONAL_KNOWN)


#: GGA quality indicator -> NavSatStatus (0 invalid, 1 GPS, 2 DGPS, 3 PPS, 4 RTK fixed,
#: 5 RTK float, 6 dead reckoning, 7 manual, 8 simulator: NMEA 0183 v4.11).
_GGA_STATUS = {1: NavSatStatus.STATUS_FIX, 2: NavSatStatus.STATUS_SBAS_FIX,
               3: NavSatStatus.STATUS_FIX, 4: NavSatStatus.STATUS_GBAS_FIX,
               5: NavSatStatus.STATUS_GBAS_FIX}


def fix_from_gga(gga: NmeaFix, errors: NmeaErrors | None, stamp: Time, frame_id: str,
                 service: int, uere_m: float) -> NavSatFix:
    """NavSatFix of an NMEA GGA fix (altitude = MSL height + geoid separation, ellipsoidal).

    Covariance from a GST sentence when given (1-sigma latitude/longitude/altitude errors,
    DIAGONAL_KNOWN), else approximated as (HDOP uere_m)^2 horizontally and twice that sigma
    vertically (APPROXIMATED).
    """
    if errors is not None and all(map(math.isfinite, (errors.std_lat, errors.std_lon,
                                                      errors.std_alt))):
        cov, kind = ([errors.std_lon ** 2, errors.std_lat ** 2, errors.std_alt ** 2],
                     NavSatFix.COVARIANCE_TYPE_DIAGONAL_KNOWN)
    else:
        sigma_h = gga.hdop * uere_m
        cov, kind = ([sigma_h ** 2, sigma_h ** 2, (2 * sigma_h) ** 2],
                     NavSatFix.COVARIANCE_TYPE_APPROXIMATED)
    return _fix(stamp, frame_id, gga.lat, gga.lon, gga.h_msl + gga.geoid_sep,
                _GGA_STATUS.get(gga.quality, NavSatStatus.STATUS_NO_FIX), service, cov, kind)


def twist_msg(vel_enu, var_enu, stamp: Time, frame_id: str) -> TwistWithCovarianceStamped:
    """Linear velocity ENU [m/s] with its diagonal variances [m^2/s^2]; the angular rate is not
    measured (its variances are -1)."""
    msg = TwistWithCovarianceStamped(header=Header(stamp=stamp, frame_id=frame_id))
    lin = msg.twist.twist.linear
    lin.x, lin.y, lin.z = (float(v) for v in vel_enu)
    cov = np.zeros((6, 6))
    cov[:3, :3] = np.diag(var_enu)
    cov[3, 3] = cov[4, 4] = cov[5, 5] = -1.0
    msg.twist.covariance = [float(v) for v in cov.ravel()]
    return msg


def heading_msg(baseline_azimuth: float, azimuth_std: float, stamp: Time, frame_id: str,
                azimuth_offset: float, elevation: float = math.nan, elevation_offset: float = 0.0,
                pitch_std: float = math.nan, baseline_length: float = math.nan) -> Heading:
    """Heading (source RECEIVER, reference TRUE, status FIXED) of an antenna baseline.

    Parameters
    ----------
    baseline_azimuth : float
        Azimuth of the baseline (primary -> secondary antenna), clockwise from true north [rad].
    azimuth_std, pitch_std : float
        1-sigma accuracies [rad].
    azimuth_offset, elevation_offset : float
        Mounting: the baseline's azimuth in the body frame (clockwise from body x, i.e.
        towards starboard) and its elevation above the body x-y plane [rad].
    elevation : float
        Elevation of the baseline above the horizon [rad] (NaN: not observed).

    Notes
    -----
    Body azimuth = baseline azimuth - azimuth offset.  Pitch (nose up) is observable from one
    baseline only along the body x axis: for a baseline within ``FORE_AFT_TOLERANCE`` of it,
    pitch = +-(elevation - elevation offset) (sign of cos(azimuth offset)), the roll then
    leaking in by sin(azimuth offset); otherwise NaN.
    """
    fore_aft = abs(math.sin(azimuth_offset)) <= math.sin(FORE_AFT_TOLERANCE)
    pitch = math.copysign(1.0, math.cos(azimuth_offset)) * (elevation - elevation_offset) \
        if fore_aft else math.nan
    return Heading(
        header=Header(stamp=stamp, frame_id=frame_id),
        azimuth=float(wrap_2pi(baseline_azimuth - azimuth_offset)), pitch=pitch,
        roll=math.nan, azimuth_variance=azimuth_std ** 2,
        pitch_variance=pitch_std ** 2 if math.isfinite(pitch) else math.nan,
        roll_variance=math.nan, reference=Heading.REFERENCE_TRUE,
        source=Heading.SOURCE_RECEIVER, baseline_length=float(baseline_length),
        ambiguity_ratio=math.nan, status=Heading.STATUS_FIXED)


def relposned_elevation(rel: RelPosNed) -> float:
    """Elevation of a NAV-RELPOSNED baseline above the horizon [rad] (up = -down)."""
    n, e, d = rel.rel_pos_ned
    return math.atan2(-d, math.hypot(n, e))


def rmc_velocity(rmc: NmeaRecommended) -> np.ndarray:
    """ENU velocity [m/s] from RMC speed and course over ground (clockwise from true north);
    the vertical is not reported (0)."""
    return np.array([rmc.speed_mps * math.sin(rmc.course), rmc.speed_mps * math.cos(rmc.course),
                     0.0])


# -- messages -> records ---------------------------------------------------------------------
def _optional(values, i: int) -> float:
    """Element i of an optional per-signal array (the std arrays may be left empty): NaN if absent."""
    return float(values[i]) if i < len(values) else math.nan


def raw_epoch_from_msg(msg: GnssObservations, systems) -> tuple[RawEpoch, list[int]] | None:
    """The RawEpoch of the signals of ``systems`` (letters) in a GnssObservations, and the message
    indices they came from; None if the message's arrays have unequal lengths.

    Signals with an unknown (gnssId, sigId) are left out, as are repeated signals and BeiDou GEO
    satellites (PRN 1-5, 59-63: their orbit needs a rotation the ephemeris module lacks).
    """
    n = len(msg.system)
    arrays = (msg.prn, msg.frequency_slot, msg.signal, msg.pseudorange, msg.doppler,
              msg.carrier_phase, msg.cn0, msg.lock_time, msg.loss_of_lock)
    if any(len(a) != n for a in arrays):
        return None
    obs, kept, seen = [], [], set()
    for i in range(n):
        system = UBX_GNSS_ID.get(int(msg.system[i]))
        sig = UBX_SIGNALS.get((int(msg.system[i]), int(msg.signal[i])))
        prn = int(msg.prn[i])
        if system not in systems or sig is None or (system, prn, sig[0]) in seen:
            continue
        if system == BEIDOU and (prn <= 5 or prn >= 59):
            continue
        seen.add((system, prn, sig[0]))
        kept.append(i)
        obs.append(SatObs(system, prn, int(msg.frequency_slot[i]), sig[0], sig[1],
                          float(msg.pseudorange[i]), float(msg.doppler[i]),
                          float(msg.carrier_phase[i]), float(msg.cn0[i]),
                          1000.0 * float(msg.lock_time[i]), _optional(msg.pseudorange_std, i),
                          _optional(msg.carrier_phase_std, i), math.nan, True, False))
    raw = RawEpoch(int(msg.gps_week), float(msg.time_of_week), int(msg.leap_seconds),
                   msg.leap_seconds != -128, bool(msg.clock_reset), obs)
    return raw, kept


def kepler_from_msg(msg: GnssEphemeris, t_gps: float) -> KeplerEphemeris:
    """KeplerEphemeris of a GnssEphemeris, toe and toc resolved within half a week of ``t_gps``.

    Only the seconds of week are used: the week field is numbered per system (GST, BDT weeks)
    and modulo 1024 or 8192 depending on the source, while a broadcast ephemeris in use is
    always within hours of the epoch (IS-GPS-200 §20.3.3.4.3 resolves it the same way).
    """
    system = UBX_GNSS_ID[int(msg.system)]
    # BeiDou broadcasts BDT seconds of week; KeplerEphemeris keeps GPS seconds.
    shift = -BDT_MINUS_GPST_S if system == BEIDOU else 0.0
    toe = time_of_week_near((msg.toe + shift) % SECONDS_PER_WEEK, t_gps)
    toc = time_of_week_near((msg.toc + shift) % SECONDS_PER_WEEK, toe)
    return KeplerEphemeris(
        system=system, prn=int(msg.prn), toe=toe, toc=toc, sqrt_a=msg.sqrt_a,
        e=msg.eccentricity, m0=msg.m0, delta_n=msg.delta_n, omega0=msg.omega0, i0=msg.i0,
        omega=msg.omega, idot=msg.idot, omega_dot=msg.omega_dot, cuc=msg.cuc, cus=msg.cus,
        crc=msg.crc, crs=msg.crs, cic=msg.cic, cis=msg.cis, af0=msg.af0, af1=msg.af1,
        af2=msg.af2, tgd=msg.tgd, bgd_e5a=0.0, iode=int(msg.iode), health=int(msg.health),
        accuracy_index=0)

