"""Body headings from a receiver baseline (mounting offsets) and from the phase-attitude core."""
import math

import numpy as np
import pytest

from ins_gnss_ros.gnss.attitude import AttitudeSolution
from ins_gnss_ros.gnss.heading import attitude_heading, receiver_heading


def test_fore_aft_baseline_gives_pitch_athwartship_one_does_not():
    aft = receiver_heading(math.radians(10.0), 0.01, math.pi, math.radians(3.0),
                           math.radians(1.0), 0.02, 1.5)
    # Mounted pointing aft: the body azimuth is the baseline's + 180 deg, pitch its negative.
    assert math.degrees(aft.azimuth) == pytest.approx(190.0)
    assert math.degrees(aft.pitch) == pytest.approx(-2.0)
    assert (aft.var_azimuth, aft.var_pitch) == pytest.approx((1e-4, 4e-4))
    assert (aft.status, aft.baseline_length, aft.satellites) == ("FIXED", 1.5, 0)
    across = receiver_heading(math.radians(10.0), 0.01, math.radians(-90.0), math.radians(3.0))
    assert math.degrees(across.azimuth) == pytest.approx(100.0)
    assert math.isnan(across.pitch) and math.isnan(across.var_pitch) and math.isnan(across.roll)


def test_attitude_heading_uses_fixed_always_float_on_request():
    sol = AttitudeSolution("FLOAT", azimuth=1.0, pitch=0.1, roll=-0.2, var_azimuth=1e-4,
                           var_pitch=2e-4, var_roll=3e-4, ratio=2.0,
                           satellites=("G01", "G01_2L", "E11"),
                           baselines=np.array([[3.0, 4.0, 0.0]]))
    none = attitude_heading(sol, use_float=False)
    assert none.status == "NONE" and math.isnan(none.azimuth)
    assert (none.satellites, none.ratio) == (2, 2.0)
    used = attitude_heading(sol, use_float=True)
    assert (used.status, used.azimuth, used.roll, used.baseline_length) == ("FLOAT", 1.0, -0.2,
                                                                             5.0)
    assert used.pitch == -0.1   # nose-up, the core's ROS pitch is nose-down
    assert attitude_heading(AttitudeSolution("NONE"), True).status == "NONE"
