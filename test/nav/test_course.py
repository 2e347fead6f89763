"""nav/course.py: the course over ground of a receiver without velocity output."""

from __future__ import annotations

import math

import numpy as np
import pytest

from ins_gnss_ros.nav.course import MAX_COURSE_SIGMA, CourseFromFixes
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


def turning_run(tau, speed_end=1.0, rate=1.0 / 3.0, accel=0.05):
    """Positions (N, 3; ENU at the last, m) and yaws (rad) at times tau (s, the last 0) of a
    vehicle turning at `rate` rad/s whose speed changes at `accel` m/s^2, speed_end at the end:
    integrated finely (the velocity turns with the body)."""
    from scipy.integrate import cumulative_trapezoid

    fine = np.linspace(tau[0], 0.0, 200001)
    speed, yaw = speed_end + accel * fine, rate * fine
    east = cumulative_trapezoid(speed * np.cos(yaw), fine, initial=0.0)
    north = cumulative_trapezoid(speed * np.sin(yaw), fine, initial=0.0)
    k = np.searchsorted(fine, tau - 1e-9)
    d = np.stack([east[k] - east[-1], north[k] - north[-1], np.zeros(len(tau))], axis=1)
    return d, rate * tau


def test_run_velocity_follows_a_turn_the_gyros_carry_and_a_changing_speed():
    # 20 s of fixes at 2.5 Hz around a 3 m circle, the speed rising at 0.05 m/s^2 to 1 m/s:
    # the velocity at the last fix is east at 1 m/s, the residuals those of the trapezoid
    from ins_gnss_ros.nav.course import run_velocity

    tau = np.arange(-20.0, 1e-9, 0.4)
    d, yaw = turning_run(tau)
    n = len(tau)
    # (the INS's yaw with any offset: only its turns enter)
    v, cov, gains, chi2, dof, *_ = run_velocity(tau, d, yaw + 1.3, np.ones(n),
                                                np.full(n, 4.0), 0.0)
    np.testing.assert_allclose(v, [1.0, 0.0, 0.0], atol=2e-3)
    assert chi2 < 1e-3 and dof == 3 * n - 8
    # the gains are the fit's: a fix moved moves the velocity by them
    moved = d.copy()
    moved[-1] += [0.1, -0.2, 0.3]
    w, *_ = run_velocity(tau, moved, yaw, np.ones(n), np.full(n, 4.0), 0.0)
    np.testing.assert_allclose(w - v, gains[-1] @ [0.1, -0.2, 0.3], atol=2e-3)


def test_run_velocity_covariance_holds_its_errors():
    """Fixes of 1 m white noise over runs of 14 and 24 s (turning, the speed changing to 1
    m/s: runs whose course is known to MAX_COURSE_SIGMA, as released): the course error within
    its claimed sigma (the velocity's across its own direction over the speed; measured 0.86
    and 0.55 of it squared on average, the slow error's share of the claim growing with the
    run), the speed well within its claimed sigma (steps of the acceleration the fit could not
    see make that much larger than the noise's)."""
    from ins_gnss_ros.nav.course import run_velocity

    rng = np.random.default_rng(5)
    for seconds in (14.0, 24.0):
        tau = np.arange(-seconds, 1e-9, 0.4)
        d, yaw = turning_run(tau, rate=0.05, accel=0.04)
        n = len(tau)
        course, along = [], []
        for _ in range(400):
            noisy = d + rng.standard_normal(d.shape) * [1.0, 1.0, 2.0]
            v, cov, *_ = run_velocity(tau, noisy, yaw, np.ones(n), np.full(n, 4.0), 0.0)
            speed = np.hypot(v[0], v[1])
            u, across = v[:2] / speed, np.array([-v[1], v[0]]) / speed
            course.append(math.atan2(v[1], v[0]) ** 2 / (across @ cov[:2, :2] @ across)
                          * speed ** 2)
            along.append((speed - 1.0) ** 2 / (u @ cov[:2, :2] @ u))
        assert 0.5 < np.mean(course) < 1.3, seconds
        assert np.mean(along) < 1.0, seconds


