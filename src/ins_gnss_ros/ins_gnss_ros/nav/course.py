"""Course over ground from successive fixes, for a receiver without velocity output.

A receiver that gives only positions (NMEA GGA, many SBAS units) still tells the direction of
motion once the vehicle has moved well beyond the fixes' noise: the displacement between two fixes
over the time between them is a velocity that aligns the heading as the receiver's own would.

What counts as "beyond the noise" is the fix-to-fix noise, not the absolute error: a receiver's
position error is mostly slow (atmosphere, orbits, multipath over tens of seconds) and cancels in a
difference over a second or two, and a fix without covariance is given a generous absolute sigma
(nav/aiding.py). The white part is measured from the fixes themselves: the second difference of
three equally spaced fixes, e_(k+1) - 2 e_k + e_(k-1), has six times the white variance and no
velocity in it (an acceleration a adds a dt^2, so the estimate errs on the large side).

The velocity carries the fixes it was made of (GnssVelocity.fixes): its error is
(e_1 - e_0) / dt, so it is correlated with the first fix's error by -W_0 / dt and with the
last's by W_1 / dt (W the white covariances), and an alignment on it must not take those fixes
for independent news (nav/alignment.py, fixes_with_course).

A vehicle too slow for the chord (a wheeled robot at 1 m/s with 1 m fixes would need 20 m
within two seconds) gets its velocity from a run of fixes instead (:func:`run_velocity`): a
least-squares fit over up to RUN_S seconds in which the gyros carry the direction of motion
(the INS's yaw at each fix, levelled but of any heading; their rate error about the vertical an
unknown of the fit, within its prior) and the speed may change at a constant rate, the velocity
taken at the run's last fix. Its covariance holds what the fit leaves out: a change of
acceleration, and the fixes' slow error, which over tens of seconds no longer cancels. The same
fit serves a car started on the move whose fixes are too noisy for the chord (2 m at 5 Hz: the
chord's ten sigma needs 14 m/s): its gyros' turn-on bias, never measured at rest, is what the
fit's rate error measures.
"""
from __future__ import annotations

import bisect
import functools
from collections import deque
from typing import NamedTuple

import numpy as np
from scipy.optimize import brentq
from scipy.stats import ncx2

from .earth import ecef_to_enu_matrix, geodetic_to_ecef
from .gating import chi2_gate
from .measurement_types import GnssFix, GnssVelocity

