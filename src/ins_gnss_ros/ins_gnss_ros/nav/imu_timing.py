"""The IMU's clock against GNSS time, checked on turns: the gyros' turn against the course's.

IMU stamps that are s off GNSS time (a driver stamping on arrival, a log mapped onto GNSS time by
its start and end) put every turn the gyros measure s early or late against the fixes, and an
INS aided by those fixes errs by about the speed times the turn rate times s in every turn (on
the bundled car drive a 75 ms error gave 0.3-0.5 m/s within a second of a sharp turn). Groves
("Principles of GNSS, Inertial, and Multisensor Integrated Navigation Systems", 2nd ed., section
14.1.5) treats such an offset as a filter state; this module measures it outside the filter, from
two quantities that need no attitude: the rotation of the vehicle about the vertical (the gyro
increments projected on the mean specific force, which is gravity whatever the mounting) and the
turn of its course over ground (the fixes).

For fixes p_(j-1), p_j, p_(j+1) the chord p_(j+1) - p_(j-1) points along the course at t_j to
second order; the course turns by c_(j+1) - c_(j-1) between t_(j-1) and t_(j+1), and the IMU's
rotation over the same GNSS-time interval is Y(t_(j+1) - s) - Y(t_(j-1) - s) on its own stamps
(Y the accumulated vertical rotation; the stamps plus s are GNSS time, the sign of the
imu_preprocessor's ``time_offset_s``). Summed squared differences over every such pair give, on
a grid of candidate offsets, the one that fits; its sigma follows from the residual scatter and
the yaw-rate changes that carry the information (linearised least squares:
sigma^2 = residual variance / sum((w(t_(j+1)) - w(t_(j-1)))^2)).

The gyros' bias about the vertical turns the IMU by b (t_(j+1) - t_(j-1)) over each pair, which
no course turn has: both fits take it out, as a term in the pair's duration fitted with them
(a consumer unit's 5 deg/s, uncorrected here, read as a scale of 1.4 from 1 Hz fixes and
flagged the rates wrong; docs/results/product_path.md, "2026-12-08 (session 48)").

The same pairs give the gyros' scale, 1 for rates in rad/s and 57.3 for a driver publishing deg/s:
at the offset where the two turn together best (largest correlation of either sign), the IMU
turns' sum of squares over their products with the course turns (the inverse of the slope of the
course turns on the IMU's, so that the fixes' noise, which is in the course turns, does not bias
it; on a ship in waves it outweighs the few real turns many times). Not at the offset of least
squared difference, which assumes the scale: with rates of the wrong sign or 57 x too large that
is where the IMU turns least (the car drive with gravity down waited 638 course changes for its
verdict). Where the scale lies beyond SCALE_RANGE by SCALE_SIGMAS standard deviations of that
slope, the summary says so instead of an offset (which assumes the scale): a scale of fewer
turns is noise (1.30 after 24 course changes of 1 Hz fixes, on a simulated drive with exact
gyros). A negative scale, the IMU turning against the course, is an "up" that points down: an
accelerometer publishing acceleration (gravity down) instead of specific force, or axes that
are not right-handed.

A check, not a correction (the offset is ambiguous between the two clocks, and applying it would
move the solution onto the other one mid-run): the ekf's /diagnostics names what it finds
(:class:`Verdict`), and the navigator stops flagging a solution valid on rates it finds wrong
(``Navigator.note_imu_rates_wrong``). Over a long run the check also follows the offset of the
last DRIFT_WINDOW_S and tells when it has moved (:meth:`ImuTimingCheck.drift`: an IMU clock
drifting against GNSS time), without judging it. The course is that of the antenna, and a wheeled
vehicle's antenna ahead of its rear axle slips sideways in proportion to the turn rate, which
leads the course by about (distance to the axle) / speed; on the car drive the fitted offset
was the same within 20 ms at 3-5 m/s and at 10-14 m/s. A ship's drift angle in a turn would
bias it more. Only fixes above MIN_SPEED (the course is defined) and equally spaced ones are
used.
"""
from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass

import numpy as np

