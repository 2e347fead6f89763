"""The continuous ``odom`` frame of REP-105 for a filter that fuses wheel odometry.

REP-105 asks of ``odom -> base_link`` that it never jumps (a controller steers on it) and of
``map -> odom`` that it takes the corrections of global aiding (GNSS) that ``map -> base_link``
has. The filter has one solution; its velocity is continuous where its position is not (a GNSS
update moves the position, barely the velocity), so the odom pose is the solution's velocity
integrated (trapezoid rule between output epochs) with the solution's attitude, started at the
first map position; ``map -> odom`` is then the translation between the two positions, with no
rotation (both carry the same attitude).
"""
from __future__ import annotations

import numpy as np


class OdomTrack:
    """base_link's position in ``odom`` (m, axes parallel to ``map``'s ENU)."""

    def __init__(self):
        self._t = None
        self._v = None
        self.position = None

    def advance(self, t: float, map_position: np.ndarray, v_enu: np.ndarray) -> np.ndarray:
        """The odom position at time t (s) of a solution at ``map_position`` (m) moving at
        ``v_enu`` (m/s); the first call starts odom at the map position."""
        v = np.asarray(v_enu, float)
        if self.position is None:
            self.position = np.asarray(map_position, float).copy()
        elif t > self._t:
            self.position = self.position + 0.5 * (self._v + v) * (t - self._t)
        self._t, self._v = t, v
        return self.position
