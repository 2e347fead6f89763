"""GNSS records (``gnss.observations``, broadcast ephemerides, headings) <-> ROS messages.

Records -> messages for ``gnss_driver``, ``gnss_simulator`` and ``phase_heading``; messages ->
records (:func:`raw_epoch_from_msg`, :func:`kepler_from_msg`) for the nodes that use raw observations (``phase_heading``, ``ekf`` in tight coupling).  Field
mapping only: time scales are :mod:`ins_gnss_ros.gnss.time`'s (a stamp is UTC as POSIX time),
accuracies and headings are computed in :mod:`ins_gnss_ros.gnss`.

Frames: ``gnss/fix`` and ``gnss/vel`` are the antenna's; the fix covariance and the velocity
are in ENU axes (NavSatFix defines its covariance as ENU; REP-103).
"""

from __future__ import annotations

import math

import numpy as np
from builtin_interfaces.msg import Time
from geometry_msgs.msg import TwistWithCovarianceStamped
from geometry_msgs.msg import Vector3
from ins_gnss_msgs.msg import GnssEphemeris, GnssObservations, Heading, PhaseDoubleDifferences
from sensor_msgs.msg import NavSatFix, NavSatStatus, TimeReference
from std_msgs.msg import Header

from ..gnss import (BDT_MINUS_GPST_S, BEIDOU, GALILEO, GLONASS, GPS, SECONDS_PER_WEEK,
                    SIGNAL_ID, SYSTEM_ID, UBX_GNSS_ID, UBX_SIGNALS, FixedDoubleDifferences,
                    GlonassEphemeris, GnssHeading,
                    KeplerEphemeris, NmeaErrors, NmeaFix, PvtFix, RawEpoch, SatObs, Stamp,
                    accuracy_m, glonass_time_of_day, gps_to_posix_ns, system_week,
                    time_of_week_near, utc_to_posix)
from ..io import sec_to_stamp

#: System -> NavSatStatus service bit.
_SERVICE = {GPS: NavSatStatus.SERVICE_GPS, GLONASS: NavSatStatus.SERVICE_GLONASS,
            BEIDOU: NavSatStatus.SERVICE_COMPASS, GALILEO: NavSatStatus.SERVICE_GALILEO}
#: GnssHeading status -> Heading status.
_HEADING_STATUS = {"FIXED": Heading.STATUS_FIXED, "FLOAT": Heading.STATUS_FLOAT,
                   "NONE": Heading.STATUS_NONE}


def gps_stamp(week: int, tow: float, leap_s: int) -> Time:
    """ROS stamp (UTC POSIX) of a GPS week and time of week [s], with GPST - UTC = ``leap_s``,
    to the nanosecond (:func:`~ins_gnss_ros.gnss.time.gps_to_posix_ns`)."""
    sec, nanosec = gps_to_posix_ns(week, tow, leap_s)
    return Time(sec=sec, nanosec=nanosec)


def stamp_msg(stamp: Stamp) -> Time:
    """ROS stamp of a receiver output's :class:`~ins_gnss_ros.gnss.receiver.Stamp`."""
    if stamp.utc is not None:
        return sec_to_stamp(utc_to_posix(stamp.utc))
    return gps_stamp(stamp.week, stamp.tow, stamp.leap)


