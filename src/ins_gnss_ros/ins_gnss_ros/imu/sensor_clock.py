"""The IMU's sample clock: its rate from the first stamps, and a causal fit of its ticks.

A MEMS IMU samples on its own crystal, at a fixed period, but a USB or serial driver stamps each
sample when the host reads it: the stamps scatter by 1-3 ms around the sampling instants (the
car drive's logger: ±1.5 ms in 1 ms steps, 0.54 ms RMS around a line over the sample count, at
99.974 Hz rather than the nominal 100 Hz). Integrated with those stamps, every increment's dt is
off by the difference of two jitters (up to 30 % at 100 Hz), and a late stamp looks like a lost
sample to the gap check.

* :func:`fit_stamps`: the sample rate from the first stamps, robust to jitter and to a few
  lost samples (the median interval counts the samples of every interval: 1, or 2 after a lost
  sample; with jitter as wide as the period the order of arrival counts them), fitted as a line
  over the count, and the stamps' scatter about it: a driver that stamps a USB frame's samples
  together scatters them by a fraction of the frame (20 ms frames of a 100 Hz IMU: 5 ms RMS).
* :class:`SensorClock`: a Kalman filter on the line stamp = t0 + k period over the sample count
  k (a second-order phase-locked loop: phase and period, the period a slow random walk for the
  crystal's drift). Each sample's count follows from its stamp, the last one and the period, so
  lost samples keep their place; the sample's time is the fitted line at its count. A residual
  far beyond the jitter on several samples in a row is a step of the driver's clock: the line
  restarts there, keeping its period. A mean latency of the stamps is not observable from them
  (it is the ``time_offset_s`` of the preprocessor).
"""
from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np

__all__ = ["SensorClock", "StampFit", "fit_stamps"]


class StampFit(NamedTuple):
    """:func:`fit_stamps`' line: rate (Hz), the stamps' RMS scatter about it (s) and the rate's
    standard deviation relative to it."""
    rate_hz: float
    scatter_s: float
    rate_sigma: float


def fit_stamps(stamps_ns) -> StampFit:
    """Sample rate and stamp scatter of a stream from its first stamps: a least-squares line of
    the stamps over the samples' count.

    Parameters
    ----------
    stamps_ns : sequence of int
        Stamps of consecutive received samples, ns (jittered, some samples possibly lost:
        counted by the median step, and non-increasing steps count none; with jitter as wide as
        the period every received sample counts one period).

    Raises
    ------
    ValueError
        Fewer than two increasing steps.
    """
    stamps = np.asarray(stamps_ns, np.int64)
    d = np.diff(stamps).astype(float)
    if np.sum(d > 0) < 2:
        raise ValueError("fewer than two increasing stamp steps")
    median = np.median(d[d > 0])
    if np.median(np.abs(d - median)) > 0.25 * median:
        # Jitter as wide as the period: the steps cannot count lost samples, the arrivals do.
        steps = np.ones_like(d)
    else:
        steps = np.where(d > 0, np.maximum(np.round(d / median), 1.0), 0.0)
    count = np.concatenate([[0.0], np.cumsum(steps)])
    count -= count.mean()
    y = (stamps - stamps[0]).astype(float)
    spread = float(count @ count)
    period = float(count @ (y - y.mean())) / spread
    residual = y - y.mean() - period * count
    scatter = float(np.sqrt(residual @ residual / max(len(y) - 2, 1)))
    return StampFit(1e9 / period, scatter * 1e-9, scatter / np.sqrt(spread) / period)


