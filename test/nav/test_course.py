"""nav/course.py: the course over ground of a receiver without velocity output."""

from __future__ import annotations

import math

import numpy as np
import pytest

from ins_gnss_ros.nav.course import CourseFromFixes

LAT, LON = math.radians(59.9), math.radians(30.3)
M_PER_RAD = 6.37e6


def velocities(noise, assumed, speed=5.0, azimuth=math.radians(30.0), rate=5.0, seconds=20.0):
    """Velocities from fixes of a vehicle at `speed` m/s along `azimuth` (clockwise from north),
    with white noise `noise` m per axis and a covariance that says `assumed` m."""
    rng = np.random.default_rng(7)
    course, out = CourseFromFixes(), []
    cov = np.diag([assumed ** 2, assumed ** 2, 4 * assumed ** 2])
    for k in range(round(seconds * rate)):
        t = k / rate
        east, north = speed * t * math.sin(azimuth), speed * t * math.cos(azimuth)
        e, n = np.array([east, north]) + noise * rng.standard_normal(2)
        lat, lon = LAT + n / M_PER_RAD, LON + e / (M_PER_RAD * math.cos(LAT))
        course.observe(t, lat, lon, 10.0)
        v = course.add(t, lat, lon, 10.0, cov)
        if v is not None:
            out.append(v)
    return out


def test_the_fixes_own_scatter_sets_when_the_motion_is_beyond_it():
    # A fix without covariance is given 5 m; differences over two seconds see only the white
    # part, which the second differences measure: 0.3 m here.
    found = velocities(noise=0.3, assumed=5.0)
    assert found
    for v in found:
        assert math.degrees(abs(math.atan2(v.v_enu[0], v.v_enu[1]) - math.radians(30.0))) < 10.0
        assert np.hypot(*v.v_enu[:2]) == pytest.approx(5.0, abs=1.0)
    # where the white noise really is 5 m, 5 m/s is not beyond it
    assert not velocities(noise=5.0, assumed=5.0)
