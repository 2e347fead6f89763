"""Rest detection for the aiding front end: an IMU that is still and fixes that do not move.

A receiver that outputs no velocity (NMEA GGA, many SBAS units) leaves the filter without the
speed that tells it the vehicle stands, so it would neither use the fixes of a static start nor
learn the gyro biases there; a receiver whose velocity scatters beyond the speed that tells
rest (0.2 m/s per axis against 0.1 m/s) leaves it just as uninformed (nav/aiding.py asks the
detector behind it while the heading is unknown). An IMU alone cannot tell rest from steady
straight motion (the specific force and the rate are the same), so rest is declared only when
both agree:

* IMU: in blocks of ``BLOCK_S`` the scatter of the specific force and of the rate about their
  block means stays within what the sensor's white noise and a small vibration explain (the
  variance test among the zero-velocity detectors of I. Skog, P. Handel, J.-O. Nilsson and
  J. Rantakokko, "Zero-velocity detection - an algorithm evaluation", IEEE Trans. Biomed. Eng.
  57(11), 2010), and the block means stay those of the first still block (a smooth start has
  no scatter within a block, but its specific force changes), for at least ``MIN_STILL_S``;
* GNSS: the velocity fitted by least squares to the fixes since the IMU became still is below
  ``REST_SPEED`` with three sigmas to spare (a noisy receiver simply takes longer to confirm),
  and in all three axes consistent with zero: an IMU can also hold still for a second or two
  in slow steady motion, and a vessel in waves does, its heave of 0.5 m/s plain in fixes of
  centimetres (docs/results/product_path.md, "2026-12-07 (session 39)").

While both hold, every still block is a cue for a zero-velocity update (nav/aiding.py uses
them while the filter aligns); any block with motion in it ends the rest at once.
"""
from __future__ import annotations

import math

import numpy as np

from .course import SLOW_ERROR_RATE
from .earth import ecef_to_enu_matrix, geodetic_to_ecef
from .gating import chi2_gate

#: Length of the IMU blocks whose scatter is tested, s.
BLOCK_S = 0.25
#: Stillness needed before the fixes are asked, s.
MIN_STILL_S = 1.0
#: Vibration a standing vehicle may show beyond the sensor noise (1 sigma per axis): 5 mg and
#: 0.2 deg/s, an engine idling on soft mounts shows more (its rest then goes undetected, and the
#: filter waits for motion as without this detector).
VIBRATION_ACCEL = 0.05
VIBRATION_RATE = math.radians(0.2)
#: The block scatter may reach this many times its expectation at rest (a chi-square of 3(n-1)
#: degrees of freedom over n samples stays below twice its mean for n >= 20 at 1e-4).
SCATTER_MARGIN = 2.0
#: Horizontal speed the fixes must rule out (at three sigmas) to declare rest, m/s.
REST_SPEED = 0.5
#: A run's fitted velocity beyond this quantile of its chi-square (three degrees of freedom,
#: the fit's covariance of the fixes' white noise, and the rate of their slow error: their
#: absolute sigma over the run's length, at least SLOW_ERROR_RATE, twice that vertically) is
#: motion, whatever its size.
MOTION_QUANTILE = 0.999
#: Degrees of freedom of a receiver velocity's scatter in still runs before it is its noise.
MIN_VELOCITY_DOF = 10
#: Longest a fix or a receiver velocity waits for the IMU blocks of its time, s (beyond it the
#: IMU is missing, not late: it counts for no run).
MAX_FIX_WAIT_S = 5.0


def _sum3(values) -> float:
    """Sum of three floats in order, as numpy sums three (not math.fsum's exact sum)."""
    a, b, c = values
    return a + b + c


def _wait(queue: list, item: tuple) -> None:
    """Queue an input (its time first) ahead of the judged IMU blocks, forgetting those
    older than ``MAX_FIX_WAIT_S`` before it."""
    queue.append(item)
    del queue[:sum(1 for waiting in queue if waiting[0] < item[0] - MAX_FIX_WAIT_S)]


