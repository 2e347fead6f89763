"""The aiding front end: sensor readings -> navigator measurements, one policy for every path.

What the filter is told about each input is decided here, once: how an IMU increment after a
gap is bridged or loses the IMU; which readings are
refused (no fix, non-finite, beyond any vehicle), what variance a reading without one gets, the
variance floors, the receiver's velocity latency, how a magnetic heading is referred to true
north, when GNSS ranges replace fix and velocity (tight coupling, seed 004 section 2.1), and,
for a receiver without velocity output, the rest that a still IMU and unmoving fixes show
(zero-velocity updates in place of the receiver's speed, nav/rest_detector.py) and the course
over ground from successive fixes that aligns the heading.
The ``ekf`` node feeds it the topics' messages as plain values; the offline replay feeds it the
same values from a bag (the configuration both build from the ``ekf`` parameters:
:mod:`ins_gnss_ros.nav.filter_config`).
"""
from __future__ import annotations

import bisect
import math
from collections import deque
from dataclasses import dataclass
from typing import Callable

import numpy as np

from ..magnetic.wmm import FieldAlongTrack, decimal_year, field_elements
from .alignment import course_is_known, yaw_of_x
from .course import MIN_SCATTER_SAMPLES, CourseFromFixes, WhiteNoise
from .ekf import ExtraState
from .heading_noise import HeadingNoise
from .heading_turns import HeadingTurns
from .imu_timing import ImuTimingCheck
from .increments import BRIDGED, CONTIGUOUS, LOST, classify_gap, held_increments
from .integrity import NOT_VOUCHING
from .local_frame import to_map
from .rotations import quat_to_dcm
from .measurement_types import GnssFix, GnssVelocity, HeadingFix, HeadingRefuted, \
    PhaseDifferences, Rest, SpeedLog, StillImu, WheelOdometry, ZeroVelocity
from .modes import ALIGNING, NAVIGATING
from .navigator import REST_HOLD, Navigator
from .rest_detector import RestDetector
from .velocity_check import VelocityAgreement

__all__ = ["Aiding", "AidingPolicy", "InputStats", "WheelPolicy"]

#: Horizontal sigma (m) given to a fix that carries no covariance, by its sensor_msgs/NavSatStatus
#: status (STATUS_FIX 0, STATUS_SBAS_FIX 1, STATUS_GBAS_FIX 2): a single-point fix (~5 m), an
#: SBAS-corrected fix (~2 m) and a ground-based differential fix (DGNSS or RTK: 1 m, the
#: conservative end, since NavSatStatus does not tell RTK fixed from float or code DGNSS). The
#: vertical sigma is taken twice the horizontal (the geometry of a ground receiver).
UNKNOWN_FIX_SIGMA = {0: 5.0, 1: 2.0, 2: 1.0}
#: Horizontal sigma from which a fix's covariance is taken as the receiver's absolute accuracy,
#: m: single-point, SBAS and code-differential errors (atmosphere, orbits, multipath) change
#: over tens of seconds and do not average out from fix to fix; carrier-phase fixes (cm) are
#: taken as given.
SHARED_ERROR_SIGMA = 0.3
#: The fixes' measured white variance must be below this share of the covariance's for a shared
#: part to be split off: 50 second differences measure it to about 25 %, and a white part taken
#: below the truth makes the filter chase the fixes' noise (white fixes as reported: a simulated
#: SAR flight's smoothed 1 s relative error 0.02 -> 1.6 mm).
WHITE_SHARE = 0.5
#: Time over which the fixes' white share is averaged for that decision, s: ten fixes at 5 Hz,
#: so that neither one fix's reported sigma nor one fluke of the measured noise flips it.
SHARE_TIME_CONSTANT = 2.0
#: Sigma of a GNSS velocity without covariance (an all-zero one: a driver that fills none, or a
#: geometry_msgs/TwistStamped converted), m/s horizontal; twice that vertically. The conservative
#: end of receivers' Doppler velocities (0.05-0.2 m/s; an NMEA course and speed, 0.1-0.2): a
#: floor-level sigma (velocity_sigma_floor_mps) would let a noisier receiver's velocity tilt the
#: heading and pull the position beyond its covariance (a simulated car with 0.05 m/s velocities
#: so published: position NEES 8 -> 33). A receiver noisier than that shows it while the IMU is
#: still (the velocity constant: rest, or steady straight motion), and its scatter there is
#: taken instead (RestDetector.velocity_noise): taken at 0.2 m/s, a receiver scattering 0.3
#: m/s at rest aligned the heading on its noise in two of five simulated standstills.
UNKNOWN_VELOCITY_SIGMA = 0.2
#: Velocity noise per horizontal axis no receiver's reaches, m/s: five times the conservative
#: end above, three times the robustness matrix's noisiest receiver (0.3 m/s). A course known
#: beyond it (alignment.course_is_known: from 5 m/s) is motion, whatever the receiver's noise
#: where the IMU is still.
RECEIVER_NOISE_BOUND = 1.0
#: A receiver's speed tells rest by the navigator's static_speed when its reported sigma per
#: horizontal axis is at most this fraction of static_speed: a standing vehicle's speed then
#: passes static_speed by noise on at most a third of the epochs (exp(-1 / (2 f^2)) = 1/3). A
#: noisier one (0.2 m/s per axis passes 0.1 m/s at rest on 88 % of the epochs, and while the
#: heading was unknown its fixes were held as in motion) leaves rest to the rest detector
#: (Rest); not a receiver whose speed can tell it: the detector lags a smooth start (taken
#: beside the simulated RTK car's 0.05 m/s velocities, it held its first 0.2 m/s as rest, and
#: the first fixes after the heading alignment were 6 sigma off).
SPEED_TELLS_REST = 1.0 / math.sqrt(2.0 * math.log(3.0))
#: Behind a noisy receiver, a speed beyond this many sigmas (per horizontal axis) is motion,
#: whatever the rest detector says (noise alone passes it on exp(-4.5) = 1 % of the epochs).
MOVING_SIGMAS = 3.0
#: A receiver's velocity covariance is refuted when its velocities scatter more than this many
#: times its sigma while the IMU is still (an honest one's does so with 10 degrees of freedom
#: with probability P(chi2_10 > 40) = 2e-5): a driver's placeholder covariance, taken as it
#: was, let 0.3 m/s of noise reported as 0.03 align the heading in the standstill 20 sigma off.
#: Its fixes' covariance likewise, by their scatter about the vehicle's motion (2 m fixes
#: reported as 0.1 m were refused at the gate, then forced in, and a whole simulated drive was
#: degraded with no valid nav/fix): their second differences less what the receiver's
#: velocities say the acceleration made of them, or without those their third differences,
#: while the IMU is still (rest, steady straight motion, or a steady acceleration a smooth
#: vehicle's IMU may pass as still, which leaves second differences but no third ones) or where
#: a vehicle's jerk leaves them the noise (MAX_JERK). A refuted fix is taken as one without
#: covariance, so a false refutation costs little: fixes reporting just their white noise are
#: refuted by third differences on 2e-4 of the fixes of a standstill (Monte Carlo, 2000
#: standstills of 30 s at 5 Hz, 1 % of them with one such fix; most where ten differences
#: first make the median).
COVARIANCE_REFUTED = 2.0
#: A vehicle's largest fourth derivative of position, m/s^4 (a car turning in: its lateral
#: acceleration's jerk of a few m/s^3 changing within a second). A second difference of fixes
#: dt apart less dt (v2 - v0) / 2 keeps snap dt^4 / 12 of the motion: the velocities measure a
#: reported sigma only where that is below half of it (a 1 Hz receiver's 2 cm: no; its 5 Hz
#: ones' 2 cm, 1 mm: yes).
MAX_SNAP = 5.0
#: A vehicle's largest third derivative of position, m/s^3 (a car turning in or braking at
#: 0.4 g within a second). The third difference of fixes dt apart keeps jerk dt^3 of the
#: motion: in motion, without the receiver's velocities, it measures a reported sigma where that
#: is below half of it (5 Hz fixes' 0.1 m: yes; 1 Hz ones' 0.5 m: no).
MAX_JERK = 5.0
#: The first fixes of a recording, as many as the test of their reported covariance takes
#: (MIN_SCATTER_SAMPLES third differences, the last judged at the next fix), make no course
#: before it where it measures in motion (_jerk_below_noise): 2 m fixes reported as 0.1 m
#: aligned a start on the move 30 sigma off on the chord of two of them (11 valid nav/fix
#: beyond 5 sigma; docs/results/product_path.md, "2026-12-06 (session 33)"). Fixes too
#: irregularly spaced for the test by then (stamped on arrival) do not wait for it.
FIXES_TO_TEST = MIN_SCATTER_SAMPLES + 4
#: Receiver velocities kept to be paired with the fixes of their epochs.
RECENT_VELOCITIES = 8
#: Heights this filter navigates at, m (a fix outside is corrupt; the integrity logic would
#: otherwise force it in after a while).
HEIGHT_RANGE = (-1000.0, 1e5)
#: Vertical sigma of a fix without an altitude (NavSatFix: "quiet NaN if no altitude is
#: available", a 2-D fix), m: its height is the solution's (the filter starts there with this
#: sigma, GnssFix.height_known), so the vertical is left to the INS and its other aiding
#: (gnss/vel, the vehicle constraint). The fix keeps its vertical row: without it, with the
#: height this uncertain, the horizontal rows' slight dependence on it (the Earth's curvature)
#: moved the height by up to 300 m on a simulated 90 s drive; with it the height holds.
NO_ALTITUDE_SIGMA = 1000.0
#: Fastest plausible GNSS velocity, m/s (beyond any vehicle this filter is for).
MAX_SPEED = 1000.0
#: The receiver's messages whose stamps are taken for their epochs (the "td" state moves both).
GNSS_STAMPED = ("gnss/fix", "gnss/vel")
#: A GNSS message reaching the filter at most this long after its stamp was stamped on its
#: arrival (a driver that stamps the time it read the message, nmea_navsat_driver's way), ns:
#: no receiver delivers a solution that soon after its epoch (10-100 ms at output rates of
#: 1-20 Hz), while a driver's stamp precedes its message's arrival only by the transport
#: (0.1-1 ms on one machine). Judged on the least delay seen (any message may come late, none
#: comes before its epoch), in the node's clock or a replay's log time.
ARRIVAL_STAMP_MAX_NS = 3_000_000
#: A delay below this tells nothing, ns: a recording written at its stamps (simulated,
#: converted), whose log times equal them or differ by the rounding of a float time; no
#: transport between two processes takes less.
ARRIVAL_STAMP_MIN_NS = 10_000
#: Sigma of the receiver's latency behind such stamps (the filter's time-offset state "td"), s:
#: receivers and serial links give 20-200 ms.
ARRIVAL_LATENCY_SIGMA = 0.2
#: Range of that latency's estimate, s: a message does not arrive before its epoch. Left
#: free, a car's straight acceleration took it to -86 ms (the truth 50-150 ms) and 45 mg of
#: accelerometer bias with it, the horizontal RMS of a drive with fixes alone 0.89x the raw
#: fixes' (0.44x held at zero; docs/results/product_path.md, "2026-12-07 (session 41)").
ARRIVAL_LATENCY_RANGE = (0.0, np.inf)
#: Intervals between the arrival stamps of each such topic over which their scatter about the
#: receiver's epochs is measured (stamp_scatter: within 0.8-1.5 of a uniform latency's over 100,
#: 0.4-2.4 over 25), and the fewest that measure it.
STAMP_INTERVALS = 100
MIN_STAMP_INTERVALS = 10