def service_bits(systems) -> int:
    """NavSatStatus service flags of the systems (RINEX letters) a solution uses."""
    return sum({_SERVICE[s] for s in systems if s in _SERVICE})


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
        week, toe = system_week(eph.toe, GPS)
        tb = glonass_time_of_day(eph.toe, leap_s)
        return GnssEphemeris(
            header=header, system=SYSTEM_ID[GLONASS], prn=eph.prn, week=week,
            iode=int(round(tb / 900.0)), iodc=int(round(tb / 900.0)), health=eph.health,
            ura=math.nan, toe=toe, toc=toe, frequency_slot=eph.freq_slot, tb=tb,
            position=[float(v) for v in eph.pos], velocity=[float(v) for v in eph.vel],
            acceleration=[float(v) for v in eph.acc], tau_n=eph.tau_n, gamma_n=eph.gamma_n)
    week, toe = system_week(eph.toe, eph.system)
    _, toc = system_week(eph.toc, eph.system)
    return GnssEphemeris(
        header=header, system=SYSTEM_ID[eph.system], prn=eph.prn, week=week,
        iode=int(eph.iode), iodc=int(eph.iode), health=int(eph.health),
        ura=accuracy_m(eph.system, eph.accuracy_index), toe=toe, toc=toc, af0=eph.af0,
        af1=eph.af1, af2=eph.af2, tgd=eph.tgd, sqrt_a=eph.sqrt_a, eccentricity=eph.e,
        i0=eph.i0, omega0=eph.omega0, omega=eph.omega, m0=eph.m0, delta_n=eph.delta_n,
        idot=eph.idot, omega_dot=eph.omega_dot, cuc=eph.cuc, cus=eph.cus, crc=eph.crc,
        crs=eph.crs, cic=eph.cic, cis=eph.cis)


def fix_msg(stamp: Time, frame_id: str, lat: float, lon: float, h: float, status: int,
            service: int, cov_enu, cov_type: int) -> NavSatFix:
    """NavSatFix of a position (lat, lon [rad], ellipsoidal h [m]) with its ENU covariance
    (3 x 3, m^2) of NavSatFix covariance type ``cov_type``."""
    msg = NavSatFix(header=Header(stamp=stamp, frame_id=frame_id), latitude=math.degrees(lat),
                    longitude=math.degrees(lon), altitude=float(h))
    msg.status = NavSatStatus(status=status, service=service)
    msg.position_covariance = [float(v) for v in np.asarray(cov_enu).ravel()]
    msg.position_covariance_type = cov_type
    return msg


def fix_from_pvt(pvt: PvtFix, stamp: Time, frame_id: str, service: int) -> NavSatFix:
    """NavSatFix of a NAV-PVT solution: ellipsoidal height; status NO_FIX unless the receiver
    flags gnssFixOK with a 2D/3D(/+DR) fix, GBAS_FIX for an RTK fixed solution (carrSoln 2),
    SBAS_FIX for an RTK float one (carrSoln 1: NavSatStatus has no float state, and a float
    solution is an augmented one that has not reached carrier-phase accuracy);
    covariance diagonal from hAcc (east and north each) and vAcc, as u-blox's accuracy
    estimates are not split by axis."""
    if not pvt.gnss_fix_ok or pvt.fix_type not in (2, 3, 4):
        status = NavSatStatus.STATUS_NO_FIX
    elif pvt.carr_soln == 2:
        status = NavSatStatus.STATUS_GBAS_FIX
    elif pvt.carr_soln == 1:
        status = NavSatStatus.STATUS_SBAS_FIX
    else:
        status = NavSatStatus.STATUS_FIX
    return fix_msg(stamp, frame_id, pvt.lat, pvt.lon, pvt.h, status, service,
                   np.diag([pvt.h_acc ** 2, pvt.h_acc ** 2, pvt.v_acc ** 2]),
                   NavSatFix.COVARIANCE_TYPE_DIAGONAL_KNOWN)


#: GGA quality indicator -> NavSatStatus (0 invalid, 1 GPS, 2 DGPS, 3 PPS, 4 RTK fixed,
#: 5 RTK float, 6 dead reckoning, 7 manual, 8 simulator: NMEA 0183 v4.11). GBAS_FIX is RTK
#: fixed only; float is an augmented fix (SBAS_FIX), as in :func:`fix_from_pvt`.
_GGA_STATUS = {1: NavSatStatus.STATUS_FIX, 2: NavSatStatus.STATUS_SBAS_FIX,
               3: NavSatStatus.STATUS_FIX, 4: NavSatStatus.STATUS_GBAS_FIX,
               5: NavSatStatus.STATUS_SBAS_FIX}


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
    return fix_msg(stamp, frame_id, gga.lat, gga.lon, gga.h_msl + gga.geoid_sep,
                   _GGA_STATUS.get(gga.quality, NavSatStatus.STATUS_NO_FIX), service,
                   np.diag(cov), kind)