#: Two fixes at most WINDOW_S apart whose horizontal displacement exceeds MIN_SIGMAS times its
#: standard deviation give a velocity (applied at the mid-epoch, within the navigator's 3 s
#: history).
WINDOW_S = 2.0
MIN_SIGMAS = 10.0
#: 1σ of the change of horizontal acceleration between two fixes of the window, m/s^2. The
#: chord velocity (p(t) - p(t0)) / dt equals the velocity at the mid-epoch under any constant
#: acceleration; a steady change Δa over dt (constant jerk) leaves Δa dt / 24, a step of Δa at
#: the mid-epoch Δa dt / 8 (the most a monotone change can leave). A car's acceleration
#: changes by up to about 4 m/s^2 within the two seconds (turning in or braking at 0.4 g),
#: taken as 2σ; a wheeled robot's steps of up to ~0.7 m/s^2 (each errs like a steady change
#: three times larger) and a ship's fraction of that lie within it.
ACCELERATION_CHANGE = 2.0
#: Second differences kept for the white-noise estimate, and the fewest that make one.
SCATTER_SAMPLES, MIN_SCATTER_SAMPLES = 50, 10
#: Median of a chi-square variable of one degree of freedom (a robust variance from squares).
CHI2_1_MEDIAN = 0.4549
#: A run of fixes (:func:`run_velocity`): at most RUN_S s long (a robot at 0.5 m/s with 1 m
#: fixes at 2.5 Hz needs about 25 s), of at least MIN_RUN_FIXES (the fit's five unknowns and a
#: few residuals to test it with).
RUN_S, MIN_RUN_FIXES = 30.0, 6
#: Fewest standard deviations of a run's speed (its fit's noise and the slow error) in that
#: speed. The course's sigma, the velocity across the track over the speed, holds only where
#: the speed is known; on a short run the first to pass MAX_COURSE_SIGMA is otherwise one the
#: noise flattered, its speed come out high or the fixes' white variance, from a few second
#: differences yet, low (robots at 1 m/s with a known gyro rate: a run of 6 s released at
#: 1.28 m/s, 22 deg off for a sigma of 4; the squared errors over their variance 2.84 on
#: average at release, 1.19 with it; test_course.py).
MIN_SPEED_SIGMAS = 5.0
#: Largest 1 sigma of the course of a run's velocity [rad], as of a course the heading aligns
#: on with the IMU still (alignment.MAX_STILL_COURSE_SIGMA): released once its speed is known,
#: a run errs as it claims (test_course.py). The chord's ten sigma (4 deg) held a robot at 0.7
#: m/s with 1 m fixes and a consumer unit's unknown gyro rate unaligned for 30 s of straight
#: motion (the fit's own 5 deg after 30 s, the slow error's 0.03 m/s another 2.5) and for 80 s
#: where a turn came first (docs/results/product_path.md, "2026-12-07 (session 41)").
#: A run that only checks a heading (GnssVelocity.checks_only) is released at the chord's
#: sigma: a check wants a course that knows more than the heading it checks (the navigator's
#: CONFIRM_COURSE_SIGMA, 5 deg with the side slip's 3), and a run released short of it would
#: start again from its last fix, never confirming (a robot's AHRS so left unconfirmed, its
#: published position 36 m uncertain after 90 s).
MAX_COURSE_SIGMA, MAX_CHECK_COURSE_SIGMA = 0.2, 1.0 / (MIN_SIGMAS * np.sqrt(2.0))
#: 1 sigma per horizontal axis of the mean rate of the fixes' slow error over a run, m/s: a
#: single-point or SBAS receiver's error wanders by a metre or two over minutes (ionosphere,
#: orbits, multipath of a slow vehicle); over two seconds the chord neglects it, over a run it
#: is as large as the white noise's share of a robot's course.
SLOW_ERROR_RATE = 0.03
#: The fit's residuals beyond this quantile of their chi-square say the motion left the model
#: (a change of acceleration or side slip the covariance does not hold): the run's older half
#: is dropped.
RESIDUAL_QUANTILE = 0.999
#: The probability with which a change of motion counted as seen would be (Baarda's 80 %).
DETECTION_POWER = 0.8


@functools.lru_cache(maxsize=None)
def detectable_noncentrality(dof: int) -> float:
    """The noncentrality of a chi-square of ``dof`` degrees of freedom that the test at
    RESIDUAL_QUANTILE detects with probability DETECTION_POWER."""
    gate = chi2_gate(dof, RESIDUAL_QUANTILE)
    return float(brentq(lambda lam: ncx2.sf(gate, dof, lam) - DETECTION_POWER, 1e-6, 1e4))


def _undetected_steps(moves, a, gain, weight, dof):
    """The size of the largest step of the acceleration at each fix that the residual test
    would miss, at most ACCELERATION_CHANGE (N,): moves (N, M) the fixes' rows moved by a unit
    step at each fix's time, a (M, p) the fit's design, gain (p, M) its gain, weight (M,) its
    rows' weights."""
    unfitted = moves - (moves @ gain.T) @ a.T
    return np.minimum(ACCELERATION_CHANGE, np.sqrt(
        detectable_noncentrality(dof) / np.maximum((unfitted ** 2) @ weight, 1e-300)))


def _worst_step(size, moves, rows, direct):
    """The largest error of the unknowns ``rows`` of the fit (the gain's rows, k of them) that
    the steps of :func:`_undetected_steps` (``size``) leave: direct (N, k) what a unit step at
    each fix does to those unknowns themselves."""
    errors = size[:, None] * (moves @ rows.T + direct)
    return errors[np.argmax(np.linalg.norm(errors, axis=1))]


def _from_each_to_last(f, tau):
    """Integral of the samples f (N, ...) over time from each sample's tau (N,) to the last's
    (trapezoidal): the last is 0."""
    segments = 0.5 * (f[1:] + f[:-1]) * np.diff(tau).reshape((-1,) + (1,) * (f.ndim - 1))
    return np.concatenate([np.cumsum(segments[::-1], axis=0)[::-1], np.zeros_like(f[:1])])


