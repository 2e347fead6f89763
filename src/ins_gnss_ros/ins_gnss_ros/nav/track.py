"""A navigation solution sampled at epochs: the common part of the navigator's forward pass, the
smoothed pass and the simulated truth."""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass
class Track:
    """Positions, velocities and attitudes at k epochs.

    Attributes
    ----------
    t : (k,) s
    lat, lon, h : (k,) rad, rad, m
        Geodetic position of the IMU, WGS-84.
    v_enu : (k, 3) m/s
        Velocity relative to the Earth, ENU.
    q_nb : (k, 4)
        Attitude, Hamilton scalar-first, body FLU to ENU.
    """

    t: np.ndarray
    lat: np.ndarray
    lon: np.ndarray
    h: np.ndarray
    v_enu: np.ndarray
    q_nb: np.ndarray

    def state(self, k):
        """NavState of epoch k."""
        # Imported here: strapdown.py compiles its kernels on import (0.6 s), which the truth
        # records of sim/ (sim/trajectory.py) do not need.
        from .strapdown import NavState

        return NavState(self.lat[k], self.lon[k], self.h[k], self.v_enu[k], self.q_nb[k],
                        self.t[k])
