"""nav/aiding.py and nav/filter_config.py: one aiding policy and one configuration for every path."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest

from ins_gnss_ros.nav.aiding import Aiding, AidingPolicy, WheelPolicy
from ins_gnss_ros.nav.filter_config import PARAMS, navigator_config
from ins_gnss_ros.nav import GnssFix, GnssVelocity, HeadingFix, PhaseDifferences, WheelOdometry, \
    ZeroVelocity
from ins_gnss_ros.params import ParameterError, resolve


class Recorder:
    """A navigator that keeps what it is given (levelled and aligned)."""

    config = SimpleNamespace(noise=SimpleNamespace(accel_psd=1e-6, gyro_psd=1e-8))
    started = True

    def __init__(self):
        self.measurements, self.heading_known = [], True

    def add_measurement(self, m):
        self.measurements.append(m)


def aiding(**policy):
    events = []
    nav = Recorder()
    return Aiding(nav, AidingPolicy(**policy), lambda text, log=True: events.append(text)), nav, events


def test_fixes_are_refused_floored_or_given_a_variance():
    front, nav, events = aiding(position_sigma_floor=0.1)
    cov = np.diag([1e-4, 4.0, 1.0])
    assert not front.fix(1.0, 59.9, 30.3, 10.0, cov, status=-1, covariance_known=True)
    assert not front.fix(1.0, np.nan, 30.3, 10.0, cov, 0, True)
    assert not front.fix(1.0, 59.9, 30.3, 2e5, cov, 0, True)
    assert front.fix(1.0, 59.9, 30.3, 10.0, cov, 0, True)
    fix = nav.measurements[-1]
    assert isinstance(fix, GnssFix) and np.allclose(np.diag(fix.cov_enu), [0.01, 4.0, 1.0])
    assert front.datum == pytest.approx((np.radians(59.9), np.radians(30.3), 10.0))
    # no covariance: a variance that fits the fix's status (single point, SBAS, GBAS)
    for status, sigma in ((0, 5.0), (1, 2.0), (2, 1.0)):
        assert front.fix(2.0, 59.9, 30.3, 10.0, np.eye(3), status, covariance_known=False)
        assert np.allclose(np.diag(nav.measurements[-1].cov_enu), [sigma ** 2, sigma ** 2, 4 * sigma ** 2])
    assert front.fix(2.0, 59.9, 30.3, 10.0, np.zeros((3, 3)), 0, covariance_known=True)  # zero
    assert np.allclose(np.diag(nav.measurements[-1].cov_enu), [25.0, 25.0, 100.0])
    assert events == ["gnss/fix without a fix ignored", "non-finite gnss/fix rejected",
                      "implausible gnss/fix altitude rejected",
                      "gnss/fix without covariance: 5 m assumed from its status",
                      "gnss/fix without covariance: 2 m assumed from its status",
                      "gnss/fix without covariance: 1 m assumed from its status",
                      "gnss/fix without covariance: 5 m assumed from its status"]


def test_velocity_delay_heading_declination_and_range_choice():
    front, nav, events = aiding(velocity_delay=0.1, coupling="auto", min_satellites=5)
    assert front.velocity(2.0, np.array([1.0, 0.0, 0.0]), np.zeros((3, 3)))
    vel = nav.measurements[-1]
    assert isinstance(vel, GnssVelocity) and vel.t == pytest.approx(1.9)
    assert not front.velocity(2.0, np.array([2000.0, 0.0, 0.0]), np.eye(3))
    assert front.heading(3.0, 0.5, 1e-4, declination=0.1, source="mag/heading")
    heading = nav.measurements[-1]
    assert isinstance(heading, HeadingFix) and heading.azimuth == pytest.approx(0.6)
    assert heading.bias == "mag"
    assert not front.heading(3.0, 0.5, 0.0, None)
    assert front.choose_ranges(4) and not front.fix(4.0, 59.9, 30.3, 0.0, np.eye(3), 0, True)
    assert not front.choose_ranges(8)


def test_wheel_odometry_variances_delay_and_zero_speed():
    wheel = WheelPolicy(sigma=(0.1, 0.2, 0.0), zero_speed=0.01, zero_time=0.5, zero_sigma=0.02,
                        delay=0.05)
    front, nav, events = aiding(wheel=wheel)
    # the message's variances where it has them, the policy's elsewhere; sigma 0: axis left out
    assert front.wheel_odometry(1.0, np.array([5.0, np.nan, 0.0]), np.array([0.09, -1.0, 0.0]))
    m = nav.measurements[-1]
    assert isinstance(m, WheelOdometry) and m.t == pytest.approx(0.95)
    assert np.array_equal(m.velocity_b, [5.0, 0.0, 0.0])
    assert np.allclose(m.variance, [0.09, 0.04, np.inf])
    assert not front.wheel_odometry(1.1, np.array([np.nan, 0.0, 0.0]), np.zeros(3))
    # zero counts: a speed until they have lasted zero_time, then zero-velocity updates
    for t in (2.0, 2.25, 2.5, 2.75):
        assert front.wheel_odometry(t, np.zeros(3), np.zeros(3))
    kinds = [type(m) for m in nav.measurements[-4:]]
    assert kinds == [WheelOdometry, WheelOdometry, ZeroVelocity, ZeroVelocity]
    assert nav.measurements[-1].t == pytest.approx(2.7) and nav.measurements[-1].sigma_v == 0.02
    assert front.wheel_odometry(3.0, np.array([0.4, 0.0, 0.0]), np.zeros(3))  # moving again
    assert front.wheel_odometry(3.1, np.zeros(3), np.zeros(3))
    assert isinstance(nav.measurements[-1], WheelOdometry)
    assert events == ["wheel/odom without a finite forward speed rejected"]
    assert front.inputs["wheel/odom"].received == 8 and front.inputs["wheel/odom"].refused == 1


def test_a_profile_section_configures_the_filter_the_node_would():
    p = resolve(PARAMS, {"layout": "21", "lever_arm": [0.5, 0.0, 1.0],
                         "nonholonomic_sigma_mps": [0.1, 0.05]})
    config = navigator_config(p, record=True)
    assert config.layout == "21" and config.nhc_sigma == (0.1, 0.05) and config.record
    assert np.array_equal(config.lever_arm_b, [0.5, 0.0, 1.0])
    with pytest.raises(ParameterError, match="unknown parameter"):
        resolve(PARAMS, {"lever_arms": [0.0, 0.0, 0.0]})
    with pytest.raises(ParameterError, match="gate_probability"):
        resolve(PARAMS, {"gate_probability": 2.0})


def test_successive_fixes_give_a_course_velocity_until_the_heading_is_known():
    from ins_gnss_ros.nav.earth import radii

    front, nav, _ = aiding()
    nav.heading_known = False
    lat0, lon0 = np.radians(59.9), np.radians(30.3)
    _, rn = radii(lat0)
    cov = np.diag([0.25, 0.25, 1.0])  # 0.5 m fixes
    for k in range(11):  # 10 m/s east, fixes at 5 Hz
        lon = lon0 + 10.0 * 0.2 * k / (rn * np.cos(lat0))
        front.fix(0.2 * k, 59.9, np.degrees(lon), 10.0, cov, 0, True)
    courses = [m for m in nav.measurements if isinstance(m, GnssVelocity)]
    assert courses, "no course velocity from 20 m of travel with 0.5 m fixes"
    assert np.allclose(courses[0].v_enu, [10.0, 0.0, 0.0], atol=1e-3)
    nav.heading_known = True
    front.fix(2.4, 59.9, np.degrees(lon0 + 24.0 / (rn * np.cos(lat0))), 10.0, cov, 0, True)
    assert len([m for m in nav.measurements if isinstance(m, GnssVelocity)]) == len(courses)
    # a receiver that gives velocities: no course velocity at all
    front, nav, _ = aiding()
    nav.heading_known = False
    front.velocity(0.0, np.array([10.0, 0.0, 0.0]), np.eye(3) * 0.01)
    for k in range(11):
        lon = lon0 + 10.0 * 0.2 * k / (rn * np.cos(lat0))
        front.fix(0.2 * k, 59.9, np.degrees(lon), 10.0, cov, 0, True)
    assert len([m for m in nav.measurements if isinstance(m, GnssVelocity)]) == 1


def test_phase_differences_are_checked_and_then_replace_the_phase_heading():
    front, nav, events = aiding(phase_differences=True)
    b, g = np.array([[-2.7, 0.0, 0.0], [0.0, -1.2, 0.0]]), np.array([[0.3, -0.8, 0.4],
                                                                      [-0.5, 0.2, 0.6]])
    value, cov = np.array([0.5, -0.2]), 1e-6 * np.array([[2.0, 1.0], [1.0, 2.0]])
    assert front.phase_differences(1.0, b, g, value, cov)
    assert isinstance(nav.measurements[-1], PhaseDifferences)
    assert not front.phase_differences(1.2, b, g, value, -cov)           # not positive definite
    assert not front.phase_differences(1.4, b, g, np.array([np.nan, 0.0]), cov)
    assert not front.phase_differences(1.6, b[:0], g[:0], value[:0], cov[:0, :0])
    assert len(nav.measurements) == 1
    # The heading solved from the same phase would count it twice: it only aligns.
    assert not front.heading(1.0, 0.3, 1e-4, None, source="gnss/heading")
    nav.heading_known = False
    assert front.heading(1.2, 0.3, 1e-4, None, source="gnss/heading")
    nav.heading_known = True
    assert front.heading(1.4, 0.3, 1e-4, None, source="mag/heading")   # other sources stay
    assert [type(m) for m in nav.measurements] == [PhaseDifferences, HeadingFix, HeadingFix]
