"""Whether an accelerometer stream is the specific force in m/s^2, gravity included, in
base_link's axes.

A strapdown INS integrates the specific force with gravity in it, in m/s^2 (sensor_msgs/Imu,
REP-145). Drivers that publish the acceleration in g, or with gravity removed (a "linear" or
"free" acceleration), give a stream that passes every per-sample check and makes every solution
wrong: the filter then only forces its GNSS updates in, and nothing says why. Over any stretch of
a vehicle's motion the magnitude of the specific force averages to about gravity's (a car's
accelerations are a few m/s^2 and mostly brief; a coordinated turn at 45 deg bank is 1.41 g);
in g it averages about 1, without gravity a vehicle's accelerations (on the bundled car drive
with a constant gravity vector taken out: 0.1-2.5 m/s^2 per 10 s, the two not told apart).

Its direction says whether the increments are in base_link's axes (REP-103: x forward, y left,
z up). Over such a stretch the mean specific force of a ship, a car or a ground robot points
along base_link's z within the slope, the list and the held accelerations (0.7 g of braking
for 10 s: 35 deg), and an aircraft's stays along z in coordinated turns. An IMU whose driver
keeps the sensor's FRD axes (NED convention), or one mounted upside down or on its side
without ``mounting_rpy_deg``, passes every other check: the filter navigates, and publishes
the attitude of the sensor's axes as base_link's (on a simulated car with the IMU's y and z
negated: the position as good as with FLU, roll 180 deg, and every node said "ok"). An
accelerometer with gravity down points the same way; only a turn tells it from an IMU upside
down (nav/imu_timing.py).
"""
from __future__ import annotations

import math

#: Standard gravity, m/s^2: the unit of an accelerometer that reads in g.
G = 9.80665
#: Length of each judged stretch, s of increments.
WINDOW_S = 10.0
#: Mean specific-force magnitude of a stream in m/s^2 with gravity, in units of G.
PLAUSIBLE = (0.5, 2.0)
#: Largest angle of the mean specific force from base_link's z axis (up) over a stretch, deg.
UPRIGHT_MAX_DEG = 60.0
#: Names of base_link's axes, for the direction of a mean specific force far from up.
_AXES = ("+x (forward)", "+y (left)", "+z (up)", "-x (backward)", "-y (right)", "-z (down)")


class SpecificForceCheck:
    """Judges the increments' specific force over successive :data:`WINDOW_S` stretches.

    Attributes
    ----------
    mean_norm : float
        Mean magnitude of the specific force over the last complete stretch, m/s^2 (NaN before
        one).
    mean : tuple of 3 float
        Mean specific force over that stretch, base_link, m/s^2 (NaN before one).
    """

    def __init__(self):
        self._norm = 0.0
        self._sum = [0.0, 0.0, 0.0]
        self._time = 0.0
        self.mean_norm = math.nan
        self.mean = (math.nan,) * 3

    def add(self, dv, dt: float) -> bool:
        """An increment's velocity change dv (m/s, body) over dt (s); True when it completes a
        stretch (:meth:`problem` may have changed)."""
        x, y, z = dv
        self._norm += math.sqrt(x * x + y * y + z * z)
        total = self._sum
        total[0] += x
        total[1] += y
        total[2] += z
        self._time += dt
        if self._time < WINDOW_S:
            return False
        self.mean_norm = self._norm / self._time
        self.mean = tuple(c / self._time for c in total)
        self._norm = self._time = 0.0
        self._sum = [0.0, 0.0, 0.0]
        return True

    def problem(self) -> str | None:
        """What is wrong with the last stretch, for /diagnostics; None if it looks right (or
        none is complete yet)."""
        norm = self.mean_norm
        if math.isnan(norm):
            return None
        if not PLAUSIBLE[0] <= norm / G <= PLAUSIBLE[1]:
            seen = (f"linear_acceleration averages {norm:.2f} m/s^2 in magnitude over "
                    f"{WINDOW_S:g} s (gravity: {G:.2f})")
            if norm < PLAUSIBLE[0] * G:
                return seen + ": in g, or with gravity removed (a linear or free " \
                    "acceleration)? The INS needs the specific force in m/s^2 (sensor_msgs/Imu, " \
                    "REP-145)"
            return seen + ": check its units and scale"
        return self._tilt_problem()

    def _tilt_problem(self) -> str | None:
        """The mean specific force far from base_link's up, or None."""
        length = math.sqrt(sum(c * c for c in self.mean))
        if length == 0.0:
            return None
        from_up = math.degrees(math.acos(max(-1.0, min(1.0, self.mean[2] / length))))
        if from_up <= UPRIGHT_MAX_DEG:
            return None
        axis = max(range(6), key=lambda k: (1.0 if k < 3 else -1.0) * self.mean[k % 3])
        seen = (f"the specific force over {WINDOW_S:g} s points along {_AXES[axis]}, "
                f"{from_up:.0f} deg from up (base_link is x forward, y left, z up: REP-103)")
        if axis == 5:
            return seen + ": an IMU in FRD axes (NED convention) or mounted upside down (set " \
                "imu_preprocessor mounting_rpy_deg; FRD: [180, 0, 0]), or linear_acceleration " \
                "with gravity down instead of the specific force (REP-145)?"
        return seen + ": an IMU mounted on its side, or axes other than FLU? Set " \
                      "imu_preprocessor mounting_rpy_deg"