#: Candidate offsets, s: the IMU stamps plus the offset are GNSS time.
OFFSETS = np.round(np.arange(-0.5, 0.5 + 1e-9, 0.005), 3)
#: Least speed over the three fixes of a course, m/s.
MIN_SPEED = 3.0
#: Fixes farther apart than this ratio of the median spacing break the sequence.
SPACING_TOLERANCE = 0.2
#: An estimate is reported once its sigma is below this, s.
REPORT_SIGMA = 0.02
#: IMU history kept, s: a course change spans two fix intervals (2 s with 1 Hz fixes), and the
#: candidate offsets reach half a second beyond either end.
HISTORY_S = 4.0
#: Least spacing of the stored rotation samples, s (linear interpolation between them is exact
#: to a fraction of a millirad for a car's turns; a 1 kHz IMU does not need every sample kept).
SAMPLE_S = 0.005
#: Interval over which the turn rate at either end of a course change is taken, s.
RATE_STEP_S = 0.01
#: An offset within this (or 3 sigma) is "in step", s: a 10 ms error moves a car in a sharp turn
#: by centimetres.
IN_STEP_S = 0.01
#: Gyro scale (IMU turn over course turn) beyond which the rates' units are reported as wrong: a
#: wheeled vehicle's side slip and a ship's drift change the course's turns by far less.
SCALE_RANGE = (0.8, 1.25)
#: Standard deviations of the slope of the course's turns on the IMU's by which it must lie
#: beyond 1 / SCALE_RANGE for a verdict on the rates.
SCALE_SIGMAS = 3.0
#: IMU turns over the course changes (sum of squares, rad^2) a scale verdict needs.
MIN_TURN_SQ = 1.0
#: Least correlation (either sign) of the IMU's turns with the course's for a scale verdict:
#: fixes noisy against their chords (single-point fixes 1.2 m apart at 5 Hz) make course turns
#: of noise, and a scale of them (1.46 on such a simulated drive) says nothing of the gyros.
MIN_CORRELATION = 0.5
#: Time constant of the recent offset's forgetting, s; the first recent offset and a later one
#: at least twice that apart can tell a drift: an IMU stamped by counting its samples at the
#: nominal rate runs its crystal's error against GNSS time (tens to hundreds of ppm, 10-100 ms
#: over ten minutes), which no constant time_offset_s holds.
DRIFT_WINDOW_S = 120.0
#: Least change of the recent offset (besides 3 sigma) reported as a drift, s.
DRIFT_STEP_S = 0.02


@dataclass(frozen=True)
class Verdict:
    """What the turns show of the IMU so far.

    Attributes
    ----------
    summary : str
        For /diagnostics.
    rates_wrong : bool
        The IMU's rates in other units, of the wrong sign or scale: no solution on them is a fix.
    stamps_off : bool
        The IMU's stamps off GNSS time, and the filter's time-offset state does not take it.
    """

    summary: str
    rates_wrong: bool = False
    stamps_off: bool = False

    @property
    def problem(self) -> bool:
        """Whether the IMU's rates or stamps are wrong (the ekf's /diagnostics is then WARN)."""
        return self.rates_wrong or self.stamps_off