def stamp_scatter(stamps_ns) -> float:
    """Standard deviation (s) of the stamps of a receiver's messages about its regular epochs:
    each interval is the period plus the difference of two stamps' errors, so the intervals'
    robust spread about their median over sqrt 2 (a lost epoch's double interval is an outlier
    to it, as is a rate that drifts slowly)."""
    d = np.diff(np.asarray(stamps_ns, np.int64)) * 1e-9
    return float(1.4826 * np.median(np.abs(d - np.median(d))) / math.sqrt(2.0))


@dataclass(frozen=True)
class WheelPolicy:
    """How wheel odometry readings become measurements (the ``wheel.*`` parameters).

    Attributes
    ----------
    sigma : tuple of 3 float
        Forward, lateral and vertical sigma of a reading without its variances, m/s (0: the
        axis is left out).
    zero_speed : float
        A forward speed at or below this is a zero-velocity update, m/s (0: never) ...
    zero_time : float
        ... once the speed has stayed there this long, s: encoder counts also read zero while
        the vehicle crawls off or to a stop (until then a zero reading is a speed).
    zero_sigma : float
        Sigma of that update, m/s.
    delay : float
        A reading stamped t refers to t - delay, s.
    """

    sigma: tuple = (0.1, 0.1, 0.1)
    zero_speed: float = 0.01
    zero_time: float = 0.5
    zero_sigma: float = 0.02
    delay: float = 0.0

    @classmethod
    def from_params(cls, p: dict) -> "WheelPolicy":
        """The policy of the ``ekf`` node's parameters."""
        return cls((p["wheel.speed_sigma_mps"], *p["wheel.nonholonomic_sigma_mps"]),
                   p["wheel.zero_speed_mps"], p["wheel.zero_speed_time_s"],
                   p["wheel.zero_velocity_sigma_mps"],
                   p["wheel.delay_s"])


@dataclass(frozen=True)
class AidingPolicy:
    """How aiding readings become measurements.

    Attributes
    ----------
    position_sigma_floor : float
        Floor of the GNSS position sigma per axis, m.
    velocity_sigma_floor : float
        Floor of the GNSS velocity sigma per axis, m/s.
    velocity_delay : float
        Latency of the receiver's velocity solution: a velocity stamped t is applied at
        t - delay, s.
    coupling : str
        "loose" (fix + velocity), "tight" (ranges) or "auto" (ranges below ``min_satellites``).
    min_satellites : int
        Auto coupling: fewer usable satellites than this in an epoch switch to ranges.
    max_imu_gap : float
        Longest gap in the increments bridged by holding the rates of the increment after it; a
        longer one loses the IMU and the filter aligns again, s.
    max_delay : float
        Latest a reading may come after the increment of its stamp and still be used (the
        navigator's ``history``), s.
    wheel : WheelPolicy
    phase_differences : bool
        The fixed phase double differences aid the attitude: ``gnss/heading`` only aligns the
        heading (the two come from the same phase and would count it twice).
    magnetic_levelled_by_ins : bool
        ``mag/heading`` was levelled with this filter's roll and pitch: its tilt error is the
        filter's (measurements.biased_heading).
    """

    position_sigma_floor: float = 0.02
    velocity_sigma_floor: float = 0.02
    velocity_delay: float = 0.0
    coupling: str = "loose"
    min_satellites: int = 5
    max_imu_gap: float = 2.5
    max_delay: float = 3.0
    wheel: WheelPolicy = WheelPolicy()
    phase_differences: bool = False
    magnetic_levelled_by_ins: bool = True

    @classmethod
    def from_params(cls, p: dict) -> "AidingPolicy":
        """The policy of the ``ekf`` node's parameters."""
        return cls(p["gnss.position_sigma_floor_m"], p["gnss.velocity_sigma_floor_mps"],
                   p["gnss.velocity_delay_s"], p["coupling"], p["auto.min_satellites"],
                   p["max_imu_gap_s"], p["history_s"], wheel=WheelPolicy.from_params(p),
                   phase_differences=p["use_phase_dd"],
                   magnetic_levelled_by_ins=p["magnetic_levelled_by_ins"])


#: Longest the first fixes of a receiver without velocity wait for the rest detector, s (an
#: IMU whose blocks do not come, or do not settle: the filter then levels without the static
#: gyro bias).
REST_DECISION_S = 10.0

