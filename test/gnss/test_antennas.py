"""Antenna positions from parameter lists and the phase-attitude geometry checks."""
import math

import numpy as np
import pytest

from ins_gnss_ros.gnss.antennas import antenna_positions, mounted_antennas


def test_positions_from_a_flat_list():
    assert antenna_positions([1, 2, 3], 1).tolist() == [[1.0, 2.0, 3.0]]
    with pytest.raises(ValueError, match=r"^3, 6, 9 or 12 values \(1-4 antennas\) expected, "
                                         r"got 4$"):
        antenna_positions([0.0] * 4, 1)
    with pytest.raises(ValueError, match=r"^6, 9 or 12 values \(2-4 antennas\) expected"):
        antenna_positions([0.0] * 3, 2)


def test_mounting_rotates_into_base_link_and_geometry_is_checked():
    ant = mounted_antennas([0.0, 0.0, 0.0, 1.0, 0.0, 0.0], [0.0, 0.0, math.radians(30.0)])
    assert np.allclose(ant[1], [math.cos(math.radians(30.0)), math.sin(math.radians(30.0)), 0.0])
    with pytest.raises(ValueError, match="at least 5 cm"):
        mounted_antennas([0.0, 0.0, 0.0, 0.01, 0.0, 0.0, 1.0, 0.0, 0.0], [0.0] * 3)
    with pytest.raises(ValueError, match="mostly fore-aft"):
        mounted_antennas([0.0, 0.0, 0.0, 0.0, 1.0, 0.0], [0.0] * 3)
    assert len(mounted_antennas([0, 0, 0, 0, 1, 0, 1, 0, 0], [0.0] * 3)) == 3  # 3: any layout
