"""Coning and sculling compensation: sensor-rate increments to navigation-rate increments.

Given N sensor sub-samples of one navigation interval [t(k-1), t(k)] — gyro angle increments
dtheta_i = int omega_ib dt and accelerometer velocity increments dv_i = int f_b dt, both raw
integrals in the (rotating) body frame — compute

* the rotation vector phi of b(k) relative to b(k-1) (Bortz equation to second order):
  phi = alpha + 1/2 int alpha x omega dt,  alpha(t) = int_{t(k-1)}^t omega dt;
* the specific-force velocity increment resolved in b(k-1):
  dv = upsilon + 1/2 alpha x upsilon + 1/2 int (alpha x f + upsilon x omega) dt,
  upsilon(t) = int f dt; the middle term is the rotation compensation and the last the
  sculling term (Savage, "Strapdown Analytics", ch. 7).

Splitting the interval into blocks (one or two sub-samples) makes the integrals exact between
blocks: 1/2 int alpha x omega = sum_B [1/2 alpha_start(B) x dtheta_B + c_B], where the
within-block coning c_B is the only approximation, and likewise for sculling:

* ``"two_sample"`` (Ignagni; Savage ch. 7): blocks are pairs of sub-samples,
  c = 2/3 dtheta_1 x dtheta_2, s = 2/3 (dtheta_1 x dv_2 + dv_1 x dtheta_2); N must be even.
* ``"one_sample"`` ("previous-interval" form, Savage ch. 7): blocks are single
  sub-samples, c = 1/12 dtheta_prev x dtheta, s = 1/12 (dtheta_prev x dv + dv_prev x dtheta),
  using the sub-sample before it (from the previous interval for the first one).

Both are exact for angular rate and specific force linear in time.

Residual for classic coning (half-cone angle beta at frequency Omega, transverse rate
amplitude Omega sin(beta)) over a block of length T_B: with u = Omega T_B / 2 the sub-sample
increments are chords of a circle of radius sin(beta), so the two-sample correction is
sin(beta)^2 (2/3)(2 sin u - sin 2u) and the true value sin(beta)^2 (2u - sin 2u) / 2; their
difference is -sin(beta)^2 u^5 / 30 + O(u^7). Divided by T_B this is a drift about the coning
axis of

    two-sample:  -sin(beta)^2 Omega (Omega T_B)^4 / 960,
    one-sample:  -sin(beta)^2 Omega (Omega T_B)^4 / 60      (same derivation, u = Omega T_B)

(cf. Ignagni, "Efficient class of optimized coning compensation algorithms", JGCD 1996).
For classic sculling (angular oscillation beta sin(Omega t) about x, specific force
A sin(Omega t) along y) the same algebra with (Omega sin beta)^2 / Omega^2 -> beta A / Omega
gives a velocity drift along z of -beta A (Omega T_B)^4 / 960 (two-sample) and / 60
(one-sample), against the true rectified acceleration A J1(beta) ~ beta A / 2.
"""
from __future__ import annotations

import numpy as np

from . import _kernels

METHODS = ("one_sample", "two_sample")


def coning_sculling(dtheta, dv, method: str = "two_sample", prev=None):
    """Compensated increments over one navigation interval from N sensor sub-samples.

    Parameters
    ----------
    dtheta : array_like, shape (..., N, 3)
        Gyro angle increments of the sub-samples, rad, body frame.
    dv : array_like, shape (..., N, 3)
        Accelerometer velocity increments of the sub-samples, m/s, body frame.
    method : {"two_sample", "one_sample"}
        See the module docstring. "two_sample" needs an even N.
    prev : tuple of array_like, shape (..., 3), optional
        (dtheta, dv) of the last sub-sample before this interval, for "one_sample"; zeros if
        None (start of the data).

    Returns
    -------
    phi : ndarray, shape (..., 3)
        Rotation vector of b(k) relative to b(k-1), rad.
    dv_nav : ndarray, shape (..., 3)
        Specific-force velocity increment resolved in b(k-1), m/s.
    """
    dtheta = np.asarray(dtheta, float)
    dv = np.asarray(dv, float)
    n = dtheta.shape[-2]
    if method not in METHODS:
        raise ValueError(f"method must be one of {METHODS}, got {method!r}")
    if method == "two_sample" and n % 2:
        raise ValueError(f"two_sample needs an even number of sub-samples, got {n}")
    lead = dtheta.shape[:-2] if dtheta.shape == dv.shape else \
        np.broadcast_shapes(dtheta.shape[:-2], dv.shape[:-2])

    def stacked(x, shape):
        # C-contiguous and writeable, so that the kernel is compiled for one array type only
        # (checked first: this runs once per sample in the navigator).
        if x.shape != lead + shape:
            x = np.broadcast_to(x, lead + shape)
        if not (x.flags.c_contiguous and x.flags.writeable):
            x = np.array(x, order="C")
        return x.reshape((-1,) + shape)

    th, v = stacked(dtheta, (n, 3)), stacked(dv, (n, 3))
    m = th.shape[0]
    if method == "two_sample" or prev is None:
        prev_th = prev_v = np.zeros((m, 3))
    else:
        prev_th, prev_v = stacked(np.asarray(prev[0], float), (3,)), \
            stacked(np.asarray(prev[1], float), (3,))
    phi, dv_nav = np.empty((m, 3)), np.empty((m, 3))
    # Compiled: this runs once per navigation interval in the imu_preprocessor node and once per
    # sample in the navigator, where numpy's per-call overhead (np.cross) dominated.
    _kernels.coning_sculling_run(th, v, prev_th, prev_v, method == "two_sample", phi, dv_nav)
    return phi.reshape(lead + (3,)), dv_nav.reshape(lead + (3,))