class ImuTimingCheck:
    """Accumulates increments and fixes; :meth:`estimate` gives the offset that fits best."""

    def __init__(self, gnss_latency_state: bool = False):
        # The filter estimates a GNSS latency (its "td" state): fixes stamped after the IMU's
        # clock are taken there, not a defect of the IMU's stamps.
        self.gnss_latency_state = gnss_latency_state
        self._imu = deque()                 # (t, accumulated vertical rotation, rad)
        self._rotation = 0.0
        self._specific_force = [0.0, 0.0, 0.0]  # summed dv: its direction is the body's up
        self._fixes = deque(maxlen=3)       # (t, east, north), m
        self._courses = deque(maxlen=3)     # (t, course rad)
        self._pending = deque()             # (t0, t1, course change) waiting for the IMU
        # The offset's sums over the whole run and forgetting over DRIFT_WINDOW_S, and the
        # first and the latest offset the latter gave within REPORT_SIGMA: (their pairs' mean
        # time s, offset s, sigma s).
        self._run = _OffsetSums()
        self._recent = _OffsetSums(DRIFT_WINDOW_S)
        self._first_recent = self._latest_recent = None
        # The scale's sums over the pairs, per candidate offset where the IMU's turn enters:
        # pair duration T (s), course turn c, IMU turn y (rad).
        self._turn_products = np.zeros(len(OFFSETS))  # c y
        self._imu_turn_sq = np.zeros(len(OFFSETS))    # y^2
        self._imu_turn_time = np.zeros(len(OFFSETS))  # y T
        self._course_turn_sq = 0.0                    # c^2
        self._course_turn_time = 0.0                  # c T
        self.pairs = 0
        self._verdict = (-1, None)  # (pairs, Verdict): the sums change with the pairs only

    def increment(self, t: float, dtheta: np.ndarray, dv: np.ndarray) -> None:
        """An IMU increment ending at t (s, the IMU's stamps)."""
        # Plain floats: this runs for every increment, where numpy's per-call cost on
        # 3-vectors would be most of the check's.
        f = self._specific_force
        dvx, dvy, dvz = dv.tolist()
        f[0] += dvx
        f[1] += dvy
        f[2] += dvz
        norm = math.sqrt(f[0] * f[0] + f[1] * f[1] + f[2] * f[2])
        if norm == 0.0:
            return
        wx, wy, wz = dtheta.tolist()
        self._rotation += (wx * f[0] + wy * f[1] + wz * f[2]) / norm
        if self._imu and t - self._imu[-1][0] < SAMPLE_S:
            return
        self._imu.append((t, self._rotation))
        while self._imu[0][0] < t - HISTORY_S:
            self._imu.popleft()
        while self._pending and self._pending[0][1] + OFFSETS[-1] + RATE_STEP_S <= t:
            self._compare(*self._pending.popleft())

    def fix(self, t: float, east: float, north: float) -> None:
        """A GNSS fix at t (s, GNSS time) in the map frame (m, ``local_frame.to_map``: the
        caller's conversion, shared with its other checks)."""
        if self._fixes and not self._regular(t):
            self._fixes.clear()
            self._courses.clear()
        self._fixes.append((t, east, north))
        if len(self._fixes) < 3:
            return
        (t0, e0, n0), (t1, _, _), (t2, e2, n2) = self._fixes
        speed = math.hypot(e2 - e0, n2 - n0) / (t2 - t0)
        if speed < MIN_SPEED:
            self._courses.clear()
            return
        course = math.atan2(n2 - n0, e2 - e0)
        self._courses.append((t1, course))
        if len(self._courses) == 3:
            (ta, ca), _, (tb, cb) = self._courses
            turn = math.remainder(cb - ca, 2.0 * math.pi)
            self._pending.append((ta, tb, turn))

    def _regular(self, t: float) -> bool:
        """The fix at t continues the equally spaced sequence."""
        times = [f[0] for f in self._fixes]
        spacing = t - times[-1]
        if len(times) < 2:
            return spacing > 0.0
        last = times[-1] - times[-2]
        return abs(spacing - last) <= SPACING_TOLERANCE * last

    def _compare(self, t0: float, t1: float, turn: float) -> None:
        """One course change against the IMU's rotation over [t0 - s, t1 - s] for every s."""
        if not self._imu or self._imu[0][0] > t0 - OFFSETS[-1]:
            return  # the IMU history does not reach back to the interval
        t_imu, y_imu = np.array(self._imu).T
        y0 = np.interp(t0 - OFFSETS, t_imu, y_imu)
        y1 = np.interp(t1 - OFFSETS, t_imu, y_imu)
        duration = t1 - t0
        residual = turn - (y1 - y0)
        # d(residual)/ds = w(t1 - s) - w(t0 - s), from the rotation's slope at each end
        w0 = (np.interp(t0 - OFFSETS + RATE_STEP_S, t_imu, y_imu) - y0) / RATE_STEP_S
        w1 = (np.interp(t1 - OFFSETS + RATE_STEP_S, t_imu, y_imu) - y1) / RATE_STEP_S
        for sums in (self._run, self._recent):
            sums.add(t1, duration, residual, w1 - w0)
        self._turn_products += turn * (y1 - y0)
        self._imu_turn_sq += (y1 - y0) ** 2
        self._imu_turn_time += (y1 - y0) * duration
        self._course_turn_sq += turn * turn
        self._course_turn_time += turn * duration
        self.pairs += 1
        recent = self._recent.fit()
        if recent is not None and recent[1] <= REPORT_SIGMA:
            self._latest_recent = (self._recent.times / self._recent.weight, *recent)
            if self._first_recent is None:
                self._first_recent = self._latest_recent

    def estimate(self) -> tuple[float, float] | None:
        """(offset s, sigma s): the IMU stamps plus the offset are GNSS time; None before any
        turn was seen."""
        return self._run.fit()

    def drift(self) -> tuple[float, float, float] | None:
        """(rate, first offset s, latest offset s) when the recent offset (over the last
        DRIFT_WINDOW_S) has moved by more than DRIFT_STEP_S and 3 sigma since the first one,
        their course changes' mean times at least twice that apart: the IMU's clock runs at
        1 + rate of GNSS time's, and the whole run's offset is a mean of the two. Else None."""
        first, latest = self._first_recent, self._latest_recent
        if first is None or latest[0] - first[0] < 2.0 * DRIFT_WINDOW_S:
            return None
        step = latest[1] - first[1]
        if abs(step) <= max(DRIFT_STEP_S, 3.0 * math.hypot(first[2], latest[2])):
            return None
        return -step / (latest[0] - first[0]), first[1], latest[1]

    def scale(self) -> float | None:
        """The gyros' turn over the course's where the two correlate best (module doc); None
        before the IMU turned by MIN_TURN_SQ over the course changes, or while the two turn
        together by less than MIN_CORRELATION."""
        fit = self._slope()
        return None if fit is None else 1.0 / fit[0]

    def _slope(self) -> tuple[float, float] | None:
        """(slope of the course's turns on the IMU's, its sigma) where the two correlate best,
        both with their parts in the pairs' durations taken out (the gyros' bias); None as
        for :meth:`scale`."""
        time_sq = self._run.time_sq
        if time_sq <= 0.0:
            return None
        # sums of the turns less their least-squares fits in the duration
        imu_sq = self._imu_turn_sq - self._imu_turn_time ** 2 / time_sq
        products = self._turn_products - self._course_turn_time * self._imu_turn_time / time_sq
        course_sq = self._course_turn_sq - self._course_turn_time ** 2 / time_sq
        norms = np.sqrt(np.maximum(imu_sq, 0.0) * max(course_sq, 0.0))
        if not np.any(norms > 0.0):
            return None
        correlation = np.abs(products) / np.where(norms > 0.0, norms, np.inf)
        k = int(np.argmax(correlation))
        if imu_sq[k] < MIN_TURN_SQ or correlation[k] < MIN_CORRELATION:
            return None
        slope = float(products[k] / imu_sq[k])
        residual = max(course_sq - slope * float(products[k]), 0.0)
        return slope, math.sqrt(residual / max(self.pairs - 2, 1) / float(imu_sq[k]))

    def _wrong_scale(self) -> float | None:
        """The scale, where the slope lies SCALE_SIGMAS beyond 1 / SCALE_RANGE; else None."""
        fit = self._slope()
        if fit is None:
            return None
        slope, sigma = fit
        margin = SCALE_SIGMAS * sigma
        if slope + margin < 1.0 / SCALE_RANGE[1] or slope - margin > 1.0 / SCALE_RANGE[0]:
            return 1.0 / slope
        return None

    def verdict(self) -> Verdict:
        """What the turns show so far (asked at every fix and status: kept until a course
        change is added)."""
        if self._verdict[0] != self.pairs:
            self._verdict = (self.pairs, self._judge())
        return self._verdict[1]

    def _judge(self) -> Verdict:
        scale = self._wrong_scale()
        if scale is not None and scale < 0.0:
            return Verdict(f"the gyros turn against the course over ground ({scale:.2f} x, "
                           f"{self.pairs} course changes): linear_acceleration with gravity down "
                           "(an acceleration, not the specific force), or axes not "
                           "right-handed; the time offset is not judged", rates_wrong=True)
        if scale is not None:
            return Verdict(f"the gyros turn {scale:.2f} x the course over ground ({self.pairs} "
                           "course changes): angular_velocity in deg/s (57.3 x), or its scale "
                           "or mounting wrong; the time offset is not judged", rates_wrong=True)
        est = self.estimate()
        if est is None or est[1] > REPORT_SIGMA:
            return Verdict(f"needs turns above {MIN_SPEED:g} m/s: {self.pairs} course changes "
                           "so far" + ("" if est is None
                                       else f", {1e3 * est[0]:+.0f} +- {1e3 * est[1]:.0f} ms"))
        offset, sigma = est
        off = abs(offset) > max(3.0 * sigma, IN_STEP_S)
        if not off:
            verdict = "in step"
        elif offset > 0.0 and self.gnss_latency_state:
            verdict, off = ("the fixes are stamped after the IMU's clock (on arrival?): the "
                            "filter's time-offset state takes it"), False
        elif offset > 0.0:
            # A stamp taken on arrival comes after its epoch: the IMU's clock is the likelier
            # to be right, and the filter's state keeps the solution on it.
            verdict = ("the fixes are stamped after the IMU's clock (on arrival?): set the "
                       "ekf's time_offset_sigma_s (0.1-0.2), or imu_preprocessor time_offset_s")
        else:
            verdict = "the IMU stamps are off GNSS time: add it to imu_preprocessor time_offset_s"
        drift = self.drift()
        if drift is not None:
            # Told, not judged: a change in how the course leads the heading (an antenna far
            # ahead of the axle at changing speeds, a ship's drift) would move it too, and on
            # the bundled car drive (+286 ppm, +10 -> -95 ms) taking it for the clock's did
            # not help (product_path.md, "2026-12-05 morning").
            rate, first, latest = drift
            verdict += (f"; the offset moved from {1e3 * first:+.0f} to {1e3 * latest:+.0f} ms "
                        f"over the run ({1e6 * rate:+.0f} ppm if the IMU's clock drifts against "
                        "GNSS time: an IMU stamped by counting its samples at the nominal rate)")
        return Verdict(f"{1e3 * offset:+.0f} +- {1e3 * sigma:.0f} ms from {self.pairs} course "
                       f"changes (gyro turn vs course over ground): {verdict}",
                       stamps_off=off)


