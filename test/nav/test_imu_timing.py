"""nav/imu_timing.py: the IMU's clock offset found from turns, on a drive whose offset is known."""
import math

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from ins_gnss_ros.nav.imu_timing import ImuTimingCheck


def _drive(offset, mounting_deg=(0.0, 0.0, 0.0), duration=240.0, seed=0, gyro_unit=1.0,
           check=None, accel_sign=1.0, fix_noise=0.02, drift=0.0, gyro_bias=0.0, fix_rate=5.0):
    """A car at 8 m/s weaving and turning (yaw rate up to 0.3 rad/s), IMU at 100 Hz in any
    mounting stamped ``offset`` s early (stamps + offset = GNSS time) by a clock running at
    1 + ``drift`` of GNSS time's, fixes at ``fix_rate`` Hz with ``fix_noise`` m of noise; the
    gyro increments in ``gyro_unit`` per rad with ``gyro_bias`` rad/s about the body's z axis,
    the accelerometer's times ``accel_sign``. Returns the check after the drive."""
    rng = np.random.default_rng(seed)
    dt_imu = 0.01
    t = np.arange(0.0, duration, dt_imu)
    rate = 0.2 * np.sin(2 * np.pi * t / 17.0) + 0.1 * np.sin(2 * np.pi * t / 5.3)
    yaw = np.concatenate([[0.0], np.cumsum(0.5 * (rate[1:] + rate[:-1]) * dt_imu)])
    east = np.concatenate([[0.0], np.cumsum(8.0 * np.cos(yaw[:-1] + 0.5 * np.diff(yaw))
                                            * dt_imu)])
    north = np.concatenate([[0.0], np.cumsum(8.0 * np.sin(yaw[:-1] + 0.5 * np.diff(yaw))
                                             * dt_imu)])
    c_sb = Rotation.from_euler("xyz", mounting_deg, degrees=True).as_matrix()  # body -> sensor
    check = check or ImuTimingCheck()
    fix_every = int(round(1.0 / (fix_rate * dt_imu)))
    for k in range(1, len(t)):
        # the sensor's increment: body z rotation and the specific force of gravity
        dtheta = gyro_unit * c_sb @ np.array([0.0, 0.0, yaw[k] - yaw[k - 1]
                                              + gyro_bias * dt_imu])
        dv = accel_sign * c_sb @ np.array([0.0, 0.0, 9.81 * dt_imu]) + rng.normal(0.0, 1e-4, 3)
        check.increment(t[k] * (1.0 + drift) - offset, dtheta, dv)
        if k % fix_every == 0:
            e = east[k] + rng.normal(0.0, fix_noise)
            n = north[k] + rng.normal(0.0, fix_noise)
            check.fix(t[k], e, n)
    return check


@pytest.mark.parametrize("offset, mounting", [(0.0, (0.0, 0.0, 0.0)),
                                              (0.12, (180.0, 0.0, 90.0)),
                                              (-0.2, (0.0, -7.0, 175.0))])
def test_the_offset_of_the_imu_stamps_is_found_whatever_the_mounting(offset, mounting):
    check = _drive(offset, mounting)
    found, sigma = check.estimate()
    assert found == pytest.approx(offset, abs=0.005)
    assert sigma < 0.02  # reported (REPORT_SIGMA); the fixes' noise on 3.2 m chords dominates
    verdict = check.verdict()
    assert ("in step" in verdict.summary) == (offset == 0.0), verdict
    assert verdict.problem == (offset != 0.0) and not verdict.rates_wrong
    assert verdict.stamps_off == (offset != 0.0)


def test_fixes_stamped_late_are_no_problem_where_the_filter_estimates_their_latency():
    late = _drive(0.12, check=ImuTimingCheck(gnss_latency_state=True))
    assert not late.verdict().problem and not late.verdict().stamps_off
    assert "the filter's time-offset state takes it" in late.verdict().summary
    assert "set the ekf's time_offset_sigma_s" in _drive(0.12).verdict().summary
    # the IMU's stamps late (fixes early): the state would leave the solution on the late clock
    early = _drive(-0.12, check=ImuTimingCheck(gnss_latency_state=True))
    assert "add it to imu_preprocessor time_offset_s" in early.verdict().summary
    assert early.verdict().stamps_off