def to_navigation_rate(dthetas, dvs, n_sub: int, method: str = "two_sample"):
    """Batch conversion of a sensor-rate increment stream to navigation-rate increments.

    Parameters
    ----------
    dthetas, dvs : array_like, shape (M * n_sub, 3)
        Sensor increments (rad, m/s), body frame; a trailing incomplete interval is dropped.
    n_sub : int
        Sub-samples per navigation interval.
    method : {"two_sample", "one_sample"}

    Returns
    -------
    phi, dv_nav : ndarray, shape (M, 3)
        As :func:`coning_sculling` for each interval; "one_sample" chains the previous
        sub-sample across intervals (zeros before the first).
    """
    dthetas = np.asarray(dthetas, float)
    dvs = np.asarray(dvs, float)
    m = len(dthetas) // n_sub
    th = dthetas[:m * n_sub].reshape(m, n_sub, 3)
    v = dvs[:m * n_sub].reshape(m, n_sub, 3)
    prev = None
    if method == "one_sample":
        prev = (np.vstack([np.zeros(3), th[:-1, -1]]), np.vstack([np.zeros(3), v[:-1, -1]]))
    return coning_sculling(th, v, method, prev)


class Integrator:
    """Streaming accumulator of sensor samples into navigation-rate increments.

    Feed samples one at a time with :meth:`add` (increments) or :meth:`add_rates` (rates,
    integrated as rate * dt, i.e. assumed constant over the sample); every ``n_sub`` samples a
    compensated (phi, dv, dt) triple is returned, otherwise None.

    Parameters
    ----------
    n_sub : int
        Sensor samples per navigation interval (e.g. 12 for 1200 Hz -> 100 Hz).
    method : {"two_sample", "one_sample"}
    """

    def __init__(self, n_sub: int, method: str = "two_sample"):
        if method not in METHODS:
            raise ValueError(f"method must be one of {METHODS}, got {method!r}")
        if method == "two_sample" and n_sub % 2:
            raise ValueError("two_sample needs an even n_sub")
        self.n_sub = n_sub
        self.method = method
        self.reset()

    def reset(self):
        """Drop buffered samples and the previous-sample memory (e.g. after a data gap)."""
        # Pre-allocated (1, n_sub, 3) buffers filled row by row: one compiled call per interval
        # and no per-sample array creation.
        self._th = np.empty((1, self.n_sub, 3))
        self._v = np.empty((1, self.n_sub, 3))
        self._count = 0
        self._dt = 0.0
        self._prev_th = np.zeros((1, 3))
        self._prev_v = np.zeros((1, 3))

    @property
    def remaining(self) -> int:
        """Samples still to add, the next one included, until an increment completes."""
        return self.n_sub - self._count

    def add(self, dtheta, dv, dt: float):
        """Add one sample of increments (rad, m/s over dt seconds)."""
        self._th[0, self._count] = dtheta
        self._v[0, self._count] = dv
        self._count += 1
        self._dt += dt
        if self._count < self.n_sub:
            return None
        phi, dv_nav = np.empty((1, 3)), np.empty((1, 3))
        _kernels.coning_sculling_run(self._th, self._v, self._prev_th, self._prev_v,
                                     self.method == "two_sample", phi, dv_nav)
        out = (phi[0], dv_nav[0], self._dt)
        self._prev_th[0], self._prev_v[0] = self._th[0, -1], self._v[0, -1]
        self._count, self._dt = 0, 0.0
        return out

    def add_rates(self, omega, f, dt: float):
        """Add one sample of angular rate (rad/s) and specific force (m/s^2) held over dt."""
        # (Elementwise in Python: this runs for every sample of the imu_preprocessor, where
        # two numpy conversions cost as much as the rest of the call.)
        return self.add([w * dt for w in omega], [a * dt for a in f], dt)
