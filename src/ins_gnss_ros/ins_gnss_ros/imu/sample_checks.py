"""Per-sample sanity checks of a raw IMU stream, before calibration and integration.

The strapdown integration assumes a regular stream of finite, in-range samples on a strictly
increasing time scale (seed 004 §1.5, §2.11: fixed sensor step dt, stamps tied to PPS). Real
streams break that: NaN words after a bus error, saturated channels during shocks (ISON-2's
sensing block is limited to ±150 °/s and ±30 m/s², seed 004 §1.3c), repeated or reordered
packets, dropped samples, and a stuck sensor or driver that keeps sending its last reading with
new stamps. :class:`SampleChecker` classifies every sample and keeps a count per reason; short gaps
are bridged so that the integrator keeps its nominal step, longer ones are reported so that the
caller can restart integration. What a bridge may miss is measured on the stream itself
(:class:`BridgeMiss`): the filter carries it as process noise. The sensor's clock is compared
with the arrival clock for jumps (:class:`ClockJumps`) and for drift (:class:`ArrivalDrift`).
"""
from __future__ import annotations

import math
from collections import Counter, deque
from dataclasses import dataclass, field

import numpy as np

#: Reasons returned by :meth:`SampleChecker.check`; "ok" and the two gap reasons are usable samples.
REASONS = ("ok", "non_finite", "saturated", "duplicate_stamp", "backwards_stamp", "frozen",
           "gap_bridged", "gap")


@dataclass(frozen=True)
class CheckResult:
    """Outcome of checking one sample (immutable: the results without fill samples are shared).

    Attributes
    ----------
    ok : bool
        The sample itself can be used.
    reason : str
        One of :data:`REASONS`.
    fill_stamps, fill_gyro, fill_accel : ndarray, shapes (k,), (k, 3), (k, 3)
        Samples synthesised to bridge a gap before this one (k = 0 unless reason is
        "gap_bridged"); they go to the integrator before the current sample.
    fill_miss : (float, float)
        Standard deviation per axis by which each synthesised sample may miss the true rate
        (rad/s) and specific force (m/s^2) (:meth:`BridgeMiss.sigma`).
    """

    ok: bool
    reason: str
    fill_stamps: np.ndarray = field(default_factory=lambda: np.zeros(0))
    fill_gyro: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))
    fill_accel: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))
    fill_miss: tuple = (0.0, 0.0)


def _read_only(a: np.ndarray) -> np.ndarray:
    a.flags.writeable = False
    return a


#: One shared result per reason for the samples that bring no fill samples (nearly all of them):
#: building a CheckResult and its three empty arrays cost more than the checks themselves.
_PLAIN = {reason: CheckResult(reason in ("ok", "gap"), reason, _read_only(np.zeros(0)),
                              _read_only(np.zeros((0, 3))), _read_only(np.zeros((0, 3))))
          for reason in REASONS if reason != "gap_bridged"}


