"""Whether an accelerometer stream is the specific force in m/s^2, gravity included.

A strapdown INS integrates the specific force with gravity in it, in m/s^2 (sensor_msgs/Imu,
REP-145). Drivers that publish the acceleration in g, or with gravity removed (a "linear" or
"free" acceleration), give a stream that passes every per-sample check and makes every solution
wrong: the filter then only forces its GNSS updates in, and nothing says why. Over any stretch of
a vehicle's motion the magnitude of the specific force averages to about gravity's (a car's
accelerations are a few m/s^2 and mostly brief; a coordinated turn at 45 deg bank is 1.41 g);
in g it averages about 1, without gravity a vehicle's accelerations (on the bundled car drive
with a constant gravity vector taken out: 0.1-2.5 m/s^2 per 10 s, the two not told apart).
"""
from __future__ import annotations

import math

#: Standard gravity, m/s^2: the unit of an accelerometer that reads in g.
G = 9.80665
#: Length of each judged stretch, s of increments.
WINDOW_S = 10.0
#: Mean specific-force magnitude of a stream in m/s^2 with gravity, in units of G.
PLAUSIBLE = (0.5, 2.0)


class SpecificForceCheck:
    """Judges the increments' specific force over successive :data:`WINDOW_S` stretches.

    Attributes
    ----------
    mean_norm : float
        Mean magnitude of the specific force over the last complete stretch, m/s^2 (NaN before
        one).
    """

    def __init__(self):
        self._norm = 0.0
        self._time = 0.0
        self.mean_norm = math.nan

    def add(self, dv, dt: float) -> bool:
        """An increment's velocity change dv (m/s, body) over dt (s); True when it completes a
        stretch (:meth:`problem` may have changed)."""
        x, y, z = dv
        self._norm += math.sqrt(x * x + y * y + z * z)
        self._time += dt
        if self._time < WINDOW_S:
            return False
        self.mean_norm = self._norm / self._time
        self._norm = self._time = 0.0
        return True

    def problem(self) -> str | None:
        """What is wrong with the last stretch, for /diagnostics; None if it looks right (or
        none is complete yet)."""
        norm = self.mean_norm
        if math.isnan(norm) or PLAUSIBLE[0] <= norm / G <= PLAUSIBLE[1]:
            return None
        seen = (f"linear_acceleration averages {norm:.2f} m/s^2 in magnitude over "
                f"{WINDOW_S:g} s (gravity: {G:.2f})")
        if norm < PLAUSIBLE[0] * G:
            return seen + ": in g, or with gravity removed (a linear or free acceleration)? " \
                          "The INS needs the specific force in m/s^2 (sensor_msgs/Imu, REP-145)"
        return seen + ": check its units and scale"
