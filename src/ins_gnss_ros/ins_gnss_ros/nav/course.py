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
"""
from __future__ import annotations

import bisect
from collections import deque

import numpy as np

from .earth import ecef_to_enu_matrix, geodetic_to_ecef
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


class CourseFromFixes:
    """Turns successive fixes into velocities (:class:`GnssVelocity`)."""

    def __init__(self):
        self._window: list[tuple[np.ndarray, GnssFix]] = []  # ECEF, the fix
        self._last3: deque = deque(maxlen=3)                           # t, ECEF
        # (east^2, north^2) of each, Python floats, m^2, and the same values kept sorted: every
        # fix asks for their median, and sorting a hundred values per fix cost more than the
        # rest of a fix's front end (the median of the sorted list is statistics.median's).
        self._second_differences: deque = deque(maxlen=SCATTER_SAMPLES)
        self._sorted: list[float] = []
        self._white = None  # the white variance of the current values, once asked for

    def clear(self) -> None:
        """Forget the fixes of the current window (the heading is known, or a velocity came)."""
        self._window.clear()

    def fix_to_fix(self, cov: np.ndarray) -> np.ndarray:
        """A fix's ENU covariance (m^2) for differences over a few seconds: its horizontal part
        no larger than the white variance the fixes show (once enough of them came)."""
        if len(self._second_differences) < MIN_SCATTER_SAMPLES:
            return cov
        if self._white is None:
            values, n = self._sorted, len(self._sorted)
            median = values[n // 2] if n % 2 else (values[n // 2 - 1] + values[n // 2]) / 2
            self._white = median / CHI2_1_MEDIAN / 6.0
        out = cov.copy()
        out[0, 0] = out[1, 1] = min(self._white, 0.5 * (cov[0, 0] + cov[1, 1]))
        # (a variance: never NaN or negative, as np.eye(2) * it); the white part's covariance
        # with the vertical is not measured, and the given one could leave the matrix
        # indefinite beside the smaller horizontal variance
        out[0, 1] = out[1, 0] = out[0, 2] = out[2, 0] = out[1, 2] = out[2, 1] = 0.0
        return out

    def add(self, t: float, lat: float, lon: float, h: float, cov: np.ndarray):
        """A fix at t (s; rad, rad, m) with its ENU covariance (m^2), already observed
        (:meth:`observe`). Returns the velocity it completes, or None."""
        r = geodetic_to_ecef(lat, lon, h)
        R = ecef_to_enu_matrix(lat, lon)
        self._window = [f for f in self._window if t - f[1].t <= WINDOW_S]
        self._window.append((r, GnssFix(t, lat, lon, h, cov)))
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
        self._window = [self._window[-1]]
        return GnssVelocity(0.5 * (first.t + t), d / dt, cov_v, fixes)

    def observe(self, t: float, lat: float, lon: float, h: float) -> None:
        """Every fix (t s; rad, rad, m), for the fix-to-fix noise of :meth:`fix_to_fix`."""
        r = geodetic_to_ecef(lat, lon, h)
        if self._last3 and (t <= self._last3[-1][0] or np.array_equal(r, self._last3[-1][1])):
            return  # a repeat (duplicated, or republished while frozen) has no noise of its own
        self._last3.append((t, r))
        if len(self._last3) < 3:
            return
        (t0, r0), (t1, r1), (t2, r2) = self._last3
        if abs((t2 - t1) - (t1 - t0)) > 0.1 * (t2 - t0):
            return  # a dropped fix: not equally spaced
        # (the array's dot: the same BLAS product as @, at half the cost on a 3-vector)
        s = ecef_to_enu_matrix(lat, lon).dot(r2 - 2.0 * r1 + r0)[:2]
        pair = tuple((s * s).tolist())
        if len(self._second_differences) == SCATTER_SAMPLES:
            for x in self._second_differences[0]:  # the pair the append below drops
                del self._sorted[bisect.bisect_left(self._sorted, x)]
        self._second_differences.append(pair)
        for x in pair:
            bisect.insort(self._sorted, x)
        self._white = None