def test_gyro_rates_in_degrees_per_second_are_reported_instead_of_an_offset():
    assert _drive(0.0).scale() == pytest.approx(1.0, abs=0.02)
    check = _drive(0.0, (0.0, -7.0, 175.0), gyro_unit=math.degrees(1.0))
    assert check.scale() == pytest.approx(57.3, rel=0.02)
    verdict = check.verdict()
    assert verdict.summary.startswith("the gyros turn 5")
    assert "angular_velocity in deg/s (57.3 x)" in verdict.summary
    assert verdict.rates_wrong and not verdict.stamps_off


@pytest.mark.parametrize("fix_rate", [5.0, 1.0])
def test_a_gyro_bias_is_neither_a_scale_nor_an_offset(fix_rate):
    """A consumer unit's 5 deg/s about the vertical, which nothing here removes, turns the IMU
    by 0.17 rad over two 1 Hz fix intervals whatever the course does: read as a scale of 1.41
    from 1 Hz fixes, the rates were flagged wrong (and the solution not valid), the offset's
    sigma grew 2.5x (5 Hz) and 7x (1 Hz). Fitted with the scale and the offset as a term in the
    pairs' duration."""
    unbiased = _drive(0.12, fix_rate=fix_rate)
    check = _drive(0.12, fix_rate=fix_rate, gyro_bias=np.radians(5.0))
    assert check.scale() == pytest.approx(unbiased.scale(), abs=1e-6)
    assert check.scale() == pytest.approx(1.0, abs=0.06)  # 1 Hz: the 2 s chords' 1.05
    assert check.estimate() == pytest.approx(unbiased.estimate(), abs=1e-6)
    assert check.estimate()[0] == pytest.approx(0.12, abs=0.005)
    assert not check.verdict().rates_wrong and check.verdict().stamps_off


def test_a_straight_or_slow_drive_says_what_it_needs():
    check = ImuTimingCheck()
    for k in range(1, 2000):  # standing still for 20 s
        check.increment(0.01 * k, np.zeros(3), np.array([0.0, 0.0, 0.0981]))
        if k % 20 == 0:
            check.fix(0.01 * k, 0.0, 0.0)
    assert check.estimate() is None
    assert check.verdict().summary.startswith("needs turns above 3 m/s: 0 course changes")
    assert not check.verdict().problem


def test_an_accelerometer_with_gravity_down_is_reported():
    """Acceleration published instead of specific force: the mean "up" points down, and the
    gyros' turn about it runs against the course."""
    check = _drive(0.0, (0.0, -7.0, 175.0), accel_sign=-1.0)
    # (about -1, taken where the turns correlate best; the car drive: -1.00)
    assert check.scale() == pytest.approx(-1.0, abs=0.1)
    assert "linear_acceleration with gravity down" in check.verdict().summary
    assert check.verdict().rates_wrong


def test_course_turns_of_noise_give_no_verdict_on_the_gyros():
    """Single-point fixes (1 m) 1.6 m apart: the course over two chords is noise, and the
    scale fitted to it would pass for wrong gyro units."""
    check = _drive(0.0, fix_noise=1.0)
    assert check.scale() is None and not check.verdict().problem


def test_an_imu_clock_drifting_against_gnss_time_is_told():
    """200 ppm fast (an IMU stamped by counting samples at the nominal rate, its crystal off):
    the stamps run 160 ms ahead over 800 s, which no constant time_offset_s holds."""
    check = _drive(0.0, duration=800.0, drift=200e-6)
    rate, first, latest = check.drift()
    assert rate == pytest.approx(200e-6, rel=0.1)
    assert first > latest  # the stamps run ahead: ever more to subtract
    summary = check.verdict().summary
    assert f"over the run ({1e6 * rate:+.0f} ppm if the IMU's clock drifts" in summary
    # a constant offset over as long a drive is no drift
    steady = _drive(-0.12, duration=800.0)
    assert steady.drift() is None and "over the run" not in steady.verdict().summary
