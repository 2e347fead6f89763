"""imu/orientation_heading.py: base_link's heading from an AHRS orientation, where valid."""

from __future__ import annotations

import math

import numpy as np
import pytest

from ins_gnss_ros.imu.orientation_heading import MAX_YAW_VARIANCE, OrientationHeadings, \
    orientation_heading
from ins_gnss_ros.nav.rotations import dcm_from_euler, quat_from_euler

VALID = [1e-4, 0, 0, 0, 1e-4, 0, 0, 0, math.radians(2.0) ** 2]


def test_azimuth_of_the_body_x_axis_through_the_mounting():
    # The sensor's x points north-east (ENU yaw 45 deg = azimuth 45 deg) ...
    q_ns = quat_from_euler(0.0, 0.0, math.radians(45.0))
    assert orientation_heading(q_ns, VALID, np.eye(3))[0] == pytest.approx(math.radians(45.0))
    # ... and is mounted turned 90 deg left of the body's x (c_bs = Rz(90)): the body x points
    # 90 deg clockwise of the sensor's x, south-east.
    azimuth, variance = orientation_heading(q_ns, VALID, dcm_from_euler(0.0, 0.0, math.pi / 2))
    assert azimuth == pytest.approx(math.radians(135.0))
    assert variance == VALID[8]
    # a tilted sensor: the azimuth of the projected x axis
    q_tilted = quat_from_euler(math.radians(10.0), math.radians(-5.0), math.radians(-30.0))
    assert orientation_heading(q_tilted, VALID, np.eye(3))[0] == pytest.approx(math.radians(120.0))


@pytest.mark.parametrize("covariance", [
    [-1.0] + [0.0] * 8,                                 # REP-145: no orientation
    [0.0] * 9,                                          # covariance unknown
    VALID[:8] + [MAX_YAW_VARIANCE * 1.01],              # a relative (6-axis) yaw
    VALID[:8] + [math.nan]])
def test_an_orientation_whose_covariance_does_not_vouch_for_the_yaw_is_not_a_heading(covariance):
    assert orientation_heading(quat_from_euler(0, 0, 1.0), covariance, np.eye(3)) is None


def test_headings_come_at_the_rate_asked():
    source = OrientationHeadings(5.0, np.eye(3))
    q = quat_from_euler(0.0, 0.0, 0.3)
    out = [source.add(k * 5_000_000, q, VALID) for k in range(400)]  # 2 s at 200 Hz
    assert sum(h is not None for h in out) == 10
