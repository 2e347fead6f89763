"""Whether the receiver's velocity agrees with its own fixes' displacement.

``gnss/vel`` is the antenna's velocity in ENU (the contract). A driver that publishes it in NED
(x north, y east, z down) or in the vehicle's axes passes every per-message check, and the filter
then takes a wrong heading from it and forces it in (the car drive with its gnss/vel turned into
NED: NAVIGATING at times with 13 m/s velocity errors). Integrated over a few seconds, a right
velocity reproduces the displacement between the fixes at either end, to the fixes' noise over
the distance driven: a single-point fix's metres make a per-epoch comparison useless, one over
WINDOW_S at driving speed is not. The horizontal mismatch |integral - displacement| / |displacement|
of the last few windows decides; the same with east and north swapped says whether NED fits.
"""
from __future__ import annotations

import math
from collections import deque
from statistics import median

#: Shortest time between the fixes that end a window, s.
WINDOW_S = 5.0
#: Least horizontal displacement of a window, m, and in units of the fixes' horizontal sigma.
MIN_DISPLACEMENT_M, MIN_DISPLACEMENT_SIGMAS = 20.0, 10.0
#: Most a window's velocities may leave uncovered at either end, s.
MAX_UNCOVERED_S = 0.5
#: Windows judged together, and the fewest that give a verdict.
WINDOWS, MIN_WINDOWS = 5, 3
#: Median mismatch beyond which the velocity disagrees, and within which a swapped one fits.
DISAGREE, FITS = 0.5, 0.2


class VelocityAgreement:
    """Compares the integral of the velocity readings with the fixes' displacement.

    Attributes
    ----------
    disagrees : bool
        The last :data:`WINDOWS` windows' median mismatch is beyond :data:`DISAGREE`.
    """

    def __init__(self):
        self._start = None           # (t, east, north) of the fix that opened the window
        self._integral = [0.0, 0.0]  # east, north, m, from the first velocity in the window
        self._covered = None         # (first, last) velocity stamp of the window, s
        self._last_velocity = None   # (t, east, north) m/s
        self._mismatch = deque(maxlen=WINDOWS)
        self._swapped = deque(maxlen=WINDOWS)
        self.disagrees = False

    def velocity(self, t: float, v_east: float, v_north: float) -> None:
        """A velocity reading at t (s), ENU as published, m/s."""
        last = self._last_velocity
        self._last_velocity = (t, v_east, v_north)
        if self._start is None or t < self._start[0] - MAX_UNCOVERED_S:
            return
        if self._covered is None:
            self._covered = (t, t)
            return
        dt = t - last[0]
        if dt > 2.0 * MAX_UNCOVERED_S:  # a gap in the velocities: this window is not judged
            self._covered = (math.inf, t)
            return
        self._integral[0] += 0.5 * (last[1] + v_east) * dt   # trapezoid
        self._integral[1] += 0.5 * (last[2] + v_north) * dt
        self._covered = (self._covered[0], t)

    def fix(self, t: float, east: float, north: float, sigma_h: float) -> None:
        """A fix at t (s) in a local plane (m) with its horizontal sigma (m)."""
        start, covered = self._start, self._covered
        if start is not None and t - start[0] < WINDOW_S:
            return
        if start is not None and covered is not None and \
                covered[0] - start[0] <= MAX_UNCOVERED_S and t - covered[1] <= MAX_UNCOVERED_S:
            d_east, d_north = east - start[1], north - start[2]
            distance = math.hypot(d_east, d_north)
            if distance >= max(MIN_DISPLACEMENT_M, MIN_DISPLACEMENT_SIGMAS * sigma_h):
                i_east, i_north = self._integral
                self._mismatch.append(math.hypot(i_east - d_east, i_north - d_north) / distance)
                self._swapped.append(math.hypot(i_north - d_east, i_east - d_north) / distance)
                if len(self._mismatch) >= MIN_WINDOWS:
                    self.disagrees = median(self._mismatch) > DISAGREE
        # The window integrates from the velocity of this fix's epoch when it came first.
        last = self._last_velocity
        near = last is not None and abs(t - last[0]) <= MAX_UNCOVERED_S
        self._start, self._integral = (t, east, north), [0.0, 0.0]
        self._covered = (last[0], last[0]) if near else None

    def problem(self) -> str | None:
        """Why the velocity is refused, for /diagnostics after the input's name; None while it
        agrees."""
        if not self.disagrees:
            return None
        seen = (f"integrated over {WINDOW_S:g} s misses the fixes' displacement by "
                f"{100 * median(self._mismatch):.0f} % (median of {len(self._mismatch)})")
        if median(self._swapped) <= FITS:
            return seen + ": it fits with east and north swapped: published in NED? The " \
                          "contract's gnss/vel is ENU"
        return seen + ": not ENU (the vehicle's axes? NED?), or not this receiver's"