class _OffsetSums:
    """What the offset's fit needs of the course changes, per candidate offset where the IMU's
    turn enters, each sum forgotten over ``memory`` s (inf: the whole run): the residuals r
    (course turn less IMU turn, rad) squared and times the pair's duration T, the changes of
    d r / d s squared, T^2, the pairs' weight and their ends' weighted sum (s)."""

    def __init__(self, memory: float = math.inf):
        self.memory = memory
        self.t_last = -math.inf
        self.cost = np.zeros(len(OFFSETS))           # r^2
        self.residual_time = np.zeros(len(OFFSETS))  # r T
        self.rate_change_sq = np.zeros(len(OFFSETS))
        self.time_sq = 0.0
        self.weight = 0.0
        self.times = 0.0

    def add(self, t1: float, duration: float, residual: np.ndarray,
            rate_change: np.ndarray) -> None:
        """One course change ending at t1 (s) of ``duration`` s."""
        keep = 1.0 if math.isinf(self.memory) else \
            math.exp(-max(t1 - self.t_last, 0.0) / self.memory)
        self.t_last = t1
        self.cost = self.cost * keep + residual ** 2
        self.residual_time = self.residual_time * keep + residual * duration
        self.rate_change_sq = self.rate_change_sq * keep + rate_change ** 2
        self.time_sq = self.time_sq * keep + duration * duration
        self.weight = self.weight * keep + 1.0
        self.times = self.times * keep + t1

    def fit(self) -> tuple[float, float] | None:
        """(offset s, sigma s) of the least cost over OFFSETS, the residuals' fit in the
        duration (the gyros' bias) taken out; None before 3 course changes or any turn."""
        if self.weight < 3 or self.time_sq <= 0.0:
            return None
        cost = self.cost - self.residual_time ** 2 / self.time_sq
        k = int(np.argmin(cost))
        if self.rate_change_sq[k] <= 0.0:
            return None
        # Adjacent course changes share a course, so this sigma is somewhat optimistic.
        residual_var = max(float(cost[k]), 0.0) / max(self.weight - 2, 1)
        return float(OFFSETS[k]), math.sqrt(residual_var / self.rate_change_sq[k])