def test_run_velocity_measures_the_gyros_rate_error():
    """A car started on the move, its turn-on gyro bias never measured at rest: the gyros' yaw
    turns 2 deg/s off the track (the prior says 3 deg/s), 2 m fixes at 5 Hz over 8 s at 10-12
    m/s, turning gently. Taken as an error of 3 deg/s sigma the fit left out, the course of
    such a run was uncertain by 13 deg (its error 7.8 deg RMS), never released; fitted, the
    track's curvature against the gyros' turn measures the error: the course's sigma 2.6 deg,
    within MAX_COURSE_SIGMA, and its error within it (the mean squared ratio over 400 runs;
    measured 0.89)."""
    from ins_gnss_ros.nav.course import MAX_COURSE_SIGMA, run_velocity

    rng = np.random.default_rng(3)
    tau = np.arange(-8.0, 1e-9, 0.2)
    d, yaw = turning_run(tau, speed_end=12.0, rate=0.03, accel=0.25)
    n, bias, prior = len(tau), math.radians(2.0), math.radians(3.0)
    ratios, sigmas, rate_ratios = [], [], []
    for _ in range(400):
        noisy = d + rng.standard_normal(d.shape) * [2.0, 2.0, 4.0]
        v, cov, _, chi2, dof, (rate, rate_var), _ = run_velocity(
            tau, noisy, yaw + bias * tau, np.full(n, 4.0), np.full(n, 16.0), prior)
        across = np.array([-v[1], v[0]]) / np.hypot(v[0], v[1])
        sigma = math.sqrt(across @ cov[:2, :2] @ across) / np.hypot(v[0], v[1])
        ratios.append((math.atan2(v[1], v[0]) / sigma) ** 2)
        sigmas.append(sigma)
        rate_ratios.append((rate - bias) ** 2 / rate_var)
    assert np.median(sigmas) < 0.7 * MAX_COURSE_SIGMA
    assert 0.5 < np.mean(ratios) < 1.3
    # the rate error itself, for the filter's gyro bias (measured: 0.89)
    assert 0.7 < np.mean(rate_ratios) < 1.3


def test_run_velocity_course_holds_what_the_tilt_does_to_the_turns():
    """An INS tilted by epsilon turns its yaw by up to 1 - cos epsilon per radian of the
    vehicle's turn more or less than the heading: with the tilt's sigma the course's variance
    across the track grows by (0.5 (1 - cos 2 sigma) min(turn, 1) speed)^2 over a run that
    turned, and not at all over a straight one. The rate error's variance grows by that turn
    error and the gyros' scale error times the turn, over the run's span, squared."""
    from ins_gnss_ros.nav.course import run_velocity

    tau = np.arange(-20.0, 1e-9, 0.4)
    n, sigma, scale = len(tau), 0.3, 0.015
    for rate, turn in ((0.05, 1.0), (0.0, 0.0)):
        d, yaw = turning_run(tau, rate=rate)
        level, tilted = (run_velocity(tau, d, yaw, np.ones(n), np.full(n, 4.0), 0.01, tilt,
                                      scale * bool(tilt)) for tilt in (0.0, sigma))
        np.testing.assert_allclose(tilted.v, level.v)
        across = np.array([-level.v[1], level.v[0]]) / np.hypot(*level.v[:2])
        grown = across @ (tilted.cov - level.cov)[:2, :2] @ across
        turn_error = 0.5 * (1.0 - math.cos(2.0 * sigma)) * turn
        assert grown == pytest.approx((turn_error * np.hypot(*level.v[:2])) ** 2, rel=1e-6,
                                      abs=1e-12)
        assert tilted.rate[1] - level.rate[1] == pytest.approx(
            ((turn_error + scale * rate * 20.0) / 20.0) ** 2, rel=1e-6, abs=1e-15)


def _first_run_velocity(rng, azimuth, speed, rate_error, rate_sigma, seconds=60.0,
                        min_speed=0.0, yaw0=None):
    """The first velocity CourseFromFixes gives of a robot moving straight along `azimuth`
    (clockwise from north) at speed(t) m/s with 1 m fixes at 2.5 Hz, the INS's yaw turning at
    the gyros' rate error (rad/s) whose prior sigma is `rate_sigma`, from yaw0 (None: drawn);
    None if none within `seconds`."""
    course, cov, distance = CourseFromFixes(), np.diag([1.0, 1.0, 4.0]), 0.0
    if yaw0 is None:
        yaw0 = rng.uniform(-math.pi, math.pi)
    for k in range(round(seconds * 2.5)):
        t = k / 2.5
        distance += speed(t) / 2.5
        e, n = np.array([math.sin(azimuth), math.cos(azimuth)]) * distance \
            + rng.standard_normal(2)
        lat, lon = LAT + n / M_PER_RAD, LON + e / (M_PER_RAD * math.cos(LAT))
        course.observe(t, lat, lon, 10.0)
        v = course.add(t, lat, lon, 10.0, cov, yaw0 + rate_error * t, rate_sigma,
                       min_speed=min_speed)
        if v is not None:
            return v
    return None


