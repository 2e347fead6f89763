"""The measured time correlation of a heading source's errors, and the variance it gives each
reading.

A magnetic compass's heading error is not white: its tilt compensation uses the INS roll and
pitch (their error enters every reading until the filter's tilt changes), the residual of a
hard/soft-iron calibration is a function of the heading (constant while the vehicle holds it,
changing as it turns), and disturbances rise and fall over seconds. An AHRS's yaw has the
same kinds of error. Fused at 50 Hz as independent readings of their reported variance, N
readings within the error's correlation time count as N independent ones where they are worth
about one: the filter grows as sure of the heading as the readings' white noise would allow
and its published heading covariance no longer covers its error (a simulated car drive:
attitude NEES 9.5, 19 once the compass publishes).

What the readings are worth is measured here, from the readings themselves: their error
series is the reading minus the azimuth the gyros integrated since the first reading
(:class:`HeadingNoise` gets that difference; over seconds the gyros' own drift is below
the readings' noise, and a constant drift, a gyro bias or the Earth's rate, drops out of the
statistic below). The Hadamard variance H(tau) of that series (the variance of the second
difference of successive tau-means, over 6; IEEE Std 1139-2008 and Riley, "Handbook of
Frequency Stability Analysis", NIST SP 1065, 2008, sections 5.2.8-5.2.9; the Allan variance's
sibling that does not see a constant drift or a constant offset) is, for any error correlated
over less than tau, the variance of the mean of the readings over tau. So readings that arrive
g seconds apart carry together at most the information 1 / H(tau) per tau: each of the tau / g
readings within tau is fused with the variance

    R_eff = max(R, S / g),   S = max over tau of tau * H(tau)

(rad^2 s: the readings' white-noise level equivalent, the density of a white error with the
same variance of its tau-means at the worst tau). For white readings tau * H(tau) = R g at every
tau and R_eff = R; for readings correlated over T, S / g is R times the number of readings
within T that count as one: the effective number of independent observations of an
autocorrelated series (Bayley and Hammersley, "The effective number of independent observations
in an autocorrelated time series", J. R. Stat. Soc. Suppl. 8, 1946). A constant error is the
source's bias state's (HeadingFix.bias) and not counted here.

tau runs over a ladder up to :data:`LADDER`'s last rung. A rung counts once its statistic rests
on :data:`MIN_DIFFERENCES` second differences (about ten tau of readings); rungs above the
longest measured one are not assumed to average down further: for them S takes tau times the
longest measured rung's H (the readings are worth what they have shown, no more). Before any
rung is measured a reading gets its reported variance. Each rung pools :data:`PHASES` sets of
bins staggered by tau / PHASES (the overlapping estimator), and a second difference is taken at
the bins' mean times (a bin cut by a gap or the start still cancels a drift). The statistic
forgets with :data:`MEMORY_S`, so a source whose errors change (a disturbance, a new
calibration) is re-measured.
"""
from __future__ import annotations

import math

__all__ = ["HeadingNoise", "LADDER", "MEMORY_S", "MIN_DIFFERENCES", "PHASES"]

#: Averaging times of the statistic, s: 0.05 s (a 20-50 Hz compass's few readings) doubling to
#: 25.6 s (a vehicle's turns; a longer error is the bias state's to follow).
LADDER = tuple(0.05 * 2.0 ** k for k in range(10))
#: Memory of the statistic, s (exponential forgetting): 300 s holds about 12 second differences
#: of the longest rung.
MEMORY_S = 300.0
#: Second differences (forgetting-weighted) a rung needs before it counts: with 8 the Hadamard
#: variance is known to about +-50 % (2 sigma).
MIN_DIFFERENCES = 8.0
#: Staggered bin sets per averaging time (the overlapping estimator).
PHASES = 4


