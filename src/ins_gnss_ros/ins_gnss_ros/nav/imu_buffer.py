"""The IMU samples the navigator has been given and may still need (a delayed measurement
re-runs them from a checkpoint)."""
from __future__ import annotations

import numpy as np

from . import _kernels


class ImuBuffer:
    """IMU samples by sample number: each sample keeps its number for as long as it is kept.

    A sample is its end time t (s), its raw gyro and accelerometer increments dtheta (rad) and
    dv (m/s), and their second-order coning/sculling terms cth, cdv (body FLU). The numbering
    starts at 0 with the first sample; :meth:`trim` drops old samples without renumbering the
    others, so a checkpoint can keep the number of the next sample to process.

    The columns are the filled rows of larger arrays whose capacity doubles when full, so that
    adding one sample at a time (the ekf node) costs a row copy, not a copy of the whole buffer
    as with np.concatenate.
    """

    def __init__(self):
        self.first = 0          # number of the oldest sample kept
        self._n = 0             # samples kept
        self._store = None

    def __len__(self):
        """Number of samples kept."""
        return self._n

    @property
    def end(self):
        """Number of the sample after the newest one."""
        return self.first + self._n

    @property
    def last_time(self):
        """End time of the newest sample, s (-inf when empty)."""
        return self._store[0][self._n - 1] if self._n else -np.inf

    def time(self, i):
        """End time of sample i, s."""
        return self._store[0][i - self.first]

    def times(self, i, j):
        """End times of samples i..j-1 (a view)."""
        return self._store[0][i - self.first:j - self.first]

    def rows(self, i, j):
        """(t, dtheta, dv, cth, cdv) of samples i..j-1 (views)."""
        i, j = i - self.first, j - self.first
        t, th, dv, cth, cdv = self._store
        return t[i:j], th[i:j], dv[i:j], cth[i:j], cdv[i:j]

    def search(self, t):
        """Number of the first sample ending after time t (s), or :attr:`end`."""
        # The array's method with a positional side: np.searchsorted's wrapper and keyword cost
        # more than the search (the navigator searches a few times per sample).
        return self.first + int(self._store[0][:self._n].searchsorted(t, "right"))

    def add(self, t, dtheta, dv, needed, compensated=False):
        """Add samples (t (N,) s, raw dtheta (N, 3) rad and dv (N, 3) m/s) with their coning
        and sculling terms, after dropping those before sample number `needed` (:meth:`trim`).
        ``compensated``: the increments have their terms already (imu/delta): zero terms.
        """
        n, m = self._n, len(t)
        times, th, v, cth, cdv = self._reserve(m)
        times[n:n + m], th[n:n + m], v[n:n + m] = t, dtheta, dv
        if compensated:
            # Compensated once already: adding the terms again doubles them and parts the
            # filter from the strapdown node it keeps in step.
            cth[n:n + m] = 0.0
            cdv[n:n + m] = 0.0
        else:
            # Second-order coning/sculling/rotation terms of the raw samples, one batch at a
            # time (one-sample algorithm chained across batches). Computing them before the
            # bias compensation changes them by (bias dt) x (increment) ~ 1e-6 m/s per sample
            # for a 0.2 deg/s gyro bias at 100 Hz: far below the sensor noise, and it keeps
            # the per-segment work to a subtraction.
            # Each sample's predecessor is the row before it in the store (zeros before the
            # first sample); the compiled kernel is called on views of the store, since the
            # ekf node adds one sample per call and the checks of coning.coning_sculling cost
            # more than its arithmetic there.
            if n:
                prev_th, prev_v = th[n - 1:n + m - 1], v[n - 1:n + m - 1]
            else:
                prev_th, prev_v = np.zeros((m, 3)), np.zeros((m, 3))
                prev_th[1:], prev_v[1:] = th[:m - 1], v[:m - 1]
            rows = slice(n, n + m)
            _kernels.coning_sculling_run(th[rows].reshape(m, 1, 3), v[rows].reshape(m, 1, 3),
                                         prev_th, prev_v, False, cth[rows], cdv[rows])
            cth[rows] -= th[rows]   # the terms: compensated increment minus raw
            cdv[rows] -= v[rows]
        self._n = n + m
        self.trim(needed)  # after: the newest sample before them was their predecessor

    def _reserve(self, m):
        """The store, with room for m more samples (its capacity doubled when full)."""
        n = self._n
        if self._store is None or n + m > len(self._store[0]):
            capacity = max(4096, 2 * (n + m))
            store = [np.empty((capacity,) + shape) for shape in ((), (3,), (3,), (3,), (3,))]
            for a, old in zip(store, self._store if n else ()):
                a[:n] = old[:n]
            self._store = store
        return self._store

    def trim(self, needed, keep_min=2000):
        """Drop the samples before number `needed` once there are at least `keep_min` of them
        (streaming memory stays bounded; moved to the front of the arrays, which keep their
        size)."""
        first = needed - self.first
        if first < keep_min:
            return
        n = self._n
        for a in self._store:
            a[:n - first] = a[first:n]
        self._n = n - first
        self.first = needed
