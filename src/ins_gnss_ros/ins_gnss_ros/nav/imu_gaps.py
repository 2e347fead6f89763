"""Process noise of gaps in the IMU data that the caller bridged by holding the rates."""
from __future__ import annotations

import numpy as np


class BridgedGaps:
    """The bridged gaps a delayed measurement can still re-run through.

    Parameters
    ----------
    accel_sigma, rate_sigma : float
        Standard deviation of the difference between the held and the true specific force
        (m/s^2) and angular rate (rad/s), averaged over a gap (NavigatorConfig.gap_*_sigma).
    """

    def __init__(self, accel_sigma, rate_sigma):
        self.accel_sigma, self.rate_sigma = accel_sigma, rate_sigma
        self.gaps = []  # (start, end), s

    def add(self, t_start, t_end, horizon):
        """The samples between t_start and t_end (s) were bridged; gaps that end before
        `horizon` (s) are forgotten."""
        self.gaps = [g for g in self.gaps if g[1] > horizon] + [(t_start, t_end)]

    def add_noise(self, P, space, t0, t1, yaw_known):
        """Add to P (in place) the process noise of the held-rate error over the part of
        [t0, t1] (s) that lies in a bridged gap.

        Holding the rates of one increment over a gap of T s misses the true specific force and
        rate by up to accel_sigma and rate_sigma. The miss is modelled as white noise of PSD
        sigma^2 T over the gap: over the whole gap it adds the variance (sigma T)^2 of a
        constant miss to the velocity and attitude, and the propagation carries the velocity
        part into position (sigma^2 T^4 / 3). Unlike a constant miss, it grows with the time
        spent in the gap (GNSS epochs inside the gap are applied against the part accrued so
        far) and does not tie position to velocity exactly: with a constant miss (position =
        velocity T / 2) one velocity fix after a 1.9 s gap took the position sigma from 1.9 m to
        0.09 m while the real error was 0.6 m (docs/results/faults.md).

        Parameters
        ----------
        P : (n, n) ndarray
        space : StateSpace
        t0, t1 : float
            s.
        yaw_known : bool
            Without it the yaw stays out of the filter until the heading alignment.
        """
        for g0, g1 in self.gaps:
            inside = min(t1, g1) - max(t0, g0)
            if inside <= 0.0:
                continue
            T = g1 - g0
            qw = np.full(3, self.rate_sigma ** 2 * T * inside)
            if not yaw_known:
                qw[2] = 0.0
            P[space["vel"], space["vel"]] += self.accel_sigma ** 2 * T * inside * np.eye(3)
            P[space["att"], space["att"]] += np.diag(qw)
