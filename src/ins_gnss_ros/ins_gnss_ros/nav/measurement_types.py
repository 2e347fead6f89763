"""Time-stamped measurements the navigator accepts (:meth:`Navigator.add_measurement
<ins_gnss_ros.nav.navigator.Navigator.add_measurement>`).

Values, not models: the innovations they give rise to are in :mod:`ins_gnss_ros.nav.measurements`.
Times are on the navigation time scale (s); a GNSS measurement stamped t refers to the epoch
t - td when the filter has a "td" time-offset state.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class GnssFix:
    """Antenna position at GNSS time t (s): lat, lon (rad), h (m), covariance ENU (m^2).

    ``common_var`` (m^2 per horizontal axis, m^2 vertical) is the variance of an error all of
    the receiver's fixes share that ``cov_enu`` leaves out (the absolute accuracy of a receiver
    at single-point level, whose fixes are weighted by their fix-to-fix noise): no measurement
    can observe it, so it is not a filter state but part of the published covariance.

    ``height_known`` False: a fix without an altitude (a 2-D fix), whose ``h`` and vertical
    variance stand for the solution's height and an uncertainty that carries next to no
    information (nav/aiding.py): a filter starting on it takes that variance for its height.

    ``stamp_sigma`` (s): the standard deviation of t about the epoch (plus the filter's latency
    estimate): a driver that stamps a message on its arrival passes on how much the receiver's
    and the transport's latency vary, which moves the fix by the velocity times that error.

    ``refutes_covariance``: the first fix whose status' reported covariance the fixes' scatter
    refuted (a driver's placeholder, nav/aiding.py), ``cov_enu`` the one now taken for them:
    the position the fixes before it pinned with the placeholder is known no better."""

    t: float
    lat: float
    lon: float
    h: float
    cov_enu: np.ndarray
    common_var: tuple[float, float] = (0.0, 0.0)
    height_known: bool = True
    stamp_sigma: float = 0.0
    refutes_covariance: bool = False


@dataclass(frozen=True)
class GnssVelocity:
    """Antenna velocity ENU (m/s) at GNSS time t, covariance ((m/s)^2).

    ``fixes``: for a velocity made of successive fixes (nav/course.py), those fixes, each as
    (GnssFix, X) with X (3, 3) the covariance of this velocity's error with the fix's error
    ((m^2)/s): the alignment on it uses them with that correlation, and the filter not again.
    ``aligns``: its course may align the heading (the front end says no while the IMU is still
    and the course is not known beyond the receiver's noise: nav/aiding.py).
    ``checks_only``: a course of a run of fixes made with the INS's yaw while the heading was
    unconfirmed (Navigator.heading_unconfirmed: a heading source steered it, or the gyros' bias
    about the vertical may hold a turn): it confirms or refutes that heading and aligns none
    (refuted, the yaw it was made with followed the source or the turn).
    ``rate_error``: for a run's velocity, the gyros' rate error about the vertical the run
    measured and its variance (rad/s, (rad/s)^2), which the alignment on it takes; else None.
    ``stamp_sigma`` (s): as GnssFix's, the velocity moved by the acceleration times it."""

    t: float
    v_enu: np.ndarray
    cov_enu: np.ndarray
    fixes: tuple = ()
    aligns: bool = True
    checks_only: bool = False
    rate_error: tuple | None = None
    stamp_sigma: float = 0.0


@dataclass(frozen=True)
class HeadingFix:
    """Azimuth of the body x axis (rad, clockwise from true north) at time t, variance (rad^2).
    `bias` names the extra block of the source's own heading bias: "mag" for a magnetic compass,
    "ahrs" for an IMU's orientation (declination already applied); None for a true heading
    (phase differences, a dual-antenna receiver). `field_enu`: the Earth field's direction
    (ENU) for a compass that levelled it with the filter's own roll and pitch
    (measurements.biased_heading), else None."""

    t: float
    azimuth: float
    variance: float
    bias: str | None = None
    field_enu: tuple | None = None


@dataclass(frozen=True)
class HeadingRefuted:
    """A heading source (its bias block, as HeadingFix.bias) found at time t not to be a
    heading of the body, and why (its turns against the gyros: nav/heading_turns.py): its
    readings are refused from then on, and the heading it aligned or steered is no longer
    known."""

    t: float
    bias: str | None
    why: str


@dataclass(frozen=True)
class PhaseDifferences:
    """Fixed carrier-phase double differences between antennas of the body at GNSS time t:
    row j, ``value[j] = geometry[j] · (C_nb baseline_b[j])`` + noise (m), with ``baseline_b`` the
    two antennas' difference in body FLU (m) and ``geometry`` the difference of the unit lines
    of sight to the reference and the other satellite (ENU); ``cov`` their joint covariance
    (m^2), correlated through the common reference satellite and antenna."""

    t: float
    baseline_b: np.ndarray
    geometry: np.ndarray
    value: np.ndarray
    cov: np.ndarray


@dataclass(frozen=True)
class SpeedLog:
    """Speed through the water along the body x axis (m/s) at time t, variance ((m/s)^2);
    with a "log" extra block the current and the log scale error are estimated."""

    t: float
    speed: float
    variance: float


@dataclass(frozen=True)
class WheelOdometry:
    """Velocity of the wheel odometry's reference point (rear-axle centre) in body axes (m/s,
    FLU) at time t, per-axis variances ((m/s)^2): the forward speed the wheels measure, and the
    lateral and vertical velocity the wheels allow (zero: the non-holonomic constraint); with a
    "wheel" extra block the odometry's scale error is estimated."""

    t: float
    velocity_b: np.ndarray
    variance: np.ndarray


@dataclass(frozen=True)
class ZeroVelocity:
    """The vehicle is known to be at rest at time t: ZUPT (sigma_v m/s per axis) and the
    navigator's ZARU (its ``zaru_sigma``); GNSS is then used while the heading is unknown."""

    t: float
    sigma_v: float = 0.02


@dataclass(frozen=True)
class Rest:
    """The IMU and the fixes tell the vehicle at rest at time t (nav/rest_detector.py) behind a
    receiver whose own velocity is too noisy to tell it: GNSS is used while the heading is
    unknown, as at a ZeroVelocity, and the receiver's velocities stay the updates (a
    zero-velocity update in their place measured alike: the simulated car behind 0.3 m/s
    velocities, 0.296 against 0.297 of the fixes' RMS)."""

    t: float


@dataclass(frozen=True)
class StillImu:
    """The IMU alone was still up to time t (nav/rest_detector.py): the vehicle stands, or moves
    steadily straight on. In both the specific force is gravity and the rate the Earth's, so a
    start on it levels and takes the gyro bias of the stationary mean, but its velocity is
    unknown until the fixes confirm rest (then ZeroVelocity). Used only before the start."""

    t: float


@dataclass(frozen=True)
class SatelliteRanges:
    """Tight coupling: per-satellite pseudoranges (and optionally range rates) at GNSS time t.

    Arrays of k satellites: sat_pos, sat_vel (ECEF, m, m/s), sat_clock (m), sat_clock_drift
    (m/s), pseudorange (m), pr_var (m^2), range_rate (m/s, or None), rr_var ((m/s)^2).
    """

    t: float
    sat_pos: np.ndarray
    sat_vel: np.ndarray
    sat_clock: np.ndarray
    sat_clock_drift: np.ndarray
    pseudorange: np.ndarray
    pr_var: float
    range_rate: np.ndarray | None = None
    rr_var: float = 0.01



#: Measurements of the GNSS receiver: their epoch moves with the "td" estimate, and while the
#: heading is unknown they are used only at rest.
GNSS_TYPES = (GnssFix, GnssVelocity, SatelliteRanges)
