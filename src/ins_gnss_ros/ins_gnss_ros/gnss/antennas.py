"""Antenna geometry: phase-centre positions from a flat list (3 values per antenna, as
parameters give them), and the mounted array the phase-attitude solver needs."""
from __future__ import annotations

import numpy as np

from ..nav.rotations import dcm_from_euler

#: Shortest distance of an antenna from the master for phase attitude [m].
MIN_BASELINE_M = 0.05


def antenna_positions(values, min_antennas: int, max_antennas: int = 4) -> np.ndarray:
    """Positions (shape (n, 3), m) of ``min_antennas``-``max_antennas`` antennas from a flat
    sequence x0, y0, z0, x1, ...

    Raises
    ------
    ValueError
        The length is not a multiple of 3 or gives too few or too many antennas.
    """
    n = len(values)
    if n % 3 or not min_antennas <= n // 3 <= max_antennas:
        counts = [str(3 * k) for k in range(min_antennas, max_antennas + 1)]
        raise ValueError(f"{', '.join(counts[:-1])} or {counts[-1]} values ({min_antennas}-"
                         f"{max_antennas} antennas) expected, got {n}")
    return np.asarray(values, float).reshape(-1, 3)


def mounted_antennas(values, mounting_rpy) -> np.ndarray:
    """Positions in base_link (FLU, m; shape (n, 3), row 0 the master) of 2-4 antennas given in
    the frame of their mount, which ``mounting_rpy`` (ROS roll, pitch, yaw [rad]) rotates into
    base_link.

    Raises
    ------
    ValueError
        Fewer than 2 or more than 4 antennas; an antenna within ``MIN_BASELINE_M`` of the
        master; or, with 2 antennas, a baseline mostly across the body: the core then solves
        heading and pitch with roll = 0 in closed form, which sees the heading of an athwartship
        baseline only through that assumed roll.
    """
    antennas = antenna_positions(values, 2) @ dcm_from_euler(*mounting_rpy).T
    if np.min(np.linalg.norm(antennas[1:] - antennas[0], axis=1)) < MIN_BASELINE_M:
        raise ValueError("every antenna must be at least 5 cm from the master")
    b = antennas[1] - antennas[0]
    if len(antennas) == 2 and abs(b[0]) < abs(b[1]):
        raise ValueError("with 2 antennas the baseline must be mostly fore-aft (|x| >= |y| in "
                         "base_link)")
    return antennas


__all__ = ["MIN_BASELINE_M", "antenna_positions", "mounted_antennas"]
