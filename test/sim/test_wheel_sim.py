"""Wheel odometry simulator against the truth it samples."""
from __future__ import annotations

import numpy as np
import pytest

from ins_gnss_ros.sim.scenarios import car
from ins_gnss_ros.sim.wheel_sim import WheelSpec, point_forward_speed, simulate_wheel


@pytest.fixture(scope="module")
def traj():
    return car(duration=120.0, seed=1, rate=100.0, static=10.0).trajectory


def test_distance_is_the_scaled_true_distance_to_one_count(traj):
    spec = WheelSpec(rate=20.0, scale_error=0.01, tick=0.02, latency=0.05)
    w = simulate_wheel(traj, spec)
    true_distance = np.trapezoid(np.linalg.norm(traj.v_enu, axis=1), traj.t)
    measured = np.sum(w.speed) / spec.rate  # the counts telescope: quantisation does not add up
    assert measured == pytest.approx(1.01 * true_distance, abs=0.02 + 1e-4 * true_distance)
    assert np.allclose(w.stamp - w.t, 0.05)
    # each speed is the count over its interval: a multiple of tick * rate
    counts = w.speed / (spec.tick * spec.rate)
    assert np.allclose(counts, np.round(counts), atol=1e-6)
    assert not w.slipping.any()


def test_without_quantisation_a_speed_is_its_interval_mean(traj):
    w = simulate_wheel(traj, WheelSpec(rate=10.0))
    # the interval mean refers to the middle of the interval (a latency of T / 2)
    mid = np.interp(w.t - 0.05, traj.t, np.linalg.norm(traj.v_enu, axis=1))
    assert np.max(np.abs(w.speed - mid)) < 0.02


def test_slip_events_change_the_speed_only_while_slipping(traj):
    spec = WheelSpec(rate=20.0, slip_interval=10.0)
    w = simulate_wheel(traj, spec, seed=4)
    clean = simulate_wheel(traj, WheelSpec(rate=20.0))
    assert w.slipping.sum() > 10
    assert np.array_equal(w.speed[~w.slipping], clean.speed[~w.slipping])
    ratio = np.abs(w.speed[w.slipping] / np.maximum(clean.speed[w.slipping], 1e-3) - 1.0)
    assert np.max(ratio) > 0.1 and np.max(ratio) <= 0.3 + 1e-9


def test_point_speed_has_the_lever_arm_term(traj):
    lever = np.array([0.0, 0.0, -0.5])
    # body x of (omega x l) = omega_y l_z - omega_z l_y
    expected = point_forward_speed(traj, np.zeros(3)) - 0.5 * traj.omega_ib_b[:, 1]
    assert np.allclose(point_forward_speed(traj, lever), expected, atol=1e-4)