class BridgeMiss:
    """How far a bridge of missing samples misses the true ones, measured on the real stream.

    A bridged sample is the straight line between the samples around the gap (or the sample
    before it, held). What the vehicle's vibration and the sensor noise do in between is lost:
    on the real car drive at 100 Hz an interpolated gyro sample misses the real one by 3.9
    deg/s RMS, an accelerometer sample by 0.49 m/s^2, and with 30 % of the samples lost the
    filter, not told, had a position NEES of 9.5 (7.1 told; docs/results/product_path.md,
    "2026-12-05"). Here the same bridge is applied to real samples of the stream, whose true
    value is known: for a gap of m samples, the miss
    of its worst (middle, or last held) sample, i.e. for interpolation the residual
    x_c - (x_{c-j} + x_{c+j}) / 2 with j = ceil((m + 1) / 2), for holding x_c - x_{c-j} with j
    = m. Its mean square per axis is averaged over the last ``TAU_S`` (vibration follows the
    speed), one sample in ``STRIDE`` (the statistic does not need them all; the check runs on
    every sample).

    Parameters
    ----------
    rate_hz : float
    max_bridge : int
        Longest bridged gap, samples.
    interpolate : bool
        The bridge interpolates (else holds the last sample).
    """

    TAU_S = 10.0
    STRIDE = 4

    def __init__(self, rate_hz: float, max_bridge: int, interpolate: bool):
        self.interpolate = interpolate
        self.spans = (max(max_bridge, 0) + 2) // 2 if interpolate else max(max_bridge, 0)
        self._recent = deque(maxlen=(2 if interpolate else 1) * self.spans + 1)
        self._mean_square = [[0.0, 0.0] for _ in range(self.spans)]  # per span j: gyro, accel
        self._count = 0
        self._weight_floor = self.STRIDE / (rate_hz * self.TAU_S)
        self._phase = 0

    def span(self, missing: int) -> int:
        """The span j of :class:`BridgeMiss`'s residual for a gap of ``missing`` samples."""
        return (missing + 2) // 2 if self.interpolate else missing

    def add(self, gyro: tuple, accel: tuple, contiguous: bool) -> None:
        """A real sample; ``contiguous``: none is missing between it and the previous one."""
        recent = self._recent
        if not contiguous:
            recent.clear()
        recent.append((gyro, accel))
        self._phase = (self._phase + 1) % self.STRIDE
        if self._phase or len(recent) < recent.maxlen:
            return
        self._count += 1
        weight = max(1.0 / self._count, self._weight_floor)
        x = recent[-1]
        for j in range(1, self.spans + 1):
            if self.interpolate:
                centre, before = recent[-1 - j], recent[-1 - 2 * j]
                misses = [[c - 0.5 * (b + a) for c, b, a in zip(centre[k], before[k], x[k])]
                          for k in (0, 1)]
            else:
                before = recent[-1 - j]
                misses = [[a - b for a, b in zip(x[k], before[k])] for k in (0, 1)]
            mean_square = self._mean_square[j - 1]
            for k in (0, 1):
                r = misses[k]
                mean_square[k] += weight * ((r[0] * r[0] + r[1] * r[1] + r[2] * r[2]) / 3.0
                                            - mean_square[k])

    def sigma(self, missing: int) -> tuple[float, float]:
        """Standard deviation per axis of a bridged sample's miss of the true rate (rad/s) and
        specific force (m/s^2), in a gap of ``missing`` samples; (0, 0) before any
        measurement."""
        j = min(self.span(missing), self.spans)
        if j < 1 or not self._count:
            return 0.0, 0.0
        gyro, accel = self._mean_square[j - 1]
        return math.sqrt(gyro), math.sqrt(accel)