class _Phase:
    """Second differences of tau-means over non-overlapping time bins starting at ``offset``."""

    __slots__ = ("tau", "offset", "decay", "bin", "total", "times", "count", "means", "sum_sq",
                 "weight")

    def __init__(self, tau: float, offset: float):
        self.tau, self.offset = tau, offset
        self.decay = math.exp(-tau / MEMORY_S)  # one completed bin's forgetting
        self.bin, self.total, self.times, self.count = None, 0.0, 0.0, 0
        self.means: list = []  # the last two completed bins as (index, mean, mean time)
        self.sum_sq = 0.0  # forgetting-weighted sum of squared second differences, rad^2
        self.weight = 0.0  # forgetting-weighted number of them

    def restart(self) -> None:
        """A break in the error series (its offset may change): no differences across it."""
        self.bin, self.total, self.times, self.count, self.means = None, 0.0, 0.0, 0, []

    def add(self, t: float, x: float) -> bool:
        """A reading; True when it completed a bin (the statistic may have changed)."""
        index = math.floor((t - self.offset) / self.tau)
        completed = False
        if index != self.bin:
            if self.bin is not None and self.count:
                self._complete(self.bin, self.total / self.count, self.times / self.count)
                completed = True
            self.bin, self.total, self.times, self.count = index, 0.0, 0.0, 0
        self.total += x
        self.times += t - self.offset
        self.count += 1
        return completed

    def _complete(self, index: int, mean: float, at: float) -> None:
        means = self.means
        if len(means) == 2 and means[0][0] == index - 2 and means[1][0] == index - 1:
            # the second difference at the bins' mean times (a bin cut by the start or a gap
            # is not centred): zero for any drift linear in time
            (_, m1, t1), (_, m2, t2) = means
            second = (mean - m2) - (m2 - m1) * (at - t2) / (t2 - t1)
            self.sum_sq = self.sum_sq * self.decay + second * second
            self.weight = self.weight * self.decay + 1.0
        means.append((index, mean, at))
        if len(means) > 2:
            del means[0]


class _Rung:
    """The overlapping Hadamard variance at one averaging time tau: :data:`PHASES` sets of
    non-overlapping bins, staggered by tau / PHASES, pooled (the overlapping estimator's better
    confidence at the long rungs, NIST SP 1065 section 5.2.9)."""

    __slots__ = ("tau", "phases")

    def __init__(self, tau: float):
        self.tau = tau
        self.phases = [_Phase(tau, tau * k / PHASES) for k in range(PHASES)]

    def restart(self) -> None:
        for phase in self.phases:
            phase.restart()

    def add(self, t: float, x: float) -> bool:
        """A reading; True when it completed a bin of a phase."""
        completed = False
        for phase in self.phases:
            completed |= phase.add(t, x)
        return completed

    @property
    def measured(self) -> bool:
        """Enough second differences: MIN_DIFFERENCES in every phase (the phases' overlap
        adds confidence, not independent differences)."""
        return min(phase.weight for phase in self.phases) >= MIN_DIFFERENCES

    @property
    def hadamard(self) -> float:
        """Hadamard variance, rad^2 (nan before any second difference)."""
        weight = sum(phase.weight for phase in self.phases)
        return sum(phase.sum_sq for phase in self.phases) / (6.0 * weight) if weight > 0.0 \
            else math.nan


class HeadingNoise:
    """One heading source's measured error correlation (module doc)."""

    def __init__(self):
        self._rungs = [_Rung(tau) for tau in LADDER]
        self._last_t = math.nan  # stamp of the previous reading, s
        self._offset = math.nan  # the previous error value, rad (for unwrapping)
        # density() until a bin completes (asked at every reading, it changes with the bins)
        self._density = None

    def restart(self) -> None:
        """The gyro azimuth the errors are taken against starts again (IMU lost, gap)."""
        for rung in self._rungs:
            rung.restart()
        self._offset = math.nan

    def add(self, t: float, error: float) -> None:
        """The reading at t (s) minus the gyros' azimuth at t, rad (any multiple of 2 pi)."""
        if not math.isnan(self._offset):
            error = self._offset + (error - self._offset + math.pi) % (2.0 * math.pi) - math.pi
        self._offset = error
        for rung in self._rungs:
            if rung.add(t, error):
                self._density = None

    def density(self) -> float:
        """S, rad^2 s: the largest tau * H(tau) of the measured rungs, the longest measured
        rung's H standing for every longer rung; nan before any rung is measured."""
        if self._density is None:
            self._density = self._measure_density()
        return self._density

    def _measure_density(self) -> float:
        worst, longest = math.nan, None
        for rung in self._rungs:
            if rung.measured:
                value = rung.tau * rung.hadamard
                worst = value if math.isnan(worst) else max(worst, value)
                longest = rung
        if longest is None:
            return math.nan
        return max(worst, LADDER[-1] * longest.hadamard)

    def variance(self, t: float, reported: float) -> float:
        """The variance to fuse the reading at t (s) with, given its reported variance (rad^2):
        max(reported, S / g), g the time since the source's previous reading."""
        gap = t - self._last_t
        self._last_t = t
        density = self.density()
        if math.isnan(density) or not gap > 0.0:
            return reported
        return max(reported, density / min(gap, LADDER[-1]))

    def summary(self) -> str:
        """One line for diagnostics: the measured rungs' tau * H and S."""
        measured = [f"{r.tau:g} s {r.tau * r.hadamard:.2e}" for r in self._rungs if r.measured]
        return f"tau*H(tau) rad^2 s: {', '.join(measured) or 'none measured yet'}; " \
               f"S {self.density():.2e}"