def twist_msg(vel_enu, cov_enu, stamp: Time, frame_id: str) -> TwistWithCovarianceStamped:
    """Linear velocity ENU [m/s] with its covariance (3 x 3, m^2/s^2); the angular rate is not
    measured (its variances are -1)."""
    msg = TwistWithCovarianceStamped(header=Header(stamp=stamp, frame_id=frame_id))
    lin = msg.twist.twist.linear
    lin.x, lin.y, lin.z = (float(v) for v in vel_enu)
    cov = np.zeros((6, 6))
    cov[:3, :3] = cov_enu
    cov[3, 3] = cov[4, 4] = cov[5, 5] = -1.0
    msg.twist.covariance = [float(v) for v in cov.ravel()]
    return msg


def heading_msg(h: GnssHeading, stamp: Time, frame_id: str, source: int) -> Heading:
    """ins_gnss_msgs/Heading (reference TRUE, ``source`` a Heading.SOURCE_*) of a heading."""
    return Heading(
        header=Header(stamp=stamp, frame_id=frame_id), azimuth=h.azimuth, pitch=h.pitch,
        roll=h.roll, azimuth_variance=h.var_azimuth, pitch_variance=h.var_pitch,
        roll_variance=h.var_roll, reference=Heading.REFERENCE_TRUE, source=source,
        declination=0.0, baseline_length=h.baseline_length, satellites_used=h.satellites,
        ambiguity_ratio=h.ratio, status=_HEADING_STATUS[h.status])


def phase_dd_msg(dds: FixedDoubleDifferences, ratio: float, stamp: Time,
                 frame_id: str) -> PhaseDoubleDifferences:
    """ins_gnss_msgs/PhaseDoubleDifferences of an epoch's fixed double differences (every row
    from the master antenna 0, status FIXED)."""
    n = len(dds.value)
    return PhaseDoubleDifferences(
        header=Header(stamp=stamp, frame_id=frame_id), master_antenna=[0] * n,
        remote_antenna=dds.remote.tolist(),
        baseline=[Vector3(x=x, y=y, z=z) for x, y, z in dds.baseline_b.tolist()],
        satellite=[s for s, _ in dds.pairs], reference_satellite=[r for _, r in dds.pairs],
        wavelength=dds.wavelength.tolist(), value=dds.value.tolist(),
        line_of_sight_difference=[Vector3(x=x, y=y, z=z) for x, y, z in dds.geometry.tolist()],
        ambiguity_status=[PhaseDoubleDifferences.AMBIGUITY_FIXED] * n,
        covariance=dds.cov.ravel().tolist(), ambiguity_ratio=float(ratio))


def time_reference_msg(stamp: Time, time_ref: Time, frame_id: str, source: str) -> TimeReference:
    """sensor_msgs/TimeReference: GNSS time ``time_ref`` (as UTC) at sensor time ``stamp``."""
    return TimeReference(header=Header(stamp=stamp, frame_id=frame_id), time_ref=time_ref,
                         source=source)


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


def kepler_msg_plausible(msg: GnssEphemeris) -> bool:
    """Whether a GnssEphemeris holds a usable Keplerian orbit: finite times and elements, a
    semi-major axis of at least 1000 km and an elliptic eccentricity."""
    values = [msg.toe, msg.toc, msg.sqrt_a, msg.eccentricity, msg.m0, msg.omega0, msg.i0,
              msg.omega, msg.af0]
    return all(math.isfinite(v) for v in values) and msg.sqrt_a >= 1000.0 \
        and 0.0 <= msg.eccentricity < 1.0


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