class SampleChecker:
    """Classifies raw IMU samples one at a time and bridges short gaps.

    A rejected sample (non-finite, saturated, bad stamp, frozen) is treated as missing: the next
    good sample then sees a gap, which is bridged if it is short. Stamps are compared with the last
    *accepted* sample.

    Frozen: the white noise of a working MEMS or fibre-optic sensor changes the least significant
    bits of every channel from one sample to the next, so `max_identical` consecutive samples with
    new stamps and bit-identical readings on all six channels mean a stuck sensor or a driver
    repeating its last packet; from the `max_identical`-th on they are rejected until the
    readings change.

    Parameters
    ----------
    rate_hz : float
        Nominal sample rate, Hz.
    gyro_range : float
        Measurement range of the gyros, rad/s; a reading with |w_i| >= range is saturated.
    accel_range : float
        Measurement range of the accelerometers, m/s².
    max_bridge : int
        Longest run of missing samples that is bridged; longer gaps are reported.
    bridge : {"interpolate", "hold"}
        Linear interpolation between the neighbours, or repetition of the last good sample.
    gap_factor : float
        An interval longer than gap_factor / rate_hz counts as a gap (jitter tolerance).
    max_identical : int
        This many consecutive bit-identical samples count as frozen (>= 2; 0 disables the check,
        for noise-free simulated or coarsely quantised streams).
    """

    def __init__(self, rate_hz: float, gyro_range: float, accel_range: float,
                 max_bridge: int = 5, bridge: str = "interpolate", gap_factor: float = 1.5,
                 max_identical: int = 5):
        if bridge not in ("interpolate", "hold"):
            raise ValueError(f"bridge: {bridge!r}, expected 'interpolate' or 'hold'")
        if max_identical == 1 or max_identical < 0:
            raise ValueError(f"max_identical: {max_identical}, expected 0 (off) or >= 2")
        if not (rate_hz > 0 and gyro_range > 0 and accel_range > 0 and gap_factor > 1):
            raise ValueError("rate_hz, gyro_range, accel_range must be > 0 and gap_factor > 1")
        self.rate_hz = float(rate_hz)
        self.gyro_range = float(gyro_range)
        self.accel_range = float(accel_range)
        self.max_bridge = int(max_bridge)
        self.bridge = bridge
        self.gap_factor = float(gap_factor)
        self.max_identical = int(max_identical)
        self.counts: Counter = Counter({r: 0 for r in REASONS})
        self._last = None  # (stamp, gyro, accel) of the last accepted sample
        self._previous = None  # (gyro, accel) of the last sample with a usable stamp
        self._identical = 0   # consecutive samples equal to their predecessor
        self.miss = BridgeMiss(rate_hz, max_bridge, bridge == "interpolate")

    def _reject(self, reason: str) -> CheckResult:
        self.counts[reason] += 1
        return _PLAIN[reason]

    def check(self, stamp: float, gyro, accel) -> CheckResult:
        """Classify one sample.

        Parameters
        ----------
        stamp : float
            Sensor time, s.
        gyro, accel : sequence of 3 floats
            Raw angular rate (rad/s) and specific force (m/s²).
        """
        # Six Python floats: per sample, scalar tests cost a fraction of numpy calls on 3-vectors.
        gx, gy, gz = gyro
        ax, ay, az = accel
        isfinite = math.isfinite
        if not (isfinite(stamp) and isfinite(gx) and isfinite(gy) and isfinite(gz)
                and isfinite(ax) and isfinite(ay) and isfinite(az)):
            return self._reject("non_finite")
        if (max(abs(gx), abs(gy), abs(gz)) >= self.gyro_range
                or max(abs(ax), abs(ay), abs(az)) >= self.accel_range):
            return self._reject("saturated")
        gyro, accel = (gx, gy, gz), (ax, ay, az)
        result = _PLAIN["ok"]
        dt = 0.0
        if self._last is not None:
            dt = stamp - self._last[0]
            if dt == 0.0:
                return self._reject("duplicate_stamp")
            if dt < 0.0:
                return self._reject("backwards_stamp")
        if self._frozen(gyro, accel):
            return self._reject("frozen")
        if dt > self.gap_factor / self.rate_hz:
            missing = int(round(dt * self.rate_hz)) - 1
            if 0 < missing <= self.max_bridge:
                result = self._fill(*self._last, stamp, gyro, accel, missing)
            else:
                result = _PLAIN["gap"]
        self._last = (float(stamp), gyro, accel)
        self.counts[result.reason] += 1
        self.miss.add(gyro, accel, result.reason == "ok")
        return result

    def _frozen(self, gyro: tuple, accel: tuple) -> bool:
        """Count this sample's repetition of its predecessor; True from `max_identical` in a row."""
        prev, self._previous = self._previous, (gyro, accel)
        if prev == self._previous:  # float ==, as np.array_equal (NaN never gets here)
            self._identical += 1
        else:
            self._identical = 0
        return 0 < self.max_identical <= self._identical + 1

    def _fill(self, t0, g0, a0, t1, g1, a1, missing: int) -> CheckResult:
        frac = np.arange(1, missing + 1) / (missing + 1)
        stamps = t0 + frac * (t1 - t0)
        if self.bridge == "hold":
            frac = np.zeros_like(frac)
        g0, g1, a0, a1 = (np.asarray(x, float) for x in (g0, g1, a0, a1))
        gyro = g0 + frac[:, None] * (g1 - g0)
        accel = a0 + frac[:, None] * (a1 - a0)
        return CheckResult(True, "gap_bridged", stamps, gyro, accel, self.miss.sigma(missing))