class SensorClock:
    """Causal fit of a sensor's sampling instants to its jittered stamps (module docstring).

    Parameters
    ----------
    rate_hz : float
        Nominal (or estimated) sample rate, Hz; the fit starts from it, 2000 ppm uncertain.
    jitter_s : float
        Standard deviation of the stamps about the sampling instants, s.
    time_constant_s : float
        Memory of the fit, s: the period's random walk is set so that the loop settles over
        about this long (long: the crystal drifts over minutes; short: follows a drifting clock
        faster but passes more jitter).
    gate : float
        A residual beyond ``gate`` standard deviations of the prediction is not used...
    reset_after : int
        ...and this many in a row restart the line at the stamp (a step of the driver's clock).

    Attributes
    ----------
    period_ns : float
        The fitted sample period, ns.
    resets : int
        Restarts after clock steps, gaps that made the count ambiguous or the first sample.
    """

    def __init__(self, rate_hz: float, jitter_s: float = 1e-3, time_constant_s: float = 30.0,
                 gate: float = 5.0, reset_after: int = 5):
        if not (rate_hz > 0 and jitter_s > 0 and time_constant_s > 0 and gate > 0
                and reset_after >= 1):
            raise ValueError("rate_hz, jitter_s, time_constant_s, gate must be > 0 and "
                             "reset_after >= 1")
        self.period_ns = 1e9 / rate_hz
        self._r = (jitter_s * 1e9) ** 2
        # Process noise of the period per sample: for phase-and-period loops the bandwidth is
        # (q / R)^(1/4) per sample, so N samples of memory need q = R / N^4.
        self._q = self._r / (time_constant_s * rate_hz) ** 4
        self._gate2 = gate * gate
        # Stamps scattered over more than half a period cannot tell a sample's count: then the
        # order of arrival does (every sample is at least the next one), and only a lateness
        # well beyond the jitter is a lost sample.
        self._wide = 2.0 * jitter_s * 1e9 > 0.5 * self.period_ns
        self._late = 3.0 * jitter_s * 1e9
        self._reset_after = int(reset_after)
        self._c = [self._r, 0.0, (2e-3 * self.period_ns) ** 2]   # covariance c00, c01, c11, ns^2
        self._anchor: int | None = None   # integer ns; the fitted time of the last sample is
        self._t = 0.0                     # anchor + _t
        self._outliers = 0
        self.resets = 0

    def _restart(self, stamp_ns: int) -> int:
        self._anchor, self._t, self._outliers = stamp_ns, 0.0, 0
        self._c[0], self._c[1] = self._r, 0.0
        self.resets += 1
        return stamp_ns

    def stamp(self, stamp_ns: int) -> int:
        """The sampling instant of the sample stamped ``stamp_ns`` (both ns).

        A stamp not after the last sample's instant by at least half a period gets the instant
        of that (or an earlier) count and leaves the fit alone: the caller's checks then see a
        duplicate or backwards stamp.
        """
        if self._anchor is None:
            return self._restart(stamp_ns)
        p = self.period_ns
        r = (stamp_ns - self._anchor) - self._t
        n = max(1, round((r - self._late) / p)) if self._wide else round(r / p)
        if n <= 0:
            return self._anchor + round(self._t + n * p)
        c00, c01, c11 = self._c
        c00, c01, c11 = c00 + 2 * n * c01 + n * n * c11, c01 + n * c11, c11 + n * self._q
        if c00 > (0.25 * p) ** 2 and not self._wide:   # after a long gap the count is uncertain
            return self._restart(stamp_ns)
        t = self._t + n * p
        r -= n * p
        s = c00 + self._r
        if r * r > self._gate2 * s:
            self._outliers += 1
            if self._outliers >= self._reset_after:
                return self._restart(stamp_ns)
            self._c[:] = c00, c01, c11
        else:
            self._outliers = 0
            k0, k1 = c00 / s, c01 / s
            t += k0 * r
            self.period_ns = p + k1 * r
            self._c[:] = c00 - k0 * c00, c01 - k0 * c01, c11 - k1 * c01
        whole = math.floor(t)   # keep the float part small: ns resolution for any stamp
        self._anchor += whole
        self._t = t - whole
        return self._anchor + round(self._t)