def _reached(queue: list, t: float) -> list:
    """The queued inputs of time t (s) or before, taken off the queue (in time order)."""
    reached = [item for item in queue if item[0] <= t]
    del queue[:len(reached)]
    return reached


class RestDetector:
    """Decides from IMU increments and GNSS fixes whether the vehicle stands.

    Parameters
    ----------
    accel_psd, gyro_psd : float
        White-noise densities of the accelerometers ((m/s^2)^2/Hz) and gyros ((rad/s)^2/Hz).
    """

    def __init__(self, accel_psd: float, gyro_psd: float):
        self.accel_psd, self.gyro_psd = accel_psd, gyro_psd
        self._block = None          # [t_start, n, dt, the block's sums (see increment)]
        self._reference = None      # block means (f, w) at the start of the still run
        self._any_block = False     # a block has been judged
        self.still_since = math.nan  # start of the current run of still blocks, s
        # the same, whatever the fixes say of it (motion they see ends the run, not this), s
        self.blocks_still_since = math.nan
        self.at_rest = False         # the fixes of this run confirmed rest
        self.still_until = -math.inf  # end of the last still block, s
        self._fixes = None           # least-squares sums of the run's fixes
        self._velocities = None      # the run's receiver velocities: [n, sum east, sum north,
        #                              sum of squares east, north]
        self._velocities_pending = []  # (t, east, north) ahead of the judged blocks
        self._velocity_scatter = [0.0, 0]  # squared deviations and dof of the ended runs
        self._moving_unseen = False  # the fixes showed motion the IMU cannot: until it moves
        self._judged_until = -math.inf  # end of the last IMU block judged, s
        self._fixes_waiting = []  # fixes ahead of it, as fix's arguments

    @property
    def undecided(self) -> bool:
        """No IMU block seen yet (a driver or preprocessor still measuring its rate), or the
        IMU is still but the fixes have not yet confirmed rest."""
        return not self._any_block or (not math.isnan(self.still_since) and not self.at_rest)

    def imu_still(self, t: float) -> bool:
        """The IMU alone has been still for ``MIN_STILL_S`` by t (s): at rest or in steady
        straight motion, which only the fixes tell apart."""
        return t - self.still_since >= MIN_STILL_S  # False while still_since is NaN

    def blocks_still(self, t: float) -> bool:
        """The IMU's blocks have been still for ``MIN_STILL_S`` by t (s), whatever the fixes
        said meanwhile: the vehicle's acceleration is constant (rest, steady straight motion or
        a steady acceleration), so that the fixes' third differences are their noise alone."""
        return t - self.blocks_still_since >= MIN_STILL_S  # False while NaN

    def increment(self, t: float, dtheta: np.ndarray, dv: np.ndarray, dt: float) -> bool:
        """Add an IMU increment over dt (s) ending at t (s). Returns True when it closed a
        still block while rest is confirmed (the caller's cue for a zero-velocity update)."""
        # Python floats, not numpy: every increment comes here, and numpy's per-call overhead
        # on 3-vectors was ~60 us of it (the same IEEE operations in the same order).
        b = self._block
        if b is None:
            self._block = b = [t - dt, 0, dt, [0.0] * 12]
        b[1] += 1
        sums = b[3]   # sum f (3), sum f^2 (3), sum w (3), sum w^2 (3)
        for k, v in enumerate(dv.tolist()):
            f = v / dt
            sums[k] += f
            sums[3 + k] += f * f
        for k, v in enumerate(dtheta.tolist()):
            w = v / dt
            sums[6 + k] += w
            sums[9 + k] += w * w
        if t - b[0] < BLOCK_S:
            return False
        self._block = None
        self._any_block = True
        self._judged_until = t
        velocities = _reached(self._velocities_pending, t)
        reached = _reached(self._fixes_waiting, t)
        if self._still(b):
            self.still_until = t
            if math.isnan(self.still_since):
                self.still_since = b[0]
            if math.isnan(self.blocks_still_since):
                self.blocks_still_since = b[0]
            for _, v_east, v_north in velocities:
                self._add_velocity(v_east, v_north)
            for fix in reached:
                self._add_fix(*fix)
            return self.at_rest
        self._end_run()
        self.blocks_still_since, self._moving_unseen = math.nan, False
        return False

    def _still(self, b) -> bool:
        t0, n, dt, sums = b
        if n < 2:
            return False
        var_f = _sum3(sums[3 + k] - sums[k] * sums[k] / n for k in range(3)) / (n - 1)
        var_w = _sum3(sums[9 + k] - sums[6 + k] * sums[6 + k] / n for k in range(3)) / (n - 1)
        # Per-sample variance of white noise of density q at interval dt: q / dt per axis.
        noise_f, noise_w = self.accel_psd / dt, self.gyro_psd / dt
        if var_f > SCATTER_MARGIN * 3.0 * (noise_f + VIBRATION_ACCEL ** 2) or \
                var_w > SCATTER_MARGIN * 3.0 * (noise_w + VIBRATION_RATE ** 2):
            return False
        means = [sums[k] / n for k in range(3)], [sums[6 + k] / n for k in range(3)]
        if self._reference is None:
            self._reference = means
            return True
        # The difference of two block means: twice the noise of one mean, plus the vibration.
        df = _sum3((m - r) * (m - r) for m, r in zip(means[0], self._reference[0]))
        dw = _sum3((m - r) * (m - r) for m, r in zip(means[1], self._reference[1]))
        return df <= SCATTER_MARGIN * 3.0 * (2.0 * noise_f / n + VIBRATION_ACCEL ** 2) and \
            dw <= SCATTER_MARGIN * 3.0 * (2.0 * noise_w / n + VIBRATION_RATE ** 2)

    def _end_run(self) -> None:
        self.still_since, self.at_rest, self._fixes = math.nan, False, None
        self._reference = None
        ss, dof = self._run_scatter()
        self._velocity_scatter[0] += ss
        self._velocity_scatter[1] += dof
        self._velocities = None

    def velocity(self, t: float, v_east: float, v_north: float) -> None:
        """A receiver velocity (m/s) of time t (s): within a still run the velocity is constant
        (rest, or steady straight motion), so its scatter there is the receiver's noise. It
        counts once the IMU block it falls in closes still (the first block of a motion ends
        the run); one behind the judged blocks counts if it falls in the still run going on
        (one of a run already ended is left out). Placed by its time, as the fixes are
        (:meth:`fix`), not by its arrival: counted in the block that closed next, the node
        graph, whose increments reach the filter a second after the receiver's first
        velocities (the preprocessor waits for /tf_static), measured the receiver's noise on
        other velocities than `trial replay --offline` and aligned a robot's heading a fix
        earlier (docs/results/product_path.md, "2026-12-07 (session 44)")."""
        if t > self._judged_until:
            _wait(self._velocities_pending, (t, v_east, v_north))
        elif self.still_since <= t <= self.still_until == self._judged_until:
            self._add_velocity(v_east, v_north)

    def _add_velocity(self, v_east: float, v_north: float) -> None:
        if self._velocities is None:
            self._velocities = [0, 0.0, 0.0, 0.0, 0.0]
        v = self._velocities
        v[0] += 1
        v[1] += v_east
        v[2] += v_north
        v[3] += v_east * v_east
        v[4] += v_north * v_north

    def velocity_noise(self) -> float:
        """The receiver velocity's noise per horizontal axis (m/s) from its scatter in still
        runs, NaN before ``MIN_VELOCITY_DOF`` degrees of freedom."""
        ss, dof = self._run_scatter()
        ss, dof = ss + self._velocity_scatter[0], dof + self._velocity_scatter[1]
        return math.sqrt(ss / dof) if dof >= MIN_VELOCITY_DOF else math.nan

    def _run_scatter(self) -> tuple[float, int]:
        """Squared deviations of the current run's velocities about their mean, and their
        degrees of freedom (both axes)."""
        v = self._velocities
        if v is None or v[0] < 2:
            return 0.0, 0
        n = v[0]
        return v[3] - v[1] * v[1] / n + v[4] - v[2] * v[2] / n, 2 * (n - 1)

    def fix(self, t: float, lat: float, lon: float, h: float, cov_enu: np.ndarray,
            absolute_var: tuple[float, float]) -> bool:
        """Add a fix at t (s; rad, rad, m, ENU covariance m^2 of its fix-to-fix noise, which
        the fit of a velocity sees, and its absolute variance per horizontal axis and
        vertically, m^2, whose slow part drifts over a run) and return whether the vehicle is
        confirmed at rest: the IMU still for ``MIN_STILL_S`` and the fixes of the still run
        moving at less than ``REST_SPEED`` with three sigmas to spare, at a velocity
        consistent with zero.

        A fix ahead of the IMU's judged blocks waits for them (up to MAX_FIX_WAIT_S) and counts
        if the block it falls in is still: the node graph's increments reach the filter after
        the fixes of their time (the preprocessor measures the IMU's rate first), and judged
        on arrival the first fixes of a standing start counted for no run, so that the graph
        confirmed rest 3 s after `trial replay --offline` (docs/results/product_path.md,
        "2026-12-06 (session 38)")."""
        if t > self._judged_until:
            _wait(self._fixes_waiting, (t, lat, lon, h, cov_enu, absolute_var))
            return self.at_rest
        return self._add_fix(t, lat, lon, h, cov_enu, absolute_var)

    def _add_fix(self, t: float, lat: float, lon: float, h: float, cov_enu: np.ndarray,
                 absolute_var: tuple[float, float]) -> bool:
        """:meth:`fix` once the IMU's blocks reach t."""
        if math.isnan(self.still_since) or t < self.still_since or self._moving_unseen:
            self._fixes = None
            return False
        r = geodetic_to_ecef(lat, lon, h)
        if self._fixes is None:
            self._fixes = {"r0": r, "R": ecef_to_enu_matrix(lat, lon), "t0": t, "n": 0,
                           "st": 0.0, "stt": 0.0, "sx": [0.0] * 3, "stx": [0.0] * 3}
        s = self._fixes
        # The sums of the east, north and up components in Python floats (the same IEEE
        # operations as numpy's on 3-vectors, without its per-call cost at every fix).
        x = s["R"].dot(r - s["r0"]).tolist()  # (dot: @ at half the cost, course.py)
        tau = t - s["t0"]
        s["n"] += 1
        s["st"] += tau
        s["stt"] += tau * tau
        sx, stx = s["sx"], s["stx"]
        for k in range(3):
            sx[k] += x[k]
            stx[k] += tau * x[k]
        horizontal = 0.5 * float(cov_enu[0, 0] + cov_enu[1, 1])  # the caller's latest estimate
        var = (horizontal, horizontal, float(cov_enu[2, 2]))
        n = s["n"]
        spread = s["stt"] - s["st"] ** 2 / n  # sum of (t - mean t)^2
        if n < 3 or t - self.still_since < MIN_STILL_S or spread <= 0.0:
            return self.at_rest
        v = [(stx[k] - s["st"] * sx[k] / n) / spread for k in range(3)]
        sigma_v = math.sqrt(horizontal / spread)
        # (a receiver's error of metres that the white noise leaves out wanders by about its
        # sigma over a run of seconds: a standing robot's fixes of 1 m without covariance
        # passed for motion 5 s into the standstill)
        span = t - s["t0"]
        slow = [max(SLOW_ERROR_RATE, math.sqrt(absolute_var[0]) / span)] * 2 + \
            [max(2.0 * SLOW_ERROR_RATE, math.sqrt(absolute_var[1]) / span)]
        moving = sum(v[k] * v[k] / (var[k] / spread + slow[k] ** 2) for k in range(3)) \
            > chi2_gate(3, MOTION_QUANTILE)
        if moving or math.hypot(v[0], v[1]) - 3.0 * sigma_v > REST_SPEED:
            self._end_run()   # steady motion the IMU cannot see: not at rest until it moves
            self._moving_unseen = True
        elif math.hypot(v[0], v[1]) + 3.0 * sigma_v < REST_SPEED:
            self.at_rest = True
        return self.at_rest
