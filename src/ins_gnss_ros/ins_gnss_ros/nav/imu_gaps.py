"""Process noise of IMU data the caller bridged: gaps held with the rates after them, and
samples the IMU preprocessor interpolated (their measured miss)."""
from __future__ import annotations

import numpy as np


class BridgedGaps:
    """The bridged gaps a delayed measurement can still re-run through.

    Parameters
    ----------
    accel_sigma, rate_sigma : float
        Standard deviation of the difference between the held and the true specific force
        (m/s^2) and angular rate (rad/s), averaged over a gap held by the caller
        (NavigatorConfig.gap_*_sigma).
    """

    def __init__(self, accel_sigma, rate_sigma):
        self.accel_sigma, self.rate_sigma = accel_sigma, rate_sigma
        self.gaps = []  # (start s, end s, angle variance rad^2, velocity variance (m/s)^2)

    def add(self, t_start, t_end, horizon, angle_var=None, velocity_var=None):
        """The samples between t_start and t_end (s) were bridged; gaps that end before
        `horizon` (s) are forgotten. The variances per axis (rad^2, (m/s)^2) the bridge may
        miss by over the whole gap: by default those of holding the rates, (sigma T)^2."""
        T = t_end - t_start
        if angle_var is None:
            angle_var, velocity_var = (self.rate_sigma * T) ** 2, (self.accel_sigma * T) ** 2
        self.gaps = [g for g in self.gaps if g[1] > horizon] + \
            [(t_start, t_end, angle_var, velocity_var)]

    def add_noise(self, P, space, t0, t1, yaw_known):
        """Add to P (in place) the process noise of the bridges' miss over the part of
        [t0, t1] (s) that lies in a bridged gap.

        A bridge over T s misses the true specific force and rate by up to what it may miss
        (for held rates accel_sigma and rate_sigma). The miss is modelled as white noise whose
        PSD spreads its variance over the gap: over the whole gap it adds that variance to the
        velocity and attitude, and the propagation carries the velocity part into position
        (sigma^2 T^4 / 3 for held rates). Unlike a constant miss, it grows with the time spent
        in the gap (GNSS epochs inside the gap are applied against the part accrued so far) and
        does not tie position to velocity exactly: with a constant miss (position = velocity
        T / 2) one velocity fix after a 1.9 s gap took the position sigma from 1.9 m to 0.09 m
        while the real error was 0.6 m (docs/results/faults.md).

        Parameters
        ----------
        P : (n, n) ndarray
        space : StateSpace
        t0, t1 : float
            s.
        yaw_known : bool
            Without it the yaw stays out of the filter until the heading alignment.
        """
        for g0, g1, angle_var, velocity_var in self.gaps:
            inside = min(t1, g1) - max(t0, g0)
            if inside <= 0.0:
                continue
            share = inside / (g1 - g0)
            qw = np.full(3, angle_var * share)
            if not yaw_known:
                qw[2] = 0.0
            P[space["vel"], space["vel"]] += velocity_var * share * np.eye(3)
            P[space["att"], space["att"]] += np.diag(qw)
