"""Tight-coupling measurements: per-satellite pseudoranges and range rates for the navigator,
from one raw receiver epoch, the broadcast ephemerides and the current INS solution.

The navigator (:func:`ins_gnss_ros.nav.measurements.pseudoranges` and
:func:`~ins_gnss_ros.nav.measurements.range_rates`) predicts

    P_pred    = |r^i - r_a| + c dt_r - c dt^i                                        [m]
    Pdot_pred = u . (v^i - v_a) + c dt_r' - c dt^i'                                  [m/s]

with r^i, v^i the satellite at transmission expressed in the ECEF frame of the reception
instant, r_a, v_a the antenna from the INS, u the unit line of sight antenna -> satellite,
dt_r, dt_r' the receiver clock states. This module brings the measurements to that model
(code observation model of seed 004 section 2.4; Groves, "Principles of GNSS, Inertial and
Multisensor Integrated Navigation", 2nd ed., sections 8.5.3 and 9.4.1):

* Satellite state at transmission: transmission time in satellite time t_rx - P/c (exact: the
  receiver clock cancels), then system time through the broadcast clock, orbit and clock of
  IS-GPS-200 Table 20-IV (Galileo OS SIS ICD 5.1.1, GLONASS ICD A.3.1.2), rotated into the ECEF
  frame of reception by the geometric flight time from the INS antenna (Sagnac, Groves eq.
  8.36): :func:`ins_gnss_ros.gnss.ephemeris.satellite_at_reception`.
* Satellite clock c dt^i: broadcast polynomial with the relativistic term F e sqrt(A) sin E
  (IS-GPS-200 20.3.3.3.3.1) minus the group delay of the tracked signal (T_GD, Galileo BGD:
  20.3.3.3.3.2 and OS SIS ICD 5.1.5), since P = rho + c dt_r - c (dt^i - T_GD) + I + T.
* Atmosphere removed from the pseudorange: Klobuchar ionosphere when coefficients are known
  (IS-GPS-200 20.3.3.5.2.5), Saastamoinen troposphere (:mod:`ins_gnss_ros.gnss.atmosphere`), at
  the elevation and azimuth seen from the INS antenna.
* Range rate = -wavelength x Doppler (the receiver's sign: positive Doppler for an approaching
  satellite, i.e. a shrinking range). The Doppler measures the rate of the carrier phase,
  whose atmospheric terms are -I + T: their rates are removed (central differences of the
  models with the satellite moved along its velocity). The Doppler is the derivative of the
  light-time range rho(t) = |R(w tau) r^i(t - tau) - r_a(t)|, tau = rho / c; differentiating,
  rho' (1 + k) = u . (v^i - v_a) with k = u . (v^i - w_e [y, -x, 0]^i) / c (the transmission
  time moves with the range, and so does the Sagnac rotation). The navigator's model is the
  right-hand side, so k rho' (with rho' from the INS, k ~ 1e-5) is added to the measured rate:
  up to 1 cm/s, more than the Doppler noise.
* Elevation mask from the INS antenna position, the variances of the elevation model
  sigma^2 = a^2 + b^2 / sin^2 E (:func:`ins_gnss_ros.gnss.differences.elevation_sigma`), one
  signal per system, healthy satellites with an ephemeris inside its fit interval, and at most
  `max_satellites` of them (the highest).

The navigator carries ONE receiver clock: the default systems, GPS L1 C/A and Galileo E1, share
the GPS time scale (the GPS-Galileo time offset of a few ns is ignored, :mod:`.time`). GLONASS or
BeiDou can be selected through :attr:`RangeConfig.signals`, but mixed with GPS their inter-system
time offset would enter the pseudoranges unmodelled: use them alone.

Entry point for the ``ekf`` node: :func:`satellite_ranges` (RawEpoch + dict of ephemerides +
the navigator's state at the epoch ->
:class:`~ins_gnss_ros.nav.measurement_types.SatelliteRanges`).
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from ..nav.earth import ecef_to_enu_matrix, geodetic_to_ecef
from ..nav.lever_arm import lever_arm_position
from ..nav.measurement_types import SatelliteRanges
from .atmosphere import klobuchar_delay, tropo_delay
from .constants import C_LIGHT, FIT_HALF_WIDTH_S, GALILEO, GPS, OMEGA_E
from .differences import elevation_sigma
from .ephemeris import elevation_azimuth, group_delay, satellite_at_reception
from .glonass import GlonassEphemeris
from .time import wrap_week_difference

#: Largest |t - tb| of a GLONASS ephemeris [s]: the ICD integrates within +-15 min of tb (new
#: data every 30 min); twice that tolerates one missed update.
GLONASS_MAX_AGE = 1800.0
#: Half-step of the central differences giving the atmospheric delay rates [s].
_RATE_STEP = 0.5


@dataclass(frozen=True)
class RangeConfig:
    """Selection and noise settings of the tight-coupling measurements (SI, radians).

    Attributes
    ----------
    signals : dict of str to str
        System letter -> RINEX observation code of the one signal used; other systems are
        skipped. Default GPS L1 C/A and Galileo E1-C (one clock, see the module docstring).
    elevation_mask : float
        Satellites below it, seen from the INS antenna, are not used [rad].
    code_sigma : (float, float)
        Pseudorange noise (a, b) of sigma^2 = a^2 + b^2 / sin^2 E [m] (noise plus multipath
        of a low-cost receiver; the simulator's defaults give about (0.3, 0.32)).
    doppler_sigma : (float, float)
        Doppler noise (a, b) of the same form [Hz].
    klobuchar : tuple or None
        (alpha, beta) of the broadcast ionosphere model; None applies no ionosphere
        correction.
    troposphere : bool
        Remove the Saastamoinen troposphere.
    max_satellites : int or None
        Use at most this many satellites, the highest first (None: all).
    min_satellites : int
        Fewer usable satellites give no measurement.
    use_doppler : bool
        Add the range rates (when every selected satellite has a Doppler).
    """

    signals: dict = field(default_factory=lambda: {GPS: "1C", GALILEO: "1C"})
    elevation_mask: float = math.radians(10.0)
    code_sigma: tuple = (0.5, 0.5)
    doppler_sigma: tuple = (0.05, 0.05)
    klobuchar: tuple | None = None
    troposphere: bool = True
    max_satellites: int | None = None
    min_satellites: int = 1
    use_doppler: bool = True


@dataclass(frozen=True)
class CorrectedRange:
    """One satellite's measurements brought to the navigator's model.

    Attributes
    ----------
    sat_id : str
    elevation, azimuth : float
        Seen from the INS antenna; azimuth clockwise from north [rad].
    sat_pos, sat_vel : ndarray, shape (3,)
        At transmission, in the ECEF frame of reception [m, m/s].
    sat_clock : float
        c (dt^i - T_GD): clock with relativity minus the signal's group delay [m].
    sat_clock_drift : float
        c dt^i' [m/s].
    iono, tropo : float
        Delays removed from the pseudorange [m].
    pseudorange : float
        Measured pseudorange minus iono and tropo [m].
    pr_var : float
        [m^2].
    range_rate : float
        -wavelength x Doppler, corrected as in the module docstring [m/s]; NaN without Doppler.
    rr_var : float
        [(m/s)^2].
    """

    sat_id: str
    elevation: float
    azimuth: float
    sat_pos: np.ndarray
    sat_vel: np.ndarray
    sat_clock: float
    sat_clock_drift: float
    iono: float
    tropo: float
    pseudorange: float
    pr_var: float
    range_rate: float
    rr_var: float


def ephemeris_valid(eph, t_gps):
    """Whether a healthy ephemeris may be used at GPS time `t_gps` [s] (fit interval)."""
    if eph.health:
        return False
    if isinstance(eph, GlonassEphemeris):
        return abs(t_gps - eph.toe) <= GLONASS_MAX_AGE
    return abs(wrap_week_difference(t_gps - eph.toe)) <= FIT_HALF_WIDTH_S


def atmosphere_delays(t_gps, lat, lon, h, rx_xyz, sat_xyz, frequency_hz, config):
    """Ionosphere and troposphere delays of one signal and the satellite's elevation/azimuth.

    Parameters
    ----------
    t_gps : float
        GPS time [s].
    lat, lon, h : float
        Antenna geodetic position [rad, rad, m].
    rx_xyz, sat_xyz : array_like, shape (3,)
        Antenna and satellite ECEF positions [m].
    frequency_hz : float
    config : RangeConfig

    Returns
    -------
    iono, tropo : float
        Code delays [m] (zero for a model switched off).
    elevation, azimuth : float
        [rad], azimuth clockwise from north.
    """
    elevation, azimuth = elevation_azimuth(rx_xyz, sat_xyz)
    iono = (klobuchar_delay(t_gps, lat, lon, elevation, azimuth, *config.klobuchar, frequency_hz)
            if config.klobuchar is not None else 0.0)
    tropo = tropo_delay(lat, h, elevation) if config.troposphere else 0.0
    return iono, tropo, elevation, azimuth


def _doppler_light_time_term(u, sat_pos, sat_vel, v_ant_ecef):
    """k rho' of the module docstring: add to the measured range rate [m/s]."""
    k = u @ (sat_vel - OMEGA_E * np.array([sat_pos[1], -sat_pos[0], 0.0])) / C_LIGHT
    return k * (u @ (sat_vel - v_ant_ecef))


def correct_observations(epoch, ephemerides, state, lever_b=np.zeros(3), config=RangeConfig()):
    """Every usable satellite of a raw epoch with its measurements corrected.

    Parameters
    ----------
    epoch : observations.RawEpoch
        Receiver-time-tagged observations.
    ephemerides : dict
        sat_id -> KeplerEphemeris / GlonassEphemeris.
    state : NavState
        INS (IMU) solution at the epoch: position for the geometry, attitude for the lever arm,
        velocity for the light-time term of the range rate.
    lever_b : array_like, shape (3,)
        Antenna relative to the IMU, FLU [m].
    config : RangeConfig

    Returns
    -------
    list of CorrectedRange
        Sorted by decreasing elevation; not yet limited to `max_satellites`.
    """
    lat, lon, h = (float(x) for x in lever_arm_position(state.lat, state.lon, state.h,
                                                        state.q_nb, np.asarray(lever_b, float)))
    rx = geodetic_to_ecef(lat, lon, h)
    # The antenna velocity differs from the IMU's by omega x l, a few cm/s: far below what
    # matters in a 1e-5 correction.
    v_ant = ecef_to_enu_matrix(lat, lon).T @ np.asarray(state.v_enu, float)
    t_rx = epoch.t_gps
    out = []
    for ob in epoch.obs:
        eph = ephemerides.get(ob.sat_id)
        if config.signals.get(ob.system) != ob.signal or eph is None \
                or not math.isfinite(ob.pseudorange_m) or not ephemeris_valid(eph, t_rx):
            continue
        gd = 0.0 if isinstance(eph, GlonassEphemeris) else group_delay(eph, ob.frequency_hz)
        if not math.isfinite(gd):
            continue
        sat, clock, sat_vel, drift = satellite_at_reception(eph, t_rx, ob.pseudorange_m, rx)
        iono, tropo, el, az = atmosphere_delays(t_rx, lat, lon, h, rx, sat, ob.frequency_hz,
                                                config)
        if el < config.elevation_mask:
            continue
        range_rate = math.nan
        if math.isfinite(ob.doppler_hz):
            after = atmosphere_delays(t_rx + _RATE_STEP, lat, lon, h, rx,
                                      sat + _RATE_STEP * sat_vel, ob.frequency_hz, config)
            before = atmosphere_delays(t_rx - _RATE_STEP, lat, lon, h, rx,
                                       sat - _RATE_STEP * sat_vel, ob.frequency_hz, config)
            iono_rate, tropo_rate = (np.subtract(after[:2], before[:2]) / (2 * _RATE_STEP))
            los = sat - rx
            u = los / np.linalg.norm(los)
            range_rate = (-C_LIGHT / ob.frequency_hz * ob.doppler_hz + iono_rate - tropo_rate
                          + _doppler_light_time_term(u, sat, sat_vel, v_ant))
        sigma_pr = float(elevation_sigma(el, *config.code_sigma))
        sigma_rr = float(elevation_sigma(el, *config.doppler_sigma)) * C_LIGHT / ob.frequency_hz
        out.append(CorrectedRange(
            ob.sat_id, el, az, sat, sat_vel, C_LIGHT * (clock - gd), C_LIGHT * drift, iono,
            tropo, ob.pseudorange_m - iono - tropo, sigma_pr ** 2, float(range_rate),
            sigma_rr ** 2))
    out.sort(key=lambda c: -c.elevation)
    return out


def stack_ranges(t, corrected, use_doppler=True):
    """The navigator's measurement from per-satellite corrections (all of them, in order).

    Range rates are attached only when every satellite has one (the navigator takes one
    range-rate vector per epoch).

    Parameters
    ----------
    t : float
        Epoch on the navigation time scale [s].
    corrected : sequence of CorrectedRange
    use_doppler : bool

    Returns
    -------
    SatelliteRanges
        pr_var and rr_var as per-satellite arrays.
    """
    rr = np.array([c.range_rate for c in corrected])
    with_rates = use_doppler and bool(np.all(np.isfinite(rr)))
    return SatelliteRanges(
        t=float(t), sat_pos=np.array([c.sat_pos for c in corrected]),
        sat_vel=np.array([c.sat_vel for c in corrected]),
        sat_clock=np.array([c.sat_clock for c in corrected]),
        sat_clock_drift=np.array([c.sat_clock_drift for c in corrected]),
        pseudorange=np.array([c.pseudorange for c in corrected]),
        pr_var=np.array([c.pr_var for c in corrected]),
        range_rate=rr if with_rates else None,
        rr_var=np.array([c.rr_var for c in corrected]))


def satellite_ranges(epoch, ephemerides, t, state, lever_b=np.zeros(3), config=RangeConfig()):
    """Tight-coupling measurement of one raw epoch (the ``ekf`` node's entry point).

    Parameters
    ----------
    epoch : observations.RawEpoch
        From ``gnss/observations`` (receiver time tag in `epoch.t_gps`).
    ephemerides : dict
        sat_id -> KeplerEphemeris / GlonassEphemeris from ``gnss/ephemeris``.
    t : float
        The epoch on the navigation (IMU) time scale [s]: the message stamp. The receiver time
        tag is ahead of GPS time by the receiver clock offset; the stamp must not be.
    state : NavState or None
        The navigator's solution at `t` (``Navigator.state_at(t)``); None before the
        navigator has started (it starts from a GnssFix) gives None.
    lever_b : array_like, shape (3,)
        Antenna relative to the IMU, FLU [m] (the navigator's lever arm).
    config : RangeConfig

    Returns
    -------
    SatelliteRanges or None
        None when fewer than `config.min_satellites` satellites are usable.
    """
    if state is None:
        return None
    corrected = correct_observations(epoch, ephemerides, state, lever_b, config)
    if config.max_satellites is not None:
        corrected = corrected[:config.max_satellites]
    if len(corrected) < max(config.min_satellites, 1):
        return None
    return stack_ranges(t, corrected, config.use_doppler)
