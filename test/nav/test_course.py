"""nav/course.py: the course over ground of a receiver without velocity output."""

from __future__ import annotations

import math

import numpy as np
import pytest

from ins_gnss_ros.nav.course import CourseFromFixes
from ins_gnss_ros.nav.earth import ecef_to_geodetic, enu_to_ecef

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


def test_repeated_fixes_do_not_pass_for_quiet_ones():
    """Fixes duplicated (the same stamp) or republished (the same position, a later stamp) add
    no noise sample: the white variance stays that of the fixes (0.3 m), not near 0."""
    rng = np.random.default_rng(3)
    cov = np.diag([25.0, 25.0, 100.0])
    for repeat in ("duplicated", "republished"):
        course = CourseFromFixes()
        for k in range(100):
            e, n = 0.3 * rng.standard_normal(2)
            lat, lon = LAT + n / M_PER_RAD, LON + e / (M_PER_RAD * math.cos(LAT))
            for copy in range(3):
                course.observe(0.6 * k + (0.2 * copy if repeat == "republished" else 0.0),
                               lat, lon, 10.0)
        assert math.sqrt(course.fix_to_fix(cov)[0, 0]) == pytest.approx(0.3, rel=0.3), repeat
    # a receiver's full covariance: the white part stays positive definite
    np.linalg.cholesky(course.fix_to_fix(np.array([[25.0, 5.0, 18.0], [5.0, 25.0, 18.0],
                                                   [18.0, 18.0, 100.0]])))


def chord_velocities(position, rate=1.0, seconds=12.0, sigma=0.01):
    """Velocities from noise-free fixes at position(t) (east, north; m) claiming sigma m."""
    course, out = CourseFromFixes(), []
    cov = np.diag([sigma ** 2, sigma ** 2, 4 * sigma ** 2])
    for k in range(round(seconds * rate)):
        t = k / rate
        # exactly in the local ENU frame (the course is measured there)
        lat, lon, h = ecef_to_geodetic(enu_to_ecef([*position(t), 0.0], LAT, LON, 10.0))
        course.observe(t, lat, lon, h)
        v = course.add(t, lat, lon, h, cov)
        if v is not None:
            out.append(v)
    return out


def test_chord_velocity_is_the_mid_epoch_velocity_under_constant_acceleration():
    # p = v0 t + a t^2 / 2 on both axes: the chord velocity is v0 + a t_mid exactly
    v0, a = np.array([3.0, -1.0]), np.array([0.8, 1.5])
    found = chord_velocities(lambda t: v0 * t + 0.5 * a * t * t)
    assert len(found) > 5
    for v in found:
        # (to 1 mm/s: each difference is resolved in the ENU axes of its later fix)
        np.testing.assert_allclose(v.v_enu[:2], v0 + a * v.t, atol=1e-3)


def test_chord_velocity_error_under_constant_jerk_is_within_its_variance():
    # a steady change of acceleration j leaves j dt^2 / 24 (dt the fixes' spacing): the
    # covariance's term for it, ACCELERATION_CHANGE * dt / 24, holds Δa = j dt up to 2 sigma
    from ins_gnss_ros.nav.course import ACCELERATION_CHANGE

    v0, j = np.array([5.0, 0.0]), np.array([0.0, 2.0 * ACCELERATION_CHANGE])  # 4 m/s^3
    found = chord_velocities(lambda t: v0 * t + j * t ** 3 / 6.0, seconds=6.0)
    assert found
    for v in found:
        dt = 1.0  # one fix apart at 1 Hz: the displacement is beyond 10 sigma at once
        err = v.v_enu[:2] - (v0 + 0.5 * j * v.t ** 2)
        np.testing.assert_allclose(err, j * dt ** 2 / 24.0, atol=1e-3)
        white = 2 * 0.01 ** 2 / dt ** 2
        assert abs(err[1]) <= 2.0 * np.sqrt(v.cov_enu[1, 1] - white) + 1e-9


def test_velocity_carries_its_fixes_and_their_correlation_with_it():
    """Every fix of the window comes with the velocity (the held ones between the ends too),
    and the velocity's error (e_1 - e_0) / dt is correlated with the ends' errors by -W_0 / dt
    and W_1 / dt: checked against the sample covariance of drawn fix errors."""
    rng = np.random.default_rng(2)
    cov = np.diag([0.25, 0.25, 1.0])
    v_err, e_first, e_last = [], [], []
    for _ in range(3000):
        course, found = CourseFromFixes(), None
        errors = []
        for t in (0.0, 0.5, 1.0, 1.5):  # 8 m/s north: the velocity comes with the fourth fix
            e = np.array([0.5, 0.5, 1.0]) * rng.standard_normal(3)
            errors.append(e)
            n = 8.0 * t + e[1]
            found = course.add(t, LAT + n / M_PER_RAD, LON + e[0] / (M_PER_RAD * math.cos(LAT)),
                               10.0 + e[2], cov)
        if found is None or len(found.fixes) < 4:
            continue  # the noise made the third fix complete one (a few draws in a thousand)
        v_err.append(found.v_enu - [0.0, 8.0, 0.0])
        e_first.append(errors[0])
        e_last.append(errors[-1])
    assert len(v_err) > 2900 and [f.t for f, _ in found.fixes] == [0.0, 0.5, 1.0, 1.5]
    (_, x0), (_, x1), (_, x2), (_, x3) = found.fixes
    np.testing.assert_allclose(np.hstack([x1, x2]), 0.0)
    for errs, claimed in ((e_first, x0), (e_last, x3)):
        sample = np.cov(np.hstack([v_err, errs]).T)[:3, 3:]
        np.testing.assert_allclose(sample[:2, :2], claimed[:2, :2], atol=0.025)
