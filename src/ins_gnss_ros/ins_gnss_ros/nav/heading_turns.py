"""Whether a heading source turns with the gyros, or against them.

An orientation published in NED/FRD where REP-103 and REP-145 want ENU/FLU (a driver left in
its sensor's convention), a compass whose magnetometer axes are not the IMU's, a receiver that
counts its heading counter-clockwise: each gives a valid-looking azimuth whose changes run
opposite to the vehicle's turns. Taken at the alignment it is wrong by whatever the mirror
makes of the heading, and fused afterwards it steers the filter against its own gyros (a
simulated car with its AHRS orientation in NED: heading 105 deg RMS, 180 deg at worst, the
horizontal error 2.8 x the raw fixes'; docs/results/product_path.md, "2026-12-06 (session 28)").
Its bias state cannot take it: the error grows with every turn.

The check needs no attitude: the source's azimuth a and the azimuth g the gyros integrate about
the vertical (both clockwise from north; the aiding front end's, as for the heading noise,
nav/heading_noise.py) change together. Over spans of at least SPAN_S between readings, the
changes are fitted by least squares as

    delta_a = k delta_g + c delta_t,

k the source's turn per gyro turn (1 for a heading of the body), c the difference of their
drifts (the raw gyros' bias; constant offsets, the source's bias and the declination, drop out of
the differences). k is known to sigma_k^2 = s^2 / E, s^2 the residual variance and E the squared
gyro turns beyond their mean rate (the information on k). Once E reaches TURN_EVIDENCE, a k
below zero by VERDICT_SIGMAS standard errors is the verdict: the source turns against the body.
Only a negative k is judged: a positive one far from 1 may be the gyros' (rates in deg/s, told by
the IMU timing check against the course, nav/imu_timing.py), a negative one is not (the IMU
timing check tells an IMU turning against the course apart).
"""
from __future__ import annotations

import math

__all__ = ["HeadingTurns", "SPAN_S", "TURN_EVIDENCE", "VERDICT_SIGMAS"]

#: Least time between the readings a change is taken over, s: an AHRS's or a compass's own lag
#: (tenths of a second) is then a small part of each change.
SPAN_S = 1.0
#: Squared gyro turns beyond their mean rate before a verdict, rad^2: (30 deg)^2, the first
#: corner of a town block (a 90 deg turn over 6 s gives (37 deg)^2 in 1 s spans).
TURN_EVIDENCE = math.radians(30.0) ** 2
#: Standard errors by which k must lie below zero.
VERDICT_SIGMAS = 5.0


class HeadingTurns:
    """One heading source's turns against the gyros' (module doc)."""

    def __init__(self):
        self._anchor = None  # (t s, azimuth rad, gyro azimuth rad) the next change starts from
        # sums of the normal equations: g = delta_g, a = delta_a, t = delta_t
        self._gg = self._gt = self._tt = self._ag = self._at = self._aa = 0.0
        self._n = 0
        self.against = False  # the verdict: the source turns against the gyros

    def restart(self) -> None:
        """The gyros' azimuth starts again (a gap in the increments): no change across it."""
        self._anchor = None

    def add(self, t: float, azimuth: float, gyro: float) -> bool:
        """A reading's azimuth and the gyros' at its stamp t (s; rad, clockwise from north, the
        gyros' unwrapped). True when this reading brought the verdict."""
        if self._anchor is None:
            self._anchor = (t, azimuth, gyro)
            return False
        t0, a0, g0 = self._anchor
        dt = t - t0
        if dt < SPAN_S:
            return False
        self._anchor = (t, azimuth, gyro)
        da = (azimuth - a0 + math.pi) % (2.0 * math.pi) - math.pi
        dg = gyro - g0
        self._gg += dg * dg
        self._gt += dg * dt
        self._tt += dt * dt
        self._ag += da * dg
        self._at += da * dt
        self._aa += da * da
        self._n += 1
        if self.against or self.evidence() < TURN_EVIDENCE:
            return False
        k, sigma = self.scale()
        self.against = k + VERDICT_SIGMAS * sigma < 0.0
        return self.against

    def evidence(self) -> float:
        """E: the squared gyro turns beyond their mean rate, rad^2."""
        return self._gg - self._gt * self._gt / self._tt if self._tt > 0.0 else 0.0

    def scale(self) -> tuple[float, float]:
        """k and its standard error (nan before three changes or any turn)."""
        evidence = self.evidence()
        if self._n < 3 or not evidence > 0.0:
            return math.nan, math.nan
        det = evidence * self._tt
        k = (self._ag * self._tt - self._at * self._gt) / det
        c = (self._at * self._gg - self._ag * self._gt) / det
        residual = max(self._aa - k * self._ag - c * self._at, 0.0)
        return k, math.sqrt(residual / (self._n - 2) / evidence)

    def summary(self) -> str:
        """One line for diagnostics."""
        k, sigma = self.scale()
        evidence = f"turn evidence {math.degrees(math.sqrt(self.evidence())):.0f} deg"
        if math.isnan(k):
            return f"not measured yet ({evidence})"
        text = f"turns {k:+.2f} +- {sigma:.2f} x the gyros' azimuth ({evidence})"
        if self.against:
            text += (": against the body's turns, not its heading (an orientation in NED/FRD "
                     "read as ENU/FLU, REP-145? a compass whose axes are not the IMU's?)")
        return text