def _turned(ic, js, v):
    """The displacement (N, 2) of the integrals ic, js (N,) of cos and sin of the turn applied
    to the horizontal vector v: the integral of R(theta) v."""
    return np.stack([ic * v[0] - js * v[1], js * v[0] + ic * v[1]], axis=1)


class RunFit(NamedTuple):
    """A run's fit (:func:`run_velocity`)."""

    v: np.ndarray       # (3,) the velocity at the last fix, m/s, ENU
    cov: np.ndarray     # (3, 3) its covariance, (m/s)^2
    gains: np.ndarray   # (N, 3, 3) the derivatives of v with respect to each fix's position
    chi2: float         # the fit's weighted squared residuals
    dof: int            # their degrees of freedom
    rate: tuple | None  # the gyros' rate error about the vertical and its variance (rad/s,
    #                     (rad/s)^2), or None when not fitted
    speed_sigma: float  # 1 sigma of the speed from the fit's noise and the slow error, m/s
    #                     (cov holds more: what the fit leaves out)


def run_velocity(tau, d, yaw, white, vertical_var, yaw_rate_sigma, tilt_sigma=0.0,
                 scale_sigma=0.0):
    """The velocity at the last of a run of fixes, from a fit in which the gyros carry the
    direction of motion, their rate error about the vertical is an unknown and the speed changes
    at a constant rate.

    With theta(t) the INS's yaw at t less its yaw at the last fix, less b (t - t_end) for the
    gyros' rate error b (the velocity turns with the body: a constant side slip), v the velocity
    at the last fix and k the speed's rate of change over the speed, the fixes lie at
    p(t) = p_end - integral from t to t_end of R(theta) (1 + k (t' - t_end)) v dt'
    (Gauss-Newton from the fit without k and b, which is linear). b has the prior
    N(0, yaw_rate_sigma^2): a turn-on bias of degrees per second, never measured at rest by a
    start on the move, turns a run's course by tens of degrees, and the track's curvature
    against the gyros' turn measures it (a straight track the gyros see turning). The vertical
    is a quadratic in time.

    The yaw is the heading only of a levelled body: the azimuth of a body x axis tilted by
    epsilon errs by up to (1 - cos epsilon) / 2 (small epsilon), one way at 45 deg between the
    tilt's axis and the heading and the other way a quarter turn later: over a turn of the
    vehicle the INS's yaw changes by up to (1 - cos epsilon) per radian of it more or less
    than the heading, and by up to 1 - cos epsilon in all. An INS left unaided
    on the move (a start on the move before its heading is known) tilts by what its gyros'
    biases leave, tens of degrees on a consumer unit within a minute, where its turns are no
    longer the vehicle's; the course's covariance takes (1 - cos 2 tilt_sigma) min(turn, 1) as
    two sigma of a course error (a simulated robot with a consumer unit started on the move,
    59 deg of tilt sigma after 41 s, aligned on a course 7.9 deg off for a sigma of 3.9 deg,
    its heading then running off at 7 deg/s with a sigma of 5-8 deg).

    The fitted rate error is the gyros' bias about the vertical that the filter's estimate
    misses: a start on the move learns it nowhere else, and left there the heading of a
    consumer unit's robot aligned on its course ran off at the 5 deg/s its run had measured
    to 0.2 deg/s (docs/results/product_path.md, "2026-12-06 (session 37)"). Its variance holds
    what the fit leaves out as the velocity's does: the worst step of the acceleration the
    residual test would miss (without it a weaving robot's rate errors were twice their sigma,
    test_aiding.py), and what the tilt and the gyros' scale error do to the run's turn, which
    passes for a rate over the run. (Its correlation with the course is left out: the course
    is taken at the last fix, where the rate error has turned nothing yet.)

    Parameters
    ----------
    tau : (N,) ndarray
        The fixes' times less the last's, s (increasing, the last 0).
    d : (N, 3) ndarray
        Their positions, ENU at the last fix, m.
    yaw : (N,) ndarray
        The INS's yaw of the body x axis at each, rad (counter-clockwise; any offset common).
    white, vertical_var : (N,) ndarray
        Their white variance per horizontal axis and their vertical variance, m^2.
    yaw_rate_sigma : float
        1 sigma of the error of the gyros' rate about the vertical, rad/s (0: none, b not
        fitted).
    tilt_sigma : float
        1 sigma of the INS's tilt, rad.
    scale_sigma : float
        1 sigma of the gyros' scale-factor error about the vertical (-).

    Returns
    -------
    RunFit or None
        None for a run without motion.
    """
    n = len(tau)
    turn = np.unwrap(yaw)
    turn = turn - turn[-1]
    fits_rate = yaw_rate_sigma > 0.0
    m = 6 if fits_rate else 5  # p_end (2), v (2), k, b
    # the rows: each fix's east, then its north; b's prior last
    weight = np.repeat(1.0 / white, 2)
    y = d[:, :2].reshape(-1)
    if fits_rate:
        weight, y = np.append(weight, yaw_rate_sigma ** -2), np.append(y, 0.0)

    def integrals(b):
        """The integrals from each fix to the last of cos and sin of the turn for the rate
        error b (ic, js), times t' (jc, jt) and times t'^2 (kc, kt)."""
        theta = turn - b * tau
        c, s = np.cos(theta), np.sin(theta)
        return [_from_each_to_last(f, tau) for f in (c, s, tau * c, tau * s,
                                                     tau * tau * c, tau * tau * s)]

    def design(x):
        """The model's rows and their derivatives (rows, m) at x."""
        v, k = x[2:4], x[4]
        ic, js, jc, jt, kc, kt = integrals(x[5] if fits_rate else 0.0)
        cos_part, sin_part = ic + k * jc, js + k * jt
        a = np.zeros((len(y), m))
        rows = a[:2 * n].reshape(n, 2, m)
        rows[:, 0, 0] = rows[:, 1, 1] = 1.0
        rows[:, :, 2] = -_turned(cos_part, sin_part, (1.0, 0.0))
        rows[:, :, 3] = -_turned(cos_part, sin_part, (0.0, 1.0))
        rows[:, :, 4] = -_turned(jc, jt, v)
        model = np.zeros(len(y))
        model[:2 * n] = (x[:2] + rows[:, :, 2:4] @ v).reshape(-1)
        if fits_rate:  # d theta / d b = -t': the rows turn by the integral of t' (1 + k t')
            rows[:, :, 5] = _turned(jc + k * kc, jt + k * kt, (-v[1], v[0]))
            a[-1, 5], model[-1] = 1.0, x[5]
        return model, a

    def solve(a, r):
        normal = np.linalg.inv(a.T @ (a * weight[:, None]))
        gain = normal @ (a * weight[:, None]).T
        return gain @ r, normal, gain

    # without the acceleration and the rate error the model is linear; Gauss-Newton from
    # there (a few steps: the speed's rate of change is small against the speed over a run the
    # fixes can follow, and the rate error's turn over it a fraction of a radian)
    x = np.zeros(m)
    _, a = design(x)
    x[:4] = solve(a[:, :4], y)[0]
    for _ in range(6):
        if x[2] == 0.0 and x[3] == 0.0:
            return None
        model, a = design(x)
        x = x + solve(a, y - model)[0]
    u = x[2:4] / np.hypot(x[2], x[3])
    model, a = design(x)
    residual = y - model
    _, normal, gain = solve(a, residual)
    chi2 = float(residual @ (weight * residual))
    cov = normal[2:4, 2:4] + SLOW_ERROR_RATE ** 2 * np.eye(2)
    speed_sigma = float(np.sqrt(u @ cov @ u))
    # vertical: p_end + v tau + a tau^2 / 2
    a_up = np.stack([np.ones(n), tau, 0.5 * tau * tau], axis=1)
    w_up = 1.0 / vertical_var
    normal_up = np.linalg.inv(a_up.T @ (a_up * w_up[:, None]))
    gain_up = normal_up @ (a_up * w_up[:, None]).T
    residual_up = d[:, 2] - a_up @ (gain_up @ d[:, 2])
    chi2 += float(residual_up @ (w_up * residual_up))
    dof = 3 * n - 8
    # What the fit leaves out: the worst single step of the acceleration along the track. A
    # step of Δa in the speed's rate at t_k moves the last velocity by -Δa t_k u and each
    # fix, relative to the last, by the integral from it (or from t_k) to t_end of
    # -Δa (t - t_k) R(theta) u. Its size is ACCELERATION_CHANGE, or the largest the residual
    # test misses (Baarda's minimal detectable bias: the step whose residuals reach the test's
    # detectable noncentrality), whichever is smaller: over a long run the speed at its end is
    # uncertain by what such steps could hide (its course is not: they move the fixes along
    # the track).
    ic, js, jc, jt, _, _ = integrals(x[5] if fits_rate else 0.0)
    later = np.maximum(np.arange(n)[None, :], np.arange(n)[:, None])  # (step at k, fix i)
    moves = np.zeros((n, len(y)))  # (b's prior row not moved)
    moves[:, :2 * n] = -_turned((jc[later] - tau[:, None] * ic[later]).reshape(-1),
                                (jt[later] - tau[:, None] * js[later]).reshape(-1),
                                u).reshape(n, 2 * n)
    step = 0.5 * np.clip(tau[None, :] - tau[:, None], 0.0, None) ** 2  # the vertical's
    size = _undetected_steps(moves, a, gain, weight, dof)
    worst = _worst_step(size, moves, gain[2:4], np.outer(tau, u))
    worst_up = _worst_step(_undetected_steps(step, a_up, gain_up, w_up, dof), step,
                           gain_up[1:2], tau[:, None])
    cov += np.outer(worst, worst)
    largest_turn = float(np.abs(turn).max())
    turn_error = 0.5 * (1.0 - np.cos(2.0 * tilt_sigma)) * min(largest_turn, 1.0)
    across = np.array([-u[1], u[0]])
    cov += (turn_error * np.hypot(x[2], x[3])) ** 2 * np.outer(across, across)
    rate = None
    if fits_rate:
        worst_rate = _worst_step(size, moves, gain[5:6], np.zeros((n, 1)))[0]
        rate = (float(x[5]), float(normal[5, 5] + worst_rate ** 2 + (
            (turn_error + scale_sigma * largest_turn) / -tau[0]) ** 2))
    v = np.array([x[2], x[3], gain_up[1] @ d[:, 2]])
    full = np.zeros((3, 3))
    full[:2, :2] = cov
    full[2, 2] = normal_up[1, 1] + worst_up[0] ** 2
    gains = np.zeros((n, 3, 3))
    gains[:, :2, 0], gains[:, :2, 1] = gain[2:4, 0:2 * n:2].T, gain[2:4, 1:2 * n:2].T
    gains[:, 2, 2] = gain_up[1]
    return RunFit(v, full, gains, chi2, dof, rate, speed_sigma)