@pytest.mark.parametrize("speed, rate_sigma_deg", [(0.5, 0.005), (1.0, 0.005), (0.8, 5.0)])
def test_the_first_run_released_errs_as_it_claims(speed, rate_sigma_deg):
    """The run released first is the first whose course's sigma came under MAX_COURSE_SIGMA:
    a selection, which must not pick the noise that flatters it. Robots at 0.5-1 m/s with 1 m
    fixes, the gyros' rate about the vertical known (measured at rest) or a consumer unit's 5
    deg/s unknown: the course's error at release over its sigma, squared, about 1 on average
    (measured 1.13, 0.87, 0.68; at most 3.1 sigma). Released before its speed was known to
    MIN_SPEED_SIGMAS, the 1 m/s robot's first run came after 6 s at 1.28 m/s, 22 deg off for
    a sigma of 4 (mean squared ratio 2.84, MAX_COURSE_SIGMA then 4 deg); the consumer unit's
    robot took a median 34 s to its first run at that cap (5 of 30 beyond 60 s), 14 s now."""
    rng = np.random.default_rng(9)
    ratios = []
    for _ in range(30):
        azimuth = rng.uniform(-math.pi, math.pi)
        rate_error = math.radians(rng.uniform(-1.0, 1.0) * min(rate_sigma_deg, 5.0))
        v = _first_run_velocity(rng, azimuth, lambda t: speed, rate_error,
                                math.radians(rate_sigma_deg))
        assert v is not None
        s = np.hypot(*v.v_enu[:2])
        across = np.array([-v.v_enu[1], v.v_enu[0]]) / s
        error = math.remainder(math.atan2(v.v_enu[0], v.v_enu[1]) - azimuth, math.tau)
        ratios.append(error ** 2 * s ** 2 / (across @ v.cov_enu[:2, :2] @ across))
    assert np.mean(ratios) < 1.5 and max(ratios) < 4.0 ** 2, (np.mean(ratios), max(ratios))


def test_a_slow_vehicle_gets_its_course_from_a_run():
    """A robot at 1 m/s with 1 m fixes at 2.5 Hz: the two-second chord never clears ten
    sigma, the run does within about fifteen seconds, its course within 3 sigma of the truth;
    without the INS's yaw (not levelled) no run is kept."""
    rng = np.random.default_rng(11)
    cov = np.diag([1.0, 1.0, 4.0])
    azimuth = math.radians(-70.0)
    found = {}
    for levelled in (True, False):
        course, found[levelled] = CourseFromFixes(), None
        for k in range(75):
            t = k / 2.5
            e, n = np.array([math.sin(azimuth), math.cos(azimuth)]) * t + rng.standard_normal(2)
            lat, lon = LAT + n / M_PER_RAD, LON + e / (M_PER_RAD * math.cos(LAT))
            course.observe(t, lat, lon, 10.0)
            v = course.add(t, lat, lon, 10.0, cov, 0.4 if levelled else None, 1e-4)
            if v is not None:
                found[levelled] = v
                break
    assert found[False] is None
    v = found[True]
    assert v is not None and v.t < 16.0
    error = math.atan2(v.v_enu[0], v.v_enu[1]) - azimuth
    across = np.array([-v.v_enu[1], v.v_enu[0]]) / np.hypot(*v.v_enu[:2])
    sigma = math.sqrt(across @ v.cov_enu[:2, :2] @ across) / np.hypot(*v.v_enu[:2])
    assert abs(error) < 3.0 * sigma and sigma < MAX_COURSE_SIGMA
    # it carries the fixes of the chord's window, for the alignment to take
    assert [f.t for f, _ in v.fixes] == pytest.approx([v.t - 0.4 * i for i in range(5, -1, -1)])


def test_a_run_slower_than_the_navigator_aligns_at_is_not_released():
    """A robot creeping at 0.3 m/s, at 1 m/s from 20 s on: its first run's velocity comes at
    0.43-0.48 m/s, below the navigator's align speed (0.5), which would take no course from it
    while the run started again; with that speed as min_speed the run goes on to it."""
    def first_speed(min_speed, seed):
        v = _first_run_velocity(np.random.default_rng(seed), 0.7,
                                lambda t: 0.3 if t < 20.0 else 1.0, 0.0, 1e-4,
                                seconds=40.0, min_speed=min_speed, yaw0=0.2)
        return np.hypot(*v.v_enu[:2])

    for seed in range(4):
        assert first_speed(0.0, seed) < 0.5 <= first_speed(0.5, seed)