#: Heading inputs -> the extra block of their own bias (None: a true heading, no bias).
HEADING_SOURCES = {"gnss/heading": None, "mag/heading": "mag", "imu/heading": "ahrs"}
#: Heading readings kept waiting for the increments to reach their stamps (a lost IMU stops
#: them): a second of a 50 Hz compass.
AWAITING_GYROS = 64

#: What the filter waits for while it has fixes but no heading (ALIGNING), without gnss/vel
#: and with it (a vehicle standing behind a receiver with velocity waits for motion).
_HEADING_INPUTS = ("an IMU orientation with a valid yaw covariance (imu/heading), mag/heading or "
                   "gnss/heading")
NO_HEADING = "no heading source yet: needs gnss/vel, movement well beyond the fixes' noise, " \
    + _HEADING_INPUTS
NO_MOTION = "no heading source yet: waits for motion (gnss/vel above align.speed_mps, beyond " \
    "its noise while the IMU is still), or " + _HEADING_INPUTS


#: A gnss/vel latency estimate this far beyond zero (and 3 sigma) is explained on /diagnostics,
#: s: the simulated receivers' honest velocities give a few ms.
VELOCITY_LAG_TOLD = 0.02


def velocity_latency_summary(latency: float, sigma: float) -> str:
    """/diagnostics' line of the filter's gnss/vel latency estimate ("vd" state, s) and its
    sigma, with what a clear lag can mean: both causes give it, and only the second also
    delays the fixes, which no state here takes (a receiver stamped 100 ms late on the
    simulated car: this estimate 49 +- 4 ms, 94 % of the valid nav/fix beyond 5 sigma;
    docs/results/product_path.md, "2026-12-05 (session 23)")."""
    text = f"{1e3 * latency:.0f} +- {1e3 * sigma:.0f} ms"
    if latency > max(3.0 * sigma, VELOCITY_LAG_TOLD):
        text += (": the velocity lags the IMU; a filtered solution lagging its fix (gnss."
                 "velocity_delay_s), or gnss/* stamped on arrival, whose fixes then lag as much "
                 "(the ekf's time_offset_sigma_s 0.1-0.2)")
    return text


@dataclass
class InputStats:
    """What one aiding input delivered: readings received and refused, first and last stamp (s)."""

    received: int = 0
    refused: int = 0
    first_t: float = math.nan
    last_t: float = math.nan
    lead: float = math.nan  # the last stamp minus the newest increment's at its arrival, s
    problem: str | None = None  # why the last reading was refused, for a lasting cause
    stamp_sigma: float = math.nan  # scatter of arrival stamps about the epochs, s

    def rate(self) -> float:
        """Mean rate of the readings, Hz (nan before two)."""
        span = self.last_t - self.first_t
        return (self.received - 1) / span if self.received > 1 and span > 0.0 else math.nan

    def summary(self, t: float) -> str:
        """One line for diagnostics at time t (s)."""
        lead = f", stamped {self.lead:+.2f} s from imu/delta" if math.isfinite(self.lead) else ""
        if math.isfinite(self.stamp_sigma):
            lead += f", arrival stamps scattered {1e3 * self.stamp_sigma:.1f} ms about its epochs"
        return (f"{self.rate():.2f} Hz, last {t - self.last_t:.1f} s ago{lead}, "
                f"{self.received} received, {self.refused} refused")


def _unknown(cov: np.ndarray) -> bool:
    """A reading's covariance gives no variance (ROS drivers leave it zero when they have
    none)."""
    return not all(v > 0.0 for v in cov.diagonal().tolist())


def _snap_below_noise(dt: float, reported_var: float) -> bool:
    """A vehicle's snap (MAX_SNAP) leaves less than half the reported sigma (reported_var per
    axis, m^2) in a second difference of fixes dt (s) apart less dt (v2 - v0) / 2."""
    return MAX_SNAP * dt ** 4 / 12.0 < 0.5 * math.sqrt(reported_var)


def _jerk_below_noise(dt: float, reported_var: float) -> bool:
    """A vehicle's jerk (MAX_JERK) leaves less than half the reported sigma (reported_var per
    axis, m^2) in a third difference of fixes dt (s) apart."""
    return MAX_JERK * dt ** 3 < 0.5 * math.sqrt(reported_var)


def _floored(cov: np.ndarray, sigma_floor: float) -> np.ndarray:
    """cov with its variances raised to sigma_floor^2 (each diagonal element gets
    max(floor - variance, 0) added, element by element: np.diag and np.maximum on a 3 x 3
    matrix cost several times that at every fix)."""
    floor = sigma_floor ** 2
    out = np.array(cov, float)
    for i in range(len(out)):
        out[i, i] += max(floor - out[i, i], 0.0)
    return out


