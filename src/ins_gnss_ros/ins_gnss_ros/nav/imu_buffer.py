"""The IMU samples the navigator has been given and may still need (a delayed measurement
re-runs them from a checkpoint)."""
from __future__ import annotations

import numpy as np

from .coning import coning_sculling


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
        return tuple(a[i - self.first:j - self.first] for a in self._store)

    def search(self, t):
        """Number of the first sample ending after time t (s), or :attr:`end`."""
        return self.first + int(np.searchsorted(self._store[0][:self._n], t, side="right"))

    def add(self, t, dtheta, dv, needed, compensated=False):
        """Add samples (t (N,) s, raw dtheta (N, 3) rad and dv (N, 3) m/s) with their coning
        and sculling terms, after dropping those before sample number `needed` (:meth:`trim`).
        ``compensated``: the increments have their terms already (imu/delta): zero terms.
        """
        if compensated:
            # Compensated once already: adding the terms again doubles them and parts the
            # filter from the strapdown node it keeps in step.
            self.trim(needed)
            self._append(t, dtheta, dv, np.zeros_like(dtheta), np.zeros_like(dv))
            return
        # Second-order coning/sculling/rotation terms of the raw samples, one batch at a time
        # (one-sample algorithm chained across batches). Computing them before the bias
        # compensation changes them by (bias dt) x (increment) ~ 1e-6 m/s per sample for a
        # 0.2 deg/s gyro bias at 100 Hz: far below the sensor noise, and it keeps the
        # per-segment work to a subtraction.
        # Each sample's predecessor (filled in place: np.vstack costs more than the copy in
        # the ekf node, which adds one sample per call).
        prev_th, prev_dv = np.zeros_like(dtheta), np.zeros_like(dv)
        if self._n:
            prev_th[0], prev_dv[0] = self._store[1][self._n - 1], self._store[2][self._n - 1]
        prev_th[1:], prev_dv[1:] = dtheta[:-1], dv[:-1]
        rot, dvn = coning_sculling(dtheta[:, None, :], dv[:, None, :], "one_sample",
                                   prev=(prev_th, prev_dv))
        self.trim(needed)
        self._append(t, dtheta, dv, rot - dtheta, dvn - dv)

    def _append(self, *columns):
        """Append samples: t (N,), dtheta, dv, cth, cdv (N, 3)."""
        n, m = self._n, len(columns[0])
        store = self._store if n else None
        if store is None or n + m > len(store[0]):
            capacity = max(4096, 2 * (n + m))
            store = [np.empty((capacity,) + c.shape[1:]) for c in columns]
            for a, old in zip(store, self._store if n else ()):
                a[:n] = old[:n]
            self._store = store
        for a, c in zip(store, columns):
            a[n:n + m] = c
        self._n = n + m

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