class WhiteNoise:
    """The fixes' white variance per horizontal axis from their differences: the median of the
    last SCATTER_SAMPLES squared east and north components, each over its difference's gain,
    over the chi-square median, which the few large ones of a vehicle's accelerations among
    them do not move. The gain is the difference's variance over the fixes' (six for a second
    difference r2 - 2 r1 + r0 of equally spaced fixes, twenty for a third difference); given in
    the fixes' reported variance as well, the estimate is their scatter in units of it."""

    def __init__(self):
        # (east^2, north^2) / gain of each, Python floats, and the same values kept sorted:
        # every fix asks for their median, and sorting a hundred values per fix cost more than
        # the rest of a fix's front end (the median of the sorted list is statistics.median's).
        self._differences: deque = deque(maxlen=SCATTER_SAMPLES)
        self._sorted: list[float] = []
        self._white = None  # the white variance of the current values, once asked for

    def add(self, difference: np.ndarray, gain: float = 6.0) -> None:
        """One difference of the fixes (east, north, m) whose variance is ``gain`` times
        theirs."""
        if len(self._differences) == SCATTER_SAMPLES:
            for x in self._differences[0]:  # the pair the append below drops
                del self._sorted[bisect.bisect_left(self._sorted, x)]
        pair = tuple((difference * difference / gain).tolist())
        self._differences.append(pair)
        for x in pair:
            bisect.insort(self._sorted, x)
        self._white = None

    def variance(self) -> float | None:
        """The white variance per horizontal axis, or None before MIN_SCATTER_SAMPLES."""
        if len(self._differences) < MIN_SCATTER_SAMPLES:
            return None
        if self._white is None:
            values, n = self._sorted, len(self._sorted)
            median = values[n // 2] if n % 2 else (values[n // 2 - 1] + values[n // 2]) / 2
            self._white = median / CHI2_1_MEDIAN
        return self._white


class CourseFromFixes:
    """Turns successive fixes into velocities (:class:`GnssVelocity`)."""

    def __init__(self):
        self._window: list[tuple[np.ndarray, GnssFix]] = []  # ECEF, the fix
        self._run: list[tuple[np.ndarray, float, GnssFix]] = []  # ECEF, the INS's yaw, the fix
        self._last3: deque = deque(maxlen=3)                           # t, ECEF
        self._noise = WhiteNoise()

    def clear(self) -> None:
        """Forget the fixes of the current window and run (the heading is known, or a velocity
        came)."""
        self._window.clear()
        self._run.clear()

    def fix_to_fix(self, cov: np.ndarray) -> np.ndarray:
        """A fix's ENU covariance (m^2) for differences over a few seconds: its horizontal part
        no larger than the white variance the fixes show (once enough of them came)."""
        white = self._noise.variance()
        if white is None:
            return cov
        out = cov.copy()
        out[0, 0] = out[1, 1] = min(white, 0.5 * (cov[0, 0] + cov[1, 1]))
        # (a variance: never NaN or negative, as np.eye(2) * it); the white part's covariance
        # with the vertical is not measured, and the given one could leave the matrix
        # indefinite beside the smaller horizontal variance
        out[0, 1] = out[1, 0] = out[0, 2] = out[2, 0] = out[1, 2] = out[2, 1] = 0.0
        return out

    def restart_run(self) -> None:
        """Forget the run: the INS's yaw was turned (aligned, or forgotten), its yaws before and
        after not in one frame."""
        self._run.clear()

    def add(self, t: float, lat: float, lon: float, h: float, cov: np.ndarray,
            yaw: float | None = None, yaw_rate_sigma: float = 0.0, yaw_checked: bool = False,
            tilt_sigma: float = 0.0, scale_sigma: float = 0.0, min_speed: float = 0.0):
        """A fix at t (s; rad, rad, m) with its ENU covariance (m^2), already observed
        (:meth:`observe`), and the INS's yaw of the body x axis then (rad, counter-clockwise;
        None before the INS is levelled: no run is kept) with the sigma of its gyros' rate
        error about the vertical (rad/s), of their scale-factor error there (-) and of its
        tilt (rad); ``yaw_checked``: a heading source under check steers that yaw (a run's
        velocity then only checks it: GnssVelocity.checks_only); ``min_speed``: the speed
        (m/s) below which the navigator takes no course, a run's velocity slower than it not
        released (the run would start again from its last fix: a robot starting off from rest
        aligned 2 s later). Returns the velocity it completes (of the chord, else of the run),
        or None."""
        r = geodetic_to_ecef(lat, lon, h)
        R = ecef_to_enu_matrix(lat, lon)
        fix = GnssFix(t, lat, lon, h, cov)
        if yaw is None:
            self._run.clear()
        else:
            self._run = [f for f in self._run if t - f[2].t <= RUN_S]
            self._run.append((r, yaw, fix))
        velocity = self._chord(r, R, fix)
        if velocity is None and len(self._run) >= MIN_RUN_FIXES:
            velocity = self._run_velocity(R, yaw_rate_sigma, tilt_sigma, scale_sigma,
                                          yaw_checked, min_speed)
        if velocity is not None:  # the next velocity of fixes not in this one
            self._window, self._run = self._window[-1:], self._run[-1:]
        return velocity

    def _chord(self, r: np.ndarray, R: np.ndarray, fix: GnssFix):
        """The velocity of the window's first and this fix (ECEF r, at whose ENU axes R), once
        beyond MIN_SIGMAS of their white noise."""
        t, cov = fix.t, fix.cov_enu
        self._window = [f for f in self._window if t - f[1].t <= WINDOW_S]
        self._window.append((r, fix))
        r0, first = self._window[0]
        dt = t - first.t
        if dt <= 0.0:
            return None
        d = R.dot(r - r0)  # (the array's dot: the same BLAS product as @, at half the cost)
        white0, white1 = self.fix_to_fix(first.cov_enu), self.fix_to_fix(cov)
        cov_d = white0 + white1
        if np.hypot(d[0], d[1]) < MIN_SIGMAS * np.sqrt(cov_d[0, 0] + cov_d[1, 1]):
            return None
        cov_v = cov_d / dt ** 2 \
            + np.diag([1.0, 1.0, 0.0]) * (ACCELERATION_CHANGE * dt / 24.0) ** 2
        # The fixes between the two ends are in the window too: not in the velocity, but news
        # the alignment can use (the filter refused them while the heading was unknown).
        cross = [np.zeros((3, 3))] * len(self._window)
        cross[0], cross[-1] = -white0 / dt, white1 / dt
        fixes = tuple(zip((f for _, f in self._window), cross))
        return GnssVelocity(0.5 * (first.t + t), d / dt, cov_v, fixes)

    def _run_velocity(self, R: np.ndarray, yaw_rate_sigma: float, tilt_sigma: float,
                      scale_sigma: float, checks_only: bool, min_speed: float):
        """The velocity of the run at its last fix (:func:`run_velocity`, ENU axes R there),
        once its speed is known to MIN_SPEED_SIGMAS and at least min_speed, and its course
        known to MAX_COURSE_SIGMA (MAX_CHECK_COURSE_SIGMA where it only checks); a run the fit
        does not hold loses its older half."""
        run = self._run
        r_end, last = run[-1][0], run[-1][2]
        tau = np.array([f.t - last.t for _, _, f in run])
        d = (np.array([r for r, _, _ in run]) - r_end) @ R.T
        white = [self.fix_to_fix(f.cov_enu) for _, _, f in run]
        fit = run_velocity(tau, d, np.array([yaw for _, yaw, _ in run]),
                           np.array([w[0, 0] for w in white]), np.array([w[2, 2] for w in white]),
                           yaw_rate_sigma, tilt_sigma, scale_sigma)
        if fit is None:
            return None
        v, cov, gains, chi2, dof, rate, speed_sigma = fit
        if chi2 > chi2_gate(dof, RESIDUAL_QUANTILE):
            del run[:len(run) // 2]
            return None
        across, speed2 = np.array([-v[1], v[0]]), v[0] ** 2 + v[1] ** 2
        cap = MAX_CHECK_COURSE_SIGMA if checks_only else MAX_COURSE_SIGMA
        if speed2 < max(MIN_SPEED_SIGMAS * speed_sigma, min_speed) ** 2 or \
                across @ cov[:2, :2] @ across > (cap * speed2) ** 2:
            return None
        # the fixes within the chord's window, the navigator's to take after the alignment
        fixes = tuple((f, gain @ w) for (_, _, f), gain, w in zip(run, gains, white)
                      if last.t - f.t <= WINDOW_S)
        return GnssVelocity(last.t, v, cov, fixes, checks_only=checks_only, rate_error=rate)

    def observe(self, t: float, lat: float, lon: float, h: float) -> tuple | None:
        """Every fix (t s; rad, rad, m), for the fix-to-fix noise of :meth:`fix_to_fix`.
        Returns the stamp of the first fix of the second difference it ends and that
        difference (east, north, m), or None (no two fixes before it equally spaced)."""
        r = geodetic_to_ecef(lat, lon, h)
        if self._last3 and (t <= self._last3[-1][0] or np.array_equal(r, self._last3[-1][1])):
            return None  # a repeat (duplicated, or republished while frozen) has no noise
        self._last3.append((t, r))
        if len(self._last3) < 3:
            return None
        (t0, r0), (t1, r1), (t2, r2) = self._last3
        if abs((t2 - t1) - (t1 - t0)) > 0.1 * (t2 - t0):
            return None  # a dropped fix: not equally spaced
        # (the array's dot: the same BLAS product as @, at half the cost on a 3-vector)
        s = ecef_to_enu_matrix(lat, lon).dot(r2 - 2.0 * r1 + r0)[:2]
        self._noise.add(s)
        return t0, s