class Aiding:
    """Feeds a :class:`Navigator` with aiding readings under one :class:`AidingPolicy`.

    Every method takes one reading (plain values, SI units, ENU), hands the navigator the
    measurement it makes or refuses it, and says so through ``report(text, log)`` (the caller's
    diagnostics counter). They return True when the navigator got a measurement.

    Parameters
    ----------
    navigator : Navigator
    policy : AidingPolicy
    report : callable
        ``report(text, log=True)``: count an event (``log=False``: expected, not worth a log
        line).
    """

    def __init__(self, navigator: Navigator, policy: AidingPolicy,
                 report: Callable[..., None]):
        self.navigator, self.policy, self.report = navigator, policy, report
        self.use_ranges = False  # the last observation epoch chose tight coupling
        self.datum = None  # (lat rad, lon rad, h m) of the first fix used
        self.inputs: dict[str, InputStats] = {}
        self.last_accepted_t = -math.inf  # newest accepted update, s
        self.forced: set[str] = set()  # kinds forced in since the filter last NAVIGATED
        self._course = CourseFromFixes()
        # The fixes' scatter in units of their reported variance per NavSatStatus status
        # (_fix_covariance_refuted); the (status, second difference) of the last fix if a
        # third difference ending at the next would be the fixes' noise (_third_measures);
        # the last fix's difference, judged at the next fix (by which the velocity of its
        # epoch has come: _add_scatter's arguments); the latest gnss/vel (stamp s, east and
        # north m/s, horizontal variance per axis m^2/s^2).
        self._fix_scatter: dict[int, WhiteNoise] = {}
        self._refuted_statuses: set[int] = set()  # whose fixes' covariance their scatter refuted
        self._last_second_difference = None
        self._pending_difference = None
        self._recent_velocities: deque = deque(maxlen=RECENT_VELOCITIES)
        # (heading known, the source it waits on) when the course last took the INS's yaw
        self._course_heading = (False, None)
        self._white_share = None  # (stamp s, the fixes' white share averaged up to it)
        # the IMU's clock and rates against the fixes' course (for diagnostics and the
        # navigator's mode)
        self.timing = ImuTimingCheck(gnss_latency_state="td" in navigator.config.extras)
        self.gnss_stamped_on_arrival = False  # gnss/* stamped on arrival or unset (arrival)
        # their stamps since, per topic (stamp_scatter)
        self._arrival_stamps = {name: deque(maxlen=STAMP_INTERVALS + 1)
                                for name in GNSS_STAMPED}
        self._velocity_check = VelocityAgreement()
        noise = navigator.config.noise
        self._rest = RestDetector(noise.accel_psd, noise.gyro_psd)
        self._wmm_declination = None  # at the datum, once a magnetic heading needs it
        self._wmm = FieldAlongTrack()  # the field a compass levelled with the INS measured
        self._first_held_t = math.nan  # the first fix held for the rest detector, s
        self._start_rest = False  # started in this still run before the fixes confirmed it
        # the last gnss/vel's horizontal speed and its sigma per horizontal axis (reported, or
        # taken when it has none), m/s (NaN: none yet)
        self._speed = (math.nan, math.nan)
        self.last_increment_t = math.inf  # end of the last increment, s
        self.wheel_still_since = math.inf  # stamp of the first of the zero wheel speeds, s
        # The measured error correlation of each heading source with a bias of its own
        # (nav/heading_noise.py), by source; its readings are taken against the azimuth the
        # gyros integrate from the first such reading on (rad, clockwise from north; kept as
        # (stamps, azimuths) over max_delay), a body rotation's up component from the third
        # row of C_nb of the solution at the latest reading
        self.heading_noise: dict[str, HeadingNoise] = {}
        self._gyro_azimuth: tuple[list, list] | None = None
        # Whether each heading source turns with the gyros (nav/heading_turns.py), by source,
        # against the same gyro azimuth
        self.heading_turns: dict[str, HeadingTurns] = {}
        # heading readings (source, stamp s, azimuth rad) waiting for the increments to reach
        # their stamps (an AHRS's readings are stamped with the sample an increment ends on)
        self._awaiting_gyros: deque = deque(maxlen=AWAITING_GYROS)
        self._up_row = (0.0, 0.0, 1.0)

    def arrival(self, name: str, stamp_ns: int, arrival_ns: int | None) -> None:
        """The input ``name``'s message stamped stamp_ns (0: unset) reached the filter at
        arrival_ns (the system clock, a replay's log time; None: not known). A receiver whose
        messages are stamped on their arrival (``ARRIVAL_STAMP_MAX_NS``) or not at all (the
        arrival taken for the stamp) leaves their latency unknown: the filter estimates it from
        the start (the time-offset state "td", sigma ``ARRIVAL_LATENCY_SIGMA``). Taken as the
        epochs, 50-150 ms late fixes and velocities put 94 % of a simulated drive's valid
        nav/fix beyond 5 sigma (docs/results/product_path.md, "2026-12-05 (session 25)"); the
        state from the start costs correctly stamped fixes accuracy (an RTK receiver's: 2-20
        times its sigma), so it is added only for such stamps. The latency's variation from
        message to message, which no state follows, is measured from the stamps' scatter
        (:func:`stamp_scatter`) and each message carries it (``stamp_sigma``): a receiver 125-375
        ms late put up to 22 valid nav/fix of a simulated 90 s drive beyond 5 sigma without it,
        none with it (seeds 0-7; docs/results/product_path.md, "2026-12-07 (session 42)")."""
        if name not in GNSS_STAMPED:
            return
        if not self.gnss_stamped_on_arrival:
            on_arrival = arrival_ns is not None and \
                ARRIVAL_STAMP_MIN_NS <= arrival_ns - stamp_ns <= ARRIVAL_STAMP_MAX_NS
            if not (stamp_ns == 0 or on_arrival):
                return
            self._estimate_latency(name, stamp_ns, arrival_ns)
        if stamp_ns or arrival_ns is not None:
            self._arrival_stamps[name].append(stamp_ns or arrival_ns)

    def _stamp_sigma(self, name: str, t: float) -> float:
        """The scatter (s) of the input ``name``'s stamps about its epochs at its reading t (s):
        measured where they are its arrival (and counted on /diagnostics), else 0."""
        stamps = self._arrival_stamps[name]
        if len(stamps) <= MIN_STAMP_INTERVALS:
            return 0.0
        stats = self._stats(name, t)
        stats.stamp_sigma = stamp_scatter(stamps)
        return stats.stamp_sigma

    def _estimate_latency(self, name: str, stamp_ns: int, arrival_ns: int | None) -> None:
        """The receiver's latency behind the arrival stamps of ``name`` estimated
        (:meth:`arrival`)."""
        self.gnss_stamped_on_arrival = True
        how = "unset" if stamp_ns == 0 else \
            f"on its arrival ({1e-6 * (arrival_ns - stamp_ns):.1f} ms before it)"
        if "td" in self.navigator.space:
            self.report(f"{name} stamped {how}: its latency estimated (time_offset_sigma_s)")
        elif self.navigator.started:
            self.report(f"{name} stamped {how}, after the filter started: its latency is not "
                        "estimated (set the ekf's time_offset_sigma_s 0.1-0.2)")
        else:
            self.navigator.add_extra_state("td", ExtraState(1, ARRIVAL_LATENCY_SIGMA),
                                           ARRIVAL_LATENCY_RANGE)
            self.timing.gnss_latency_state = True
            self.report(f"{name} stamped {how}: the receiver's latency estimated (time offset, "
                        f"sigma {ARRIVAL_LATENCY_SIGMA:g} s)")

    def _seen(self, name: str, t: float, used: bool) -> bool:
        stats = self._stats(name, t)
        stats.received += 1
        stats.refused += not used
        stats.last_t = t
        return used

    def _stats(self, name: str, t: float) -> InputStats:
        stats = self.inputs.get(name)
        if stats is None:
            stats = self.inputs[name] = InputStats(first_t=t)
        return stats

    def _clock_refuses(self, name: str, t: float) -> bool:
        """Whether a reading stamped t (s) is refused because its stamp does not fit the IMU's
        clock: increments come in real time (a replay keeps their order), so a reading stamped
        further ahead of the newest increment than the longest IMU gap the filter bridges, or
        further behind it than the navigator's history, comes from a clock that disagrees with
        the IMU's (a receiver stamping GPS time, 18 s ahead of UTC; a host clock not
        synchronised) or from a stopped IMU, and would be placed in the wrong part of the
        trajectory (the car drive with its fixes stamped 18 s ahead: 144 m RMS while NAVIGATING,
        NEES 4e5). Readings before the first increment are not judged."""
        stats = self._stats(name, t)
        if not math.isfinite(self.last_increment_t):
            return False
        stats.lead = lead = t - self.last_increment_t
        if -self.policy.max_delay <= lead <= self.policy.max_imu_gap:
            stats.problem = None
            return False
        stats.problem = (
            f"stamped {lead:+.1f} s from the newest imu/delta: its clock and the IMU's disagree "
            + ("(GPS time 18 s ahead of UTC?), or the IMU stopped" if lead > 0.0
               else "(a host clock?), or it comes later than history_s"))
        self.report(f"{name} refused: stamp beyond " + (
            "max_imu_gap_s ahead of the IMU's" if lead > 0.0 else "history_s behind the IMU's"))
        return True

    def note_updates(self, updates) -> None:
        """The navigator's update records since the last call (for :meth:`explain`)."""
        for u in updates:
            if u.reason == "forced" and u.name not in NOT_VOUCHING:
                self.forced.add(u.name)
            if u.accepted:
                self.last_accepted_t = max(self.last_accepted_t, u.t)

    def explain(self, t: float, imu_running: bool) -> str:
        """Why the navigator is in its mode at time t (s), for a user reading /diagnostics."""
        nav = self.navigator
        if not imu_running:
            return "waiting for imu/delta"
        if nav.mode == NAVIGATING:
            self.forced.clear()  # confirmed again
            return "navigating"
        if nav.mode == ALIGNING:
            fix = self.inputs.get("gnss/fix")
            if fix is None:
                return "aligning: no gnss/fix received yet"
            problem = self._problem()
            if problem:
                return f"aligning: {problem}"
            if fix.received == fix.refused:
                return f"aligning: every gnss/fix refused ({fix.refused})"
            if not nav.started and not math.isnan(self._first_held_t):
                return "aligning: gnss/fix held until the IMU tells rest from motion (levelling)"
            if nav.heading_known:
                return "aligning: levelling"
            return "aligning: " + (NO_MOTION if self._has_velocity() else NO_HEADING)
        problem = self._problem()
        if problem:
            return f"dead reckoning: {problem}"
        if self.timing.verdict().rates_wrong:
            return "dead reckoning (degraded): the IMU's rates are wrong (IMU from turns)"
        if self.forced:
            return ("dead reckoning (degraded): forced in, their noise floors not yet decayed: "
                    + ", ".join(sorted(self.forced)))
        unaided = t - self.last_accepted_t
        if nav.course_direction_unconfirmed and unaided < nav.config.dr_timeout:
            return ("dead reckoning: a GNSS update refused before the motion confirmed the "
                    "direction of the heading aligned on the course (the body x axis may point "
                    "against it: reversing, or the IMU mounted backwards)")
        return f"dead reckoning: no aiding accepted for {unaided:.1f} s"

    def _problem(self) -> str | None:
        """The lasting cause an input's last reading was refused for (the first input's)."""
        return next((f"{name} {stats.problem}" for name, stats in self.inputs.items()
                     if stats.problem), None)

    def _has_velocity(self) -> bool:
        """The receiver gives a velocity that agrees with its fixes (refused ones do not count:
        the fixes then stand in for it as for a receiver without one)."""
        return "gnss/vel" in self.inputs and not self._velocity_check.disagrees

    def increment(self, t: float, dtheta: np.ndarray, dv: np.ndarray, dt: float,
                  angle_var: float = 0.0, velocity_var: float = 0.0) -> str | None:
        """An IMU increment over dt (s) ending at t (s), already judged plausible
        (:func:`~ins_gnss_ros.nav.increments.increment_problem`), with the variances per axis
        of what its samples bridged by the IMU preprocessor may miss (rad^2, (m/s)^2;
        ImuDelta.bridged_*_variance), carried as process noise. After a gap its rates are held
        over the gap in increments of its length, with the process noise of what holding them
        may miss (free fall otherwise: it covers only its dt); after more than ``max_imu_gap``
        the IMU was lost and the filter aligns again. Returns None, "bridged" or "lost"."""
        interval = t - self.last_increment_t
        self.last_increment_t = t
        self.timing.increment(t, dtheta, dv)
        gap = classify_gap(interval, dt, self.policy.max_imu_gap)
        if self._gyro_azimuth is not None:
            self._integrate_azimuth(t, dtheta, gap)
        if gap == LOST:
            self.report("imu lost: gap in increments beyond max_imu_gap_s, aligning again")
            self.navigator.reset()
        elif gap == BRIDGED:
            self.report("gap in increments: bridged by holding the rates")
            self.navigator.add_bridged_gap(t - interval, t)
        if angle_var or velocity_var:
            # (after a held gap too: the increment is its last step)
            self.navigator.add_bridged_gap(t - dt, t, angle_var, velocity_var)
        if gap == BRIDGED:
            self.navigator.add_imu(*held_increments(t, dtheta, dv, dt, interval))
            return gap
        self.navigator.add_imu(t, dtheta, dv)
        # Zero-velocity updates stand in for the receiver's speed while the filter aligns; once
        # it navigates they would be a risk, not an aid: a moored vessel heaving slowly in
        # waves passes the IMU's stillness test and its fixes do not move (the bundled vessel
        # trial).
        # A filter that started on a still IMU before the fixes confirmed rest gets the
        # updates of that rest once confirmed, also when a heading source aligned it
        # meanwhile: they are the static start's velocity and gyro bias (its levelling took a
        # second of data), which the start could not wait for; they end as the vehicle moves.
        # The rest detector runs without a receiver velocity, and with one while the heading
        # is unknown: its rest stands in for a noisy receiver's speed (SPEED_TELLS_REST), and
        # its still runs measure the velocities' scatter (velocity); otherwise nothing asks it
        # (here or in fix), so it is not fed.
        if self._rest_wanted():
            rest = self._rest.increment(t, dtheta, dv, dt)
            if not self._has_velocity():
                if rest and (not self.navigator.heading_known or self._start_rest):
                    self.navigator.add_measurement(ZeroVelocity(t))
            elif rest and not self._speed_tells_rest() and \
                    not self._speed[0] > MOVING_SIGMAS * self._speed[1]:
                # a still block the fixes confirm as rest, behind a noisy receiver whose speed
                # does not contradict it
                self.navigator.add_measurement(Rest(t))
            if math.isnan(self._rest.still_since):
                self._start_rest = False  # it moved: the start's rest is over
        return None if gap == CONTIGUOUS else gap

    def fix(self, t: float, lat_deg: float, lon_deg: float, h: float, cov: np.ndarray,
            status: int, covariance_known: bool) -> bool:
        """A GNSS position fix at t (s): geodetic degrees, ellipsoidal height (m), its ENU
        covariance (m^2; ``covariance_known`` False when the receiver gave none) and its
        sensor_msgs/NavSatStatus status (-1 no fix ... 2 ground-based augmentation)."""
        if self.use_ranges or self._clock_refuses("gnss/fix", t):
            return self._seen("gnss/fix", t, False)
        if status < 0:
            self.report("gnss/fix without a fix ignored", log=False)
            return self._seen("gnss/fix", t, False)
        cov = np.asarray(cov, float)
        no_altitude = math.isnan(h)
        if no_altitude:  # (its vertical set again at the end, after the variance policy's)
            h, cov = self._height_of_2d_fix(), cov.copy()
            cov[2, :] = cov[:, 2] = 0.0
            cov[2, 2] = NO_ALTITUDE_SIGMA ** 2
        # (the covariance's checks on Python floats: numpy's on a 3 x 3 cost several times more
        # at every fix)
        if not (math.isfinite(lat_deg) and math.isfinite(lon_deg) and math.isfinite(h)
                and all(map(math.isfinite, cov.ravel().tolist()))):
            self.report("non-finite gnss/fix rejected")
            return self._seen("gnss/fix", t, False)
        if not HEIGHT_RANGE[0] <= h <= HEIGHT_RANGE[1]:
            self.report("implausible gnss/fix altitude rejected")
            return self._seen("gnss/fix", t, False)
        if lat_deg == 0.0 and lon_deg == 0.0:
            # The zeros a driver leaves in a fix it flags valid before its receiver has one
            # (no vehicle is at 0 N 0 E to the last bit): the filter started there and took
            # the real fixes for a jump (a simulated drive with 20 s of them: 14 valid nav/fix
            # of 535, the alignment's yaw 53 sigma off).
            self.report("gnss/fix at 0 N 0 E rejected (a driver's placeholder)")
            return self._seen("gnss/fix", t, False)
        assumed = not covariance_known or _unknown(cov)
        reported_var = None if assumed else \
            max(0.5 * float(cov[0, 0] + cov[1, 1]), self.policy.position_sigma_floor ** 2)
        refuted = not assumed and self._fix_covariance_refuted(status)
        first_refuted = refuted and status not in self._refuted_statuses
        if refuted:
            self._refuted_statuses.add(status)
        if assumed or refuted:
            sigma = UNKNOWN_FIX_SIGMA[min(status, 2)]
            cov = np.diag([sigma ** 2, sigma ** 2, (2.0 * sigma) ** 2])
            why = "without covariance" if assumed else \
                "covariance refuted by the fixes' own scatter"
            self.report(f"gnss/fix {why}: {sigma:g} m assumed from its status, weighted by the "
                        "fixes' measured fix-to-fix noise", log=False)
        cov = _floored(cov, self.policy.position_sigma_floor)
        lat, lon = math.radians(lat_deg), math.radians(lon_deg)
        if self.datum is None:
            self.datum = (lat, lon, h)
        on_test = self._fix_covariance_on_test(t, status, reported_var)
        self._note_scatter(t, status, reported_var, self._course.observe(t, lat, lon, h))
        east, north, _ = to_map(self.datum, lat, lon, h).tolist()
        self.timing.fix(t, east, north)
        self.navigator.note_imu_rates_wrong(self.timing.verdict().rates_wrong)
        horizontal_var = 0.5 * float(cov[0, 0] + cov[1, 1])  # per axis, m^2
        self._velocity_check.fix(t, east, north, math.sqrt(horizontal_var))
        common_var = (0.0, 0.0)
        if horizontal_var >= SHARED_ERROR_SIGMA ** 2:
            # A single-point-level sigma, assumed or the receiver's, is its absolute accuracy,
            # mostly an error the fixes share (slow: atmosphere, orbits); only their white part
            # is news from fix to fix. The filter follows the fixes with that (nav/course.py
            # measures it) and the shared part stays in the published covariance
            # (GnssFix.common_var): taken as white, a receiver's honest 2.3 m averaged down to
            # a published 0.1 m over a simulated drive with 1.9 m of slow error (NEES 290).
            white = _floored(self._course.fix_to_fix(cov), self.policy.position_sigma_floor)
            share = float(white[0, 0] + white[1, 1]) / (2.0 * horizontal_var)
            if self._averaged_white_share(t, share) < WHITE_SHARE:
                # The vertical's white share is taken as the horizontal's (the same errors
                # shared and white, in the receiver's vertical to horizontal ratio): the fixes'
                # heights also carry the vehicle's climb, which hides their own noise.
                vertical = max(share * float(cov[2, 2]), self.policy.position_sigma_floor ** 2)
                common_var = (horizontal_var - 0.5 * float(white[0, 0] + white[1, 1]),
                              float(cov[2, 2]) - vertical)
                white[2, 2] = vertical
                cov = white
        at_rest = self._rest_wanted() and self._rest.fix(
            t, lat, lon, h, self._course.fix_to_fix(cov),
            (horizontal_var, float(cov[2, 2]) + common_var[1]))
        if self._without_velocity_before_start():
            if at_rest:
                self.navigator.add_measurement(ZeroVelocity(t))  # levels as a static start
            elif self._rest.imu_still(t):
                # Levelling and the gyro bias need only the IMU's stillness: start now, with
                # the velocity unknown until the fixes confirm rest.
                self.navigator.add_measurement(StillImu(t))
                self._start_rest = True
            elif self._rest.undecided and t - self._held_since(t) < REST_DECISION_S:
                self.report("gnss/fix held: telling rest from motion before levelling",
                            log=False)
                return self._seen("gnss/fix", t, True)
        if no_altitude:
            cov[2, 2], common_var = NO_ALTITUDE_SIGMA ** 2, (common_var[0], 0.0)
            self.report("gnss/fix without altitude (NaN, a 2-D fix): the height left to the INS",
                        log=False)
        self.navigator.add_measurement(GnssFix(t, lat, lon, h, cov, common_var,
                                               height_known=not no_altitude,
                                               stamp_sigma=self._stamp_sigma("gnss/fix", t),
                                               refutes_covariance=first_refuted))
        if not on_test:
            self._course_velocity(t, lat, lon, h, cov)
        return self._seen("gnss/fix", t, True)

    def _note_scatter(self, t: float, status: int, reported_var: float | None,
                      observed: tuple | None) -> None:
        """A fix at t (s) of this status and reported horizontal variance per axis (m^2, None:
        none reported) with the second difference it ends (CourseFromFixes.observe: the stamp
        of its first fix and the difference, or None): the last fix's difference is judged now,
        this one's at the next fix."""
        pending, self._pending_difference = self._pending_difference, None
        if pending is not None:
            self._add_scatter(*pending)
        previous, self._last_second_difference = self._last_second_difference, None
        if observed is None or reported_var is None:
            return
        t0, second = observed
        third = None
        if self._third_measures(0.5 * (t - t0), t, reported_var):
            self._last_second_difference = (status, second)
            if previous is not None and previous[0] == status:
                third = second - previous[1]
        self._pending_difference = (status, reported_var, t0, t, second, third)

    def _third_measures(self, dt: float, t: float, reported_var: float) -> bool:
        """A third difference of fixes dt (s) apart ending at t (s) is their noise alone: the
        IMU was still (the vehicle's acceleration constant) or the motion leaves them the
        noise (_jerk_below_noise; reported_var per axis, m^2)."""
        return _jerk_below_noise(dt, reported_var) or \
            (self._rest_wanted() and self._rest.blocks_still(t))

    def _fix_covariance_on_test(self, t: float, status: int, reported_var: float | None) -> bool:
        """The covariance a fix at t (s) of this status reports (its horizontal variance per
        axis, m^2, None: none) waits for the fixes' scatter, which a course from it must not
        precede: one of the recording's first FIXES_TO_TEST, too few of their differences yet
        (WhiteNoise's MIN_SCATTER_SAMPLES), and their interval lets third differences measure
        it in motion (_jerk_below_noise; at the first fix, not known yet). A standstill's fixes
        make no course, and where their third differences measure only at rest, the course
        made of them at the start of the motion is as before."""
        noise = self._fix_scatter.get(status)
        if reported_var is None or (noise is not None and noise.variance() is not None):
            return False
        stats = self.inputs.get("gnss/fix")
        return stats is None or (stats.received < FIXES_TO_TEST and
                                 _jerk_below_noise(t - stats.last_t, reported_var))

    def _add_scatter(self, status: int, reported_var: float, t0: float, t2: float,
                     second: np.ndarray, third: np.ndarray | None) -> None:
        """One difference of the fixes' noise alone, in units of their reported variance: the
        second difference of the fixes t0 .. t2 (s) less dt (v2 - v0) / 2 (dt = (t2 - t0) / 2,
        the receiver's velocities at its ends: the acceleration's part) where the motion's
        snap leaves the noise (_snap_below_noise), else the third difference
        (_third_measures)."""
        dt = 0.5 * (t2 - t0)
        ends = self._velocity_at(t0), self._velocity_at(t2)
        if None not in ends and _snap_below_noise(dt, reported_var):
            (v0, var0), (v2, var2) = ends
            difference = second - 0.5 * dt * (v2 - v0)
            gain = 6.0 * reported_var + 0.25 * dt * dt * (var0 + var2)
        elif third is not None:
            difference, gain = third, 20.0 * reported_var
        else:
            return
        self._fix_scatter.setdefault(status, WhiteNoise()).add(difference, gain)

    def _velocity_at(self, t: float):
        """The gnss/vel stamped t (s, to 1 ms) as (east and north, m/s; its horizontal variance
        per axis, m^2/s^2), or None."""
        return next(((v, var) for stamp, v, var in reversed(self._recent_velocities)
                     if abs(stamp - t) < 1e-3), None)

    def _fix_covariance_refuted(self, status: int) -> bool:
        """The fixes of this status scattered more than COVARIANCE_REFUTED times the horizontal
        sigma they report (floored): a driver's placeholder."""
        noise = self._fix_scatter.get(status)
        ratio = None if noise is None else noise.variance()
        return ratio is not None and ratio > COVARIANCE_REFUTED ** 2

    def _height_of_2d_fix(self) -> float:
        """The height given a fix without one: the solution's, or before it the first fix's
        (0 m if it had none either)."""
        nav = self.navigator.solution if self.navigator.started else None
        if nav is not None:
            return float(nav.h)
        return self.datum[2] if self.datum is not None else 0.0

    def _averaged_white_share(self, t: float, share: float) -> float:
        """The fixes' white share (of their reported variance) averaged over
        ``SHARE_TIME_CONSTANT`` s up to this fix's at t (s): the split into white and shared is
        the receiver's, not one fix's (a single-point receiver's fix reported a tenth below its
        neighbours crossed WHITE_SHARE and was taken whole, publishing no shared error for it:
        sigma 3.2 -> 0.07 m, position NEES 4,270 there)."""
        if self._white_share is not None:
            t0, mean = self._white_share
            gain = 1.0 - math.exp(-max(t - t0, 0.0) / SHARE_TIME_CONSTANT)
            share = mean + gain * (share - mean)
        self._white_share = (t, share)
        return share

    def _held_since(self, t: float) -> float:
        """Stamp of the first fix held for the rest detector (t if this is it), s."""
        if math.isnan(self._first_held_t):
            self._first_held_t = t
        return self._first_held_t

    def _rest_wanted(self) -> bool:
        """The rest detector is fed: without a receiver velocity, or while the heading is
        unknown (the filter uses GNSS then only at rest, and a receiver too noisy to tell it
        leaves rest to the detector)."""
        return not self._has_velocity() or not self.navigator.heading_known

    def _speed_tells_rest(self) -> bool:
        """The last receiver speed's sigma lets static_speed tell rest (SPEED_TELLS_REST)."""
        return not self._speed[1] > SPEED_TELLS_REST * self.navigator.config.static_speed

    def _without_velocity_before_start(self) -> bool:
        """No gnss/vel so far and the filter not yet levelled: the first fixes wait for the
        rest detector's IMU verdict, so that a static start takes its gyro bias from the
        stationary mean (the navigator's levelling) as with a receiver that gives its speed
        (also with a heading source: a turn-on bias of degrees per second left to the filter
        tilts the levelled INS faster than fixes at rest correct it)."""
        return not self._has_velocity() and not self.navigator.started

    def _course_velocity(self, t: float, lat: float, lon: float, h: float,
                         cov: np.ndarray) -> None:
        """Without any gnss/vel and before the heading is known, successive fixes give the
        velocity that aligns the heading (nav/course.py), or checks one not yet confirmed
        (Navigator.heading_unconfirmed: a heading source aligned it, or the gyros' bias may
        hold a turn). The run of fixes (for a vehicle too slow for the chord) starts again where
        the INS's yaw was turned (aligned, or forgotten); made while a heading source under
        check steers that yaw, it only checks it (the run of a car starting off refuted a
        NED-convention AHRS and re-aligned the heading on its own course, 8 deg off: 26 valid
        fixes beyond 5 sigma after it). It runs on through what the fixes take for rest
        (restarted there, a robot at 0.5 m/s with 1 m fixes aligned 47 s into its motion
        instead of 13 s)."""
        nav = self.navigator
        if self._has_velocity() or (nav.heading_known and not nav.heading_unconfirmed):
            self._course.clear()
            return
        heading = (nav.heading_known, nav.heading_by)
        if heading != self._course_heading:
            self._course.restart_run()
            self._course_heading = heading
        yaw, rate_sigma, tilt_sigma, scale_sigma = None, 0.0, 0.0, 0.0  # (None: no run kept)
        if nav.started:
            yaw, rate_sigma = yaw_of_x(nav.attitude_at(t)), nav.yaw_rate_sigma()
            tilt_sigma, scale_sigma = nav.tilt_sigma(), nav.yaw_scale_sigma()
        velocity = self._course.add(t, lat, lon, h, cov, yaw, rate_sigma,
                                    yaw_checked=nav.heading_unconfirmed,
                                    tilt_sigma=tilt_sigma, scale_sigma=scale_sigma,
                                    min_speed=nav.config.align_speed)
        if velocity is not None:
            self.navigator.add_measurement(velocity)

    def velocity(self, t: float, v_enu: np.ndarray, cov: np.ndarray) -> bool:
        """A GNSS velocity (m/s, ENU) stamped t (s) with its covariance (m^2/s^2)."""
        if self.use_ranges or self._clock_refuses("gnss/vel", t):
            return self._seen("gnss/vel", t, False)
        if not (np.isfinite(v_enu).all() and np.isfinite(cov).all()):
            self.report("non-finite gnss/vel rejected")
            return self._seen("gnss/vel", t, False)
        if np.linalg.norm(v_enu) > MAX_SPEED:
            self.report("implausible gnss/vel rejected")
            return self._seen("gnss/vel", t, False)
        check = self._velocity_check
        check.velocity(t, float(v_enu[0]), float(v_enu[1]))
        self._stats("gnss/vel", t).problem = check.problem()
        if check.disagrees:
            self.report("gnss/vel refused: it disagrees with the fixes' displacement")
            return self._seen("gnss/vel", t, False)
        if self._rest_wanted():
            self._rest.velocity(t, float(v_enu[0]), float(v_enu[1]))
        scatter = self._rest.velocity_noise()  # NaN until measured
        if _unknown(cov):
            sigma = max(UNKNOWN_VELOCITY_SIGMA, scatter)
            cov = np.diag([sigma ** 2, sigma ** 2, (2.0 * sigma) ** 2])
            self.report(f"gnss/vel without covariance: {UNKNOWN_VELOCITY_SIGMA:g} m/s assumed, "
                        "or its scatter while the IMU is still", log=False)
        sigma = math.sqrt(0.5 * float(cov[0, 0] + cov[1, 1]))  # per horizontal axis
        if scatter > COVARIANCE_REFUTED * sigma:
            cov, sigma = cov * (scatter / sigma) ** 2, scatter
            self.report("gnss/vel covariance refuted by its scatter while the IMU is still: "
                        "scaled to it", log=False)
        self._speed = (math.hypot(v_enu[0], v_enu[1]), sigma)
        # While the IMU is still (rest, or steady straight motion; its still runs restart as
        # the block means drift, hence the hold) a speed may be noise with a random course:
        # the heading is aligned on it only once the course is known beyond the receiver's
        # noise measured there, or, until it is, beyond any receiver's. A vessel under way
        # at 10 m/s in waves, its IMU still by blocks, waited 12 s unaided for the noise
        # (docs/results/product_path.md, "2026-12-07 (session 47)").
        aligns = t - self._rest.still_until > REST_HOLD or course_is_known(
            v_enu, _floored(cov, RECEIVER_NOISE_BOUND) if math.isnan(scatter) else cov)
        cov = _floored(cov, self.policy.velocity_sigma_floor)
        self._recent_velocities.append((t, np.array(v_enu[:2], float),
                                        0.5 * float(cov[0, 0] + cov[1, 1])))
        self.navigator.add_measurement(
            GnssVelocity(t - self.policy.velocity_delay, v_enu, cov, aligns=aligns,
                         stamp_sigma=self._stamp_sigma("gnss/vel", t)))
        return self._seen("gnss/vel", t, True)

    def heading(self, t: float, azimuth: float, variance: float, declination: float | None,
                source: str = "gnss/heading") -> bool:
        """An azimuth of the body x axis (rad, clockwise from north) at t (s) with its variance
        (rad^2) from ``source`` (a key of :data:`HEADING_SOURCES`: which bias state it has).
        ``declination`` (rad) refers an azimuth from magnetic north to true north (None:
        already true)."""
        if self._clock_refuses(source, t):
            return self._seen(source, t, False)
        if declination is not None and not math.isfinite(declination):
            declination = self._declination(t)
        if declination is not None:
            azimuth = azimuth + declination
        if not (math.isfinite(azimuth) and math.isfinite(variance) and variance > 0.0):
            self.report(f"{source} without a finite azimuth, declination and variance rejected")
            return self._seen(source, t, False)
        self._against_gyros(source, t, float(azimuth))
        refuted = self.navigator.refuted_headings.get(HEADING_SOURCES[source])
        if refuted is not None:
            self.report(f"{source} refused: {refuted}")
            return self._seen(source, t, False)
        if source == "gnss/heading" and self.policy.phase_differences and \
                self.navigator.heading_known:
            self.report("gnss/heading not fused: its phase double differences are", log=False)
            return self._seen(source, t, False)
        if HEADING_SOURCES[source] is not None:
            variance = self._correlated_variance(source, t, float(variance))
        field = self._field_direction(t) if source == "mag/heading" and \
            self.policy.magnetic_levelled_by_ins else None
        self.navigator.add_measurement(HeadingFix(t, float(azimuth), float(variance),
                                                  bias=HEADING_SOURCES[source], field_enu=field))
        return self._seen(source, t, True)

    def _field_direction(self, t: float) -> tuple | None:
        """The WMM field's direction (ENU) at the solution's position (the datum before it
        starts) at t (s), for a compass levelled with the INS's roll and pitch; None without
        a position or outside the model. The compass's reported variance keeps the share of
        the tilt sigma this filter reported: counted twice with the tilt columns, it only
        weighs the compass less while the tilt is uncertain."""
        nav = self.navigator.solution
        at = (nav.lat, nav.lon, nav.h) if nav is not None else self.datum
        if at is None:
            return None
        try:
            field = self._wmm(*at, decimal_year(t)).enu
        except ValueError:  # outside the model's life span
            return None
        return tuple(field.tolist())

    def _against_gyros(self, source: str, t: float, azimuth: float) -> None:
        """Take a heading reading at t (s) against the azimuth the gyros integrate from the
        first heading reading on, once the increments reach its stamp (readings ahead of them
        wait, older ones than the increments kept are left out): into its source's error
        correlation (nav/heading_noise.py, a source with a bias of its own) and its turns
        (nav/heading_turns.py). A source found to turn against the gyros is refuted
        (HeadingRefuted: its readings refused from then on, the heading they may have aligned
        or steered aligned anew, on the course or another source)."""
        solution = self.navigator.solution
        if solution is not None:
            self._up_row = tuple(quat_to_dcm(solution.q_nb)[2].tolist())
        if self._gyro_azimuth is None:
            self._gyro_azimuth = ([], [])
        stamps = self._gyro_azimuth[0]
        waiting = self._awaiting_gyros
        waiting.append((source, t, azimuth))
        while waiting and stamps and waiting[0][1] <= stamps[-1]:
            name, t_reading, reading = waiting.popleft()
            gyro = self._gyro_at(t_reading)
            if gyro is None:
                continue
            if HEADING_SOURCES[name] is not None:
                self._heading_noise(name).add(t_reading, reading - gyro)
            turns = self.heading_turns.get(name)
            if turns is None:
                turns = self.heading_turns[name] = HeadingTurns()
            if not turns.against and turns.add(t_reading, reading, gyro):
                self.report(f"{name} {turns.summary()}: refused from now on, aligning again")
                self.navigator.add_measurement(
                    HeadingRefuted(t_reading, HEADING_SOURCES[name], turns.summary()))

    def _heading_noise(self, source: str) -> HeadingNoise:
        noise = self.heading_noise.get(source)
        if noise is None:
            noise = self.heading_noise[source] = HeadingNoise()
        return noise

    def _correlated_variance(self, source: str, t: float, variance: float) -> float:
        """The variance to fuse a biased source's heading at t (s) with: the reported one
        raised to what the source's readings have been measured to carry
        (nav/heading_noise.py); the reading that aligns the heading has its reported variance
        (one reading, nothing averaged)."""
        effective = self._heading_noise(source).variance(t, variance)
        if not self.navigator.heading_known:
            return variance
        if effective > variance:
            self.report(f"{source}: variance raised for its errors' time correlation",
                        log=False)
        return effective

    def _integrate_azimuth(self, t: float, dtheta: np.ndarray, gap: str) -> None:
        """The gyros' azimuth at the end of this increment (a gap or a lost IMU starts it
        again: the heading errors are not differenced across it)."""
        stamps, azimuths = self._gyro_azimuth
        if gap != CONTIGUOUS or not stamps:
            stamps.clear()
            azimuths.clear()
            for noise in self.heading_noise.values():
                noise.restart()
            for turns in self.heading_turns.values():
                turns.restart()
            previous = 0.0
        else:
            previous = azimuths[-1]
        r = self._up_row
        d = dtheta.tolist()
        # azimuth is clockwise, the body rotation's up component counter-clockwise
        stamps.append(t)
        azimuths.append(previous - (r[0] * d[0] + r[1] * d[1] + r[2] * d[2]))
        old = bisect.bisect_left(stamps, t - self.policy.max_delay)
        if old > len(stamps) // 2:
            del stamps[:old], azimuths[:old]

    def _gyro_at(self, t: float) -> float | None:
        """The gyros' azimuth at t (s), interpolated; None outside the kept increments."""
        stamps, azimuths = self._gyro_azimuth
        i = bisect.bisect_left(stamps, t)
        if i == 0 or i == len(stamps):
            return None
        t0, t1 = stamps[i - 1], stamps[i]
        return azimuths[i - 1] + (azimuths[i] - azimuths[i - 1]) * (t - t0) / (t1 - t0)

    def phase_differences(self, t: float, baseline_b: np.ndarray, geometry: np.ndarray,
                          value: np.ndarray, cov: np.ndarray) -> bool:
        """Fixed carrier-phase double differences at t (s): per row the antenna baseline
        (body FLU, m), the line-of-sight difference (ENU), the value (m); their covariance
        (m^2, symmetric positive definite)."""
        if self._clock_refuses("gnss/phase_dd", t):
            return self._seen("gnss/phase_dd", t, False)
        n = len(value)
        ok = n > 0 and np.shape(baseline_b) == (n, 3) and np.shape(geometry) == (n, 3) and \
            np.shape(cov) == (n, n) and np.isfinite(baseline_b).all() and \
            np.isfinite(geometry).all() and np.isfinite(value).all() and np.isfinite(cov).all()
        if ok:
            try:
                np.linalg.cholesky(cov)
            except np.linalg.LinAlgError:
                ok = False
        if not ok:
            self.report("gnss/phase_dd without finite rows and a positive definite covariance "
                        "rejected")
            return self._seen("gnss/phase_dd", t, False)
        self.navigator.add_measurement(PhaseDifferences(t, baseline_b, geometry, value, cov))
        return self._seen("gnss/phase_dd", t, True)

    def _declination(self, t: float) -> float:
        """The WMM declination at the datum (the first fix) for a magnetic azimuth whose
        publisher did not know it, rad; NaN before the first fix or outside the model."""
        if self.datum is None:
            return math.nan
        if self._wmm_declination is None:
            try:
                self._wmm_declination = field_elements(*self.datum, decimal_year(t)).declination
            except ValueError:  # outside the model's life span
                self._wmm_declination = math.nan
        return self._wmm_declination

    def speed_log(self, t: float, speed: float, variance: float) -> bool:
        """A water speed along body x (m/s) at t (s) with its variance (m^2/s^2)."""
        if self._clock_refuses("log/speed", t):
            return self._seen("log/speed", t, False)
        if not (np.isfinite(speed) and np.isfinite(variance) and variance > 0.0):
            self.report("log/speed without a finite speed and variance rejected")
            return self._seen("log/speed", t, False)
        self.navigator.add_measurement(SpeedLog(t, speed, variance))
        return self._seen("log/speed", t, True)

    # -- wheel odometry ----------------------------------------------------------------------
    def wheel_odometry(self, t: float, velocity_b: np.ndarray, variance: np.ndarray) -> bool:
        """A wheel odometry twist at t (s): the velocity of its reference point in body axes
        (m/s; forward from the wheels, lateral and vertical as the wheels allow them) and its
        per-axis variances ((m/s)^2; a non-positive or non-finite one is replaced by the
        policy's sigma). A zero forward speed is a zero-velocity update instead. Slip and skid
        are left to the navigator's gate (the wheels then disagree with the INS)."""
        policy = self.policy.wheel
        velocity_b = np.asarray(velocity_b, float)
        if self._clock_refuses("wheel/odom", t):
            return self._seen("wheel/odom", t, False)
        if not np.isfinite(velocity_b[0]):
            self.report("wheel/odom without a finite forward speed rejected")
            return self._seen("wheel/odom", t, False)
        epoch = t - policy.delay
        still = policy.zero_speed > 0.0 and abs(velocity_b[0]) <= policy.zero_speed
        self.wheel_still_since = min(self.wheel_still_since, t) if still else math.inf
        if still and t - self.wheel_still_since >= policy.zero_time:
            self.navigator.add_measurement(ZeroVelocity(epoch, policy.zero_sigma))
            return self._seen("wheel/odom", t, True)
        variance = np.asarray(variance, float)
        default = np.where(np.array(policy.sigma) > 0.0, np.square(policy.sigma), np.inf)
        variance = np.where(np.isfinite(variance) & (variance > 0.0), variance, default)
        lateral = np.isfinite(velocity_b[1:])  # a component not given is the constraint's zero
        velocity_b = np.concatenate([velocity_b[:1], np.where(lateral, velocity_b[1:], 0.0)])
        self.navigator.add_measurement(WheelOdometry(epoch, velocity_b, variance))
        return self._seen("wheel/odom", t, True)

    def choose_ranges(self, usable_satellites: int) -> bool:
        """Whether this observation epoch's ranges aid the filter in place of fix and velocity
        (and the following fixes and velocities are ignored until an epoch says otherwise).
        Ranges need a known heading: before it the filter aligns on fix and velocity."""
        policy = self.policy
        self.use_ranges = policy.coupling != "loose" and self.navigator.heading_known and (
            policy.coupling == "tight" or usable_satellites < policy.min_satellites)
        return self.use_ranges

    def ranges(self, ranges) -> bool:
        """An epoch's satellite ranges (:class:`SatelliteRanges`, or None: no usable satellite)."""
        if ranges is None:
            self.report("observation epoch without a usable satellite", log=False)
            return False
        self.navigator.add_measurement(ranges)
        return True
