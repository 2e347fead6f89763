"""The IMU's white noise measured at rest: a lower bound of the filter's noise densities.

An IMU grade's densities come from a data sheet, measured on a quiet table. On a vehicle, the
engine, fans and mounting add vibration that the filter has to carry as noise too: the real car
drive's IMU standing with its engine idling scatters 3-10 times the data sheet's white noise on its
axes, and a filter on the data sheet's densities gates the fixes after every outage. While the
vehicle stands, whatever the increments scatter is noise. Over blocks of ``BLOCK_S`` the increments
are averaged, and consecutive block means differenced (which removes the biases, gravity and the
Earth rate): for white noise of density N the difference has the variance 2 N^2 / T, twice the
Allan variance at tau = T (IEEE Std 952-1997, annex C). A vibration that averages out within a
block counts only with what is left of it over ``BLOCK_S``, the filter's covariance interval (on
the real car drive, blocks of 0.5 s read the accelerometers at 6.6e-3 m/s^2/sqrt(Hz) and gave a
position NEES of 3.6, blocks of 0.1 s 1.4e-2 and 1.8).

A block counts only from ``CONFIRM_S`` after the first GNSS velocity of a rest, and its difference
only once a velocity ``CONFIRM_S`` after it still says rest: the rest the navigator knows lags the
receiver's speed by up to an update, and neither the last deceleration of a stop (the suspension
rocking after it) nor the onset of a drive, before its speed passes the rest threshold, is noise.
The filter's densities follow the measured ones, per sensor the mean variance of the three axes
(the filter's model is isotropic), where they exceed the grade's by more than three standard
deviations of the estimate (a chi-square of 3 (blocks - 1) degrees of freedom); never below the
grade's.
"""
from __future__ import annotations

from dataclasses import replace

import numpy as np

#: Length of the blocks whose means are differenced, s: the default covariance interval.
BLOCK_S = 0.1
#: Time after a block by which a GNSS velocity must still say rest for the block to count, s.
CONFIRM_S = 1.0
#: Standard deviations of the estimate by which it must exceed the grade's density.
SIGNIFICANCE = 3.0


class RestNoise:
    """White-noise densities of the gyros and accelerometers measured while at rest.

    Parameters
    ----------
    grade : FilterNoise
        The configured noise (sensor_errors.filter_noise): the lower bound.

    Attributes
    ----------
    noise : FilterNoise
        The grade's noise with the densities raised to the measured ones where significant.
    """

    def __init__(self, grade):
        self.grade = self.noise = grade
        self._block = None       # [t_start, dtheta sum (3,), dv sum (3,)] of the open block
        self._previous = None    # (mean rate, mean force, length) of the last closed block
        self._pending = []       # (t_end, squared gyro difference (3,), accel (3,)) unconfirmed
        self._sq = np.zeros(2)   # sums of the confirmed squared differences: gyro, accel
        self._count = 0          # confirmed differences (each of three axes)
        self._t_last = -np.inf   # end of the last sample added, s
        self._rest_since = np.inf  # epoch of the current rest's first GNSS velocity, s

    def add(self, t, dtheta, dv):
        """IMU samples at rest: end times t (N,), increments dtheta, dv (N, 3) [s, rad, m/s].
        Samples up to the last one added are passed over (a rewound navigator re-runs them)."""
        if t[-1] <= self._t_last:
            return
        if t[0] <= self._t_last:
            keep = t > self._t_last
            t, dtheta, dv = t[keep], dtheta[keep], dv[keep]
        self._t_last = t[-1]
        if t[0] < self._rest_since + CONFIRM_S:
            return   # too close to the rest's first velocity (or none yet)
        if self._block is None:
            # The block starts at the end of its first sample (whose start is not known here):
            # a mean over a length that missed a sample would be off by gravity / samples.
            self._block = [t[0], np.zeros(3), np.zeros(3)]
            dtheta, dv = dtheta[1:], dv[1:]
        b = self._block
        b[1] = b[1] + dtheta.sum(axis=0)
        b[2] = b[2] + dv.sum(axis=0)
        if t[-1] - b[0] < BLOCK_S:
            return
        self._block = None
        length = t[-1] - b[0]
        rate, force = b[1] / length, b[2] / length
        if self._previous is not None:
            # Means over lengths T1, T2 of white noise N: their difference has the variance
            # N^2 (1/T1 + 1/T2) (the blocks end at sample boundaries: their lengths vary).
            weight = 1.0 / (1.0 / length + 1.0 / self._previous[2])
            self._pending.append((t[-1], (rate - self._previous[0]) ** 2 * weight,
                                  (force - self._previous[1]) ** 2 * weight))
        self._previous = (rate, force, length)

    def moved(self):
        """The rest is over (or not known): the next rest starts a new chain of blocks (its
        first GNSS velocity, :meth:`confirm`, starts the margin)."""
        self._block = self._previous = None

    def confirm(self, t, at_rest):
        """A GNSS velocity at t (s) says the vehicle is (or is not) at rest: the block
        differences ``CONFIRM_S`` before it count (or all unconfirmed ones are dropped, and the
        chain ends)."""
        if not at_rest:
            self._pending = []
            self._rest_since = np.inf
            self.moved()
            return
        self._rest_since = min(self._rest_since, t)
        while self._pending and self._pending[0][0] <= t - CONFIRM_S:
            _, g, a = self._pending.pop(0)
            self._sq += (g.sum(), a.sum())
            self._count += 3
        if self._count:
            self._update()

    def densities(self):
        """Measured (gyro, accel) white-noise PSD [rad^2/s, m^2/s^3] and their degrees of
        freedom, or None before any confirmed block difference."""
        if self._count == 0:
            return None
        psd = self._sq / self._count   # E[d^2] / (1/T1 + 1/T2) = N^2 per axis
        return float(psd[0]), float(psd[1]), self._count

    def ratios(self):
        """Measured over the grade's density (not squared) of the gyros and the accelerometers,
        or None."""
        d = self.densities()
        if d is None:
            return None
        return np.sqrt(d[0] / self.grade.gyro_psd), np.sqrt(d[1] / self.grade.accel_psd)

    @property
    def summary(self):
        """The measured densities against the grade's, for /diagnostics, or None."""
        ratios = self.ratios()
        if ratios is None:
            return None
        raised = self.noise is not self.grade
        return (f"gyro {ratios[0]:.1f} x, accel {ratios[1]:.1f} x the grade's white noise "
                f"({self.densities()[2]} dof): " +
                ("raised to it" if raised else "the grade's kept"))

    def _update(self):
        gyro, accel, dof = self.densities()
        limit = 1.0 + SIGNIFICANCE * np.sqrt(2.0 / dof)
        gyro = gyro if gyro > limit * self.grade.gyro_psd else self.grade.gyro_psd
        accel = accel if accel > limit * self.grade.accel_psd else self.grade.accel_psd
        if (gyro, accel) != (self.noise.gyro_psd, self.noise.accel_psd):
            self.noise = replace(self.grade, gyro_psd=gyro, accel_psd=accel)
