"""IMU increments on their way into a mechanisation: plausibility, sensor-error compensation, gaps.

Every consumer of ``imu/delta`` (the strapdown, the filter) and the IMU preprocessor that makes
it go through this one module, so that an increment is judged, compensated and bridged the same
way wherever it is integrated.

* :func:`increment_problem`: why an increment cannot be integrated (non-finite, dt <= 0, beyond
  any IMU).
* :class:`SensorErrors`: the running sensor-error estimates the filter feeds back (bias and
  scale factor per triad, base_link FLU) and their removal, ``measured = (1 + s) true + b``.
* :func:`classify_gap` and :func:`held_increments`: an increment that follows a gap in the
  stream either bridges it, its rates held over the gap in steps of its own length, or says the
  IMU was lost (beyond ``max_gap``), after which the consumer starts again.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from functools import cached_property

import numpy as np

__all__ = ["MAX_RATE", "MAX_SPECIFIC_FORCE", "SENSOR_BLOCKS", "SensorErrors", "classify_gap",
           "held_increments", "increment_problem", "CONTIGUOUS", "BRIDGED", "LOST"]

#: Bounds of a physically possible increment: angular rate (rad/s, ~5700 deg/s) and specific
#: force (m/s^2, ~1000 g), far beyond any navigation IMU's range. A value past them is a corrupt
#: message: integrated, it would wreck the state and the filter's covariance (a 1e12 rad
#: increment made the ekf's innovation covariance non-positive-definite).
MAX_RATE, MAX_SPECIFIC_FORCE = 100.0, 1e4


def increment_problem(dtheta, dv, dt: float) -> str | None:
    """Why an increment cannot be integrated (non-finite, non-positive dt, beyond MAX_RATE or
    MAX_SPECIFIC_FORCE), or None.

    Parameters
    ----------
    dtheta, dv : sequence of 3 float
        Angle (rad) and velocity (m/s) increment, body frame.
    dt : float
        Its interval, s.
    """
    # Plain floats: this runs on every increment of every consumer.
    ax, ay, az = dtheta
    vx, vy, vz = dv
    if not (math.isfinite(dt) and dt > 0.0
            and all(map(math.isfinite, (ax, ay, az, vx, vy, vz)))):
        return "non-finite or non-positive increment dropped"
    if (math.sqrt(ax * ax + ay * ay + az * az) > MAX_RATE * dt
            or math.sqrt(vx * vx + vy * vy + vz * vz) > MAX_SPECIFIC_FORCE * dt):
        return "implausible increment dropped"
    return None


def _zeros():
    return np.zeros(3)


#: SensorErrors fields and the filter blocks (error_model.py names) whose running estimates add
#: up to them.
SENSOR_BLOCKS = {"gyro_bias": ("bg", "gmg"), "accel_bias": ("ba", "gma"),
                 "gyro_scale": ("sg",), "accel_scale": ("sa",)}


@dataclass(frozen=True)
class SensorErrors:
    """Sensor-error estimates of a six-axis IMU in base_link (FLU).

    Model, per axis: measured = (1 + scale) true + bias (seed 004 section 2.5: the filter's
    sensor states fed back to the sensor outputs).

    Attributes
    ----------
    gyro_bias : (3,) rad/s
    accel_bias : (3,) m/s^2
    gyro_scale, accel_scale : (3,) dimensionless
    """

    gyro_bias: np.ndarray = field(default_factory=_zeros)
    accel_bias: np.ndarray = field(default_factory=_zeros)
    gyro_scale: np.ndarray = field(default_factory=_zeros)
    accel_scale: np.ndarray = field(default_factory=_zeros)

    @classmethod
    def of_estimates(cls, estimates: dict) -> "SensorErrors":
        """What the filter's running estimates (by block name, SENSOR_BLOCKS) add up to; zero
        where the layout has none of a field's blocks."""
        values = []
        for blocks in SENSOR_BLOCKS.values():  # the fields' order (a call per filter segment)
            total = None
            for b in blocks:
                if b in estimates:
                    e = estimates[b]
                    total = np.array(e, float) if total is None else total + e
            values.append(np.zeros(3) if total is None else total)
        return cls(*values)

    @cached_property
    def values(self) -> tuple:
        """The twelve values as Python floats in field order (gyro bias, accel bias, gyro scale,
        accel scale): the strapdown writes them into every ins/state and the IMU preprocessor
        removes them from every sample, and they change only with a correction."""
        return tuple(self.gyro_bias.tolist() + self.accel_bias.tolist()
                     + self.gyro_scale.tolist() + self.accel_scale.tolist())

    def __add__(self, other: "SensorErrors") -> "SensorErrors":
        return SensorErrors(self.gyro_bias + other.gyro_bias, self.accel_bias + other.accel_bias,
                            self.gyro_scale + other.gyro_scale,
                            self.accel_scale + other.accel_scale)

    def compensate(self, dtheta, dv, dt):
        """True increments of measured ones: (measured - bias dt) / (1 + scale).

        Parameters
        ----------
        dtheta, dv : (3,) or (n, 3)
            Measured angle (rad) and velocity (m/s) increments.
        dt : float or (n,)
            Their intervals, s. The sensor errors are one for all (3,) or one per row (n, 3).
        """
        dt = np.asarray(dt, float)
        if dt.ndim:
            dt = dt[:, None]
            return ((dtheta - dt * self.gyro_bias) / (1.0 + self.gyro_scale),
                    (dv - dt * self.accel_bias) / (1.0 + self.accel_scale))
        return ((dtheta - self.gyro_bias * dt) / (1.0 + self.gyro_scale),
                (dv - self.accel_bias * dt) / (1.0 + self.accel_scale))

    def compensate_rates(self, omega: tuple, f: tuple) -> tuple[tuple, tuple]:
        """True rate (rad/s) and specific force (m/s^2) of measured ones, in Python floats (the
        IMU preprocessor's per-sample path: numpy's per-call overhead on 3-vectors costs more
        than the arithmetic). The same formula as :meth:`compensate`."""
        values = self.values
        return (tuple((w - b) / (1.0 + s) for w, b, s in zip(omega, values[0:3], values[6:9])),
                tuple((a - b) / (1.0 + s) for a, b, s in zip(f, values[3:6], values[9:12])))