class ClockJumps:
    """Finds jumps of a sensor's clock against the arrival clock and takes them out of its stamps.

    A sensor that samples at a fixed rate delivers one sample per period. When its samples keep
    arriving one period apart but a stamp steps by J more (or less) than that, the samples were
    not lost (that would delay the arrival too): the clock labelling them jumped, e.g. a driver
    re-synchronising its time. Without correction a forward jump is taken for a gap of J and the
    stream then runs J ahead of the other sensors (a backward one is rejected sample by sample
    until the stamps pass the old ones, losing J of motion). Here the jump, rounded to whole
    sample periods, is subtracted from this and every later stamp.

    Only trusted while the arrival clock paces the samples: the last `regular_samples` arrival
    steps, and this one, within `tolerance` of a period. A replay faster than real time on a wall
    clock, a burst after a stall, reordered or duplicated deliveries all break that, and the
    stamps then pass unchanged. A stream with regular stamps is never changed: a stamp step of
    one period with a regular arrival step differs from it by at most `tolerance` periods (5 ms
    at 50 Hz), below `min_jump`. A jump beyond `max_jump` is not a glitch but a new time base
    (a restarted or looped source): it is passed on for the downstream to restart.

    Parameters
    ----------
    rate_hz : float
        Nominal sample rate, Hz.
    min_jump, max_jump : float
        Stamp steps that differ from the arrival step by min_jump..max_jump s are clock jumps.
    regular_samples : int
        Regular arrival steps needed before a jump is believed.
    tolerance : float
        Largest deviation of a regular arrival step from the period, in periods.
    """

    def __init__(self, rate_hz: float, min_jump: float = 0.1, max_jump: float = 2.5,
                 regular_samples: int = 10, tolerance: float = 0.25):
        if not (rate_hz > 0 and 0 < min_jump <= max_jump):
            raise ValueError("rate_hz must be > 0 and 0 < min_jump <= max_jump")
        self.period_ns = 1e9 / rate_hz
        self.min_ns, self.max_ns = min_jump * 1e9, max_jump * 1e9
        self.regular_samples = int(regular_samples)
        self.tolerance = float(tolerance)
        self.offset_ns = 0      # subtracted from the sensor stamps
        self.jumps = 0
        self._last = None       # (stamp, arrival) of the previous sample, ns
        self._regular = 0       # arrival steps within tolerance of a period, in a row

    def correct(self, stamp_ns: int, arrival_ns: int) -> int:
        """The stamp (ns) of a sample that arrived at arrival_ns, with the clock jumps taken out."""
        last, self._last = self._last, (stamp_ns, arrival_ns)
        if last is not None:
            arrival_step = arrival_ns - last[1]
            regular = abs(arrival_step - self.period_ns) <= self.tolerance * self.period_ns
            jump = (stamp_ns - last[0]) - arrival_step
            if regular and self._regular >= self.regular_samples \
                    and self.min_ns <= abs(jump) <= self.max_ns:
                self.offset_ns += int(round(round(jump / self.period_ns) * self.period_ns))
                self.jumps += 1
            self._regular = self._regular + 1 if regular else 0
        return stamp_ns - self.offset_ns


class ArrivalDrift:
    """The sensor clock's rate against the arrival clock (this computer's, or a bag's log time).

    An IMU stamped by counting its samples at the nominal rate runs its crystal's error against
    every other clock: tens to hundreds of ppm, 10-100 ms over ten minutes against GNSS fixes
    stamped on the receiver's or the host's time, which no constant ``time_offset_s`` holds.
    The delay of a sample (arrival - stamp) is its transport and scheduling delay plus the
    clocks' difference; its least value over a block of ``block_s`` is the transport floor, a
    sample that found the way free, so the floors' trend over the blocks is the clocks' drift,
    whatever the load added to the other samples. Least squares over the last ``blocks`` floors
    gives the rate r (the stamps advance by 1 + r s per second of arrival) and its sigma from
    the floors' scatter about the line. Only meaningful while the arrival clock paces the
    samples: a rate beyond ``max_rate`` is not a clock's (a replay faster than real time) and
    is not reported.
    """

    def __init__(self, block_s: float = 30.0, blocks: int = 20, min_span_s: float = 120.0,
                 max_rate: float = 0.01):
        self.block_ns, self.min_span_s, self.max_rate = block_s * 1e9, min_span_s, max_rate
        self._origin = None     # (stamp, arrival) ns of the first sample: offsets keep floats exact
        self._block = None      # (index, least delay s) of the block being filled
        self._floors = deque(maxlen=blocks)   # (block mid-time s, least delay s)

    def add(self, stamp_ns: int, arrival_ns: int) -> bool:
        """One sample; True when it completed a block (:meth:`rate` may have changed)."""
        if self._origin is None:
            self._origin = (stamp_ns, arrival_ns)
        t = arrival_ns - self._origin[1]
        delay = (t - (stamp_ns - self._origin[0])) * 1e-9
        index = int(t // self.block_ns)
        block, completed = self._block, False
        if block is not None and index > block[0]:
            self._floors.append(((block[0] + 0.5) * self.block_ns * 1e-9, block[1]))
            block, completed = None, True
        if block is None:
            self._block = (index, delay)
        elif delay < block[1]:  # (one that arrived out of order counts in the current block)
            self._block = (block[0], delay)
        return completed

    def rate(self) -> tuple[float, float, float] | None:
        """(rate, its sigma, span s) once the floors span ``min_span_s``; None before, or when
        the rate is beyond ``max_rate``."""
        if len(self._floors) < 3:
            return None
        t, d = np.array(self._floors).T
        span = t[-1] - t[0]
        if span < self.min_span_s:
            return None
        tc = t - t.mean()
        slope = float(tc @ (d - d.mean()) / (tc @ tc))
        residual = d - d.mean() - slope * tc
        sigma = math.sqrt(float(residual @ residual) / (len(t) - 2) / float(tc @ tc))
        if abs(slope) > self.max_rate:
            return None
        return 0.0 - slope, sigma, span  # (a flat trend is +0, not -0)