#: :func:`classify_gap` verdicts.
CONTIGUOUS, BRIDGED, LOST = "contiguous", "bridged", "lost"


def classify_gap(interval: float, dt: float, max_gap: float) -> str:
    """Whether an increment of length dt (s) that ends ``interval`` s after the previous one
    follows it directly (CONTIGUOUS), after a gap to bridge (BRIDGED: the interval exceeds dt
    by more than half of dt) or after more than ``max_gap`` s without data (LOST)."""
    if interval - dt <= 0.5 * dt:
        return CONTIGUOUS
    return LOST if interval > max_gap + dt else BRIDGED


def held_increments(t: float, dtheta: np.ndarray, dv: np.ndarray, dt: float,
                    interval: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Bridge a gap in the increments: the increment (dtheta, dv) over dt ending at t, its rates
    held over the whole `interval` before t, as increments of about dt each (end stamps, angle
    and velocity increments; shapes (n,), (n, 3), (n, 3)).

    Increments of the usual length, not one long one, so that measurements with epochs inside
    the gap are applied there, against states of the gap; integrated over the gap as it stands,
    the one increment would be free fall.
    """
    n = max(1, round(interval / dt))
    stamps = t - interval + interval / n * np.arange(1, n + 1)
    stamps[-1] = t
    scale = interval / n / dt
    return stamps, np.tile(dtheta * scale, (n, 1)), np.tile(dv * scale, (n, 1))
