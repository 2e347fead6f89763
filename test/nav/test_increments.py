"""nav/increments.py: increment plausibility, sensor-error removal, gap classification/bridging."""

from __future__ import annotations

import math

import numpy as np

from ins_gnss_ros.nav.increments import (BRIDGED, CONTIGUOUS, LOST, SensorErrors, classify_gap,
                                         held_increments, increment_problem)


def test_increment_problem_checks_every_component():
    angle, velocity, dt = (1e-3, -2e-3, 3e-3), (0.01, 0.0, 0.098), 0.01
    assert increment_problem(angle, velocity, dt) is None
    non_finite = "non-finite or non-positive increment dropped"
    for bad in (math.nan, math.inf, -math.inf):
        for k in range(3):
            vector = [0.0, 0.0, 0.0]
            vector[k] = bad
            assert increment_problem(vector, velocity, dt) == non_finite
            assert increment_problem(angle, vector, dt) == non_finite
        assert increment_problem(angle, velocity, bad) == non_finite
    assert increment_problem(angle, velocity, 0.0) == non_finite
    # 100 rad/s and 1e4 m/s^2 over 0.01 s are the bounds
    assert increment_problem((1.01, 0.0, 0.0), velocity, dt) == "implausible increment dropped"
    assert increment_problem(angle, (0.0, 0.0, 101.0), dt) == "implausible increment dropped"


def test_sensor_errors_invert_the_measurement_model():
    errors = SensorErrors(np.array([1e-3, -2e-3, 5e-4]), np.array([0.05, 0.0, -0.1]),
                          np.array([1e-3, 0.0, -2e-3]), np.array([0.0, 5e-3, 0.0]))
    omega, f, dt = np.array([0.1, -0.2, 0.3]), np.array([0.5, 0.1, 9.8]), 0.005
    measured_dtheta = ((1.0 + errors.gyro_scale) * omega + errors.gyro_bias) * dt
    measured_dv = ((1.0 + errors.accel_scale) * f + errors.accel_bias) * dt
    dtheta, dv = errors.compensate(measured_dtheta, measured_dv, dt)
    assert np.allclose(dtheta, omega * dt, atol=1e-15) and np.allclose(dv, f * dt, atol=1e-15)
    rows_dtheta, rows_dv = errors.compensate(np.tile(measured_dtheta, (4, 1)),
                                             np.tile(measured_dv, (4, 1)), np.full(4, dt))
    assert np.allclose(rows_dtheta, omega * dt) and np.allclose(rows_dv, f * dt)
    rate, force = errors.compensate_rates(tuple((1.0 + errors.gyro_scale) * omega + errors.gyro_bias),
                                          tuple((1.0 + errors.accel_scale) * f + errors.accel_bias))
    assert np.allclose(rate, omega) and np.allclose(force, f)
    total = errors + errors
    assert np.array_equal(total.gyro_bias, 2 * errors.gyro_bias)


def test_gaps_are_contiguous_bridged_or_lost():
    assert classify_gap(0.01, 0.01, 2.5) == CONTIGUOUS
    assert classify_gap(0.0149, 0.01, 2.5) == CONTIGUOUS  # within half a step: jitter
    assert classify_gap(0.02, 0.01, 2.5) == BRIDGED
    assert classify_gap(2.51, 0.01, 2.5) == BRIDGED
    assert classify_gap(2.52, 0.01, 2.5) == LOST
    assert classify_gap(-math.inf, 0.01, 2.5) == CONTIGUOUS  # the first increment


def test_held_increments_hold_the_rates_over_the_gap_in_steps_of_dt():
    dtheta, dv = np.array([1e-3, 0.0, 0.0]), np.array([0.0, 0.0, 0.098])
    stamps, angles, velocities = held_increments(10.0, dtheta, dv, 0.01, 0.5)
    assert len(stamps) == 50 and stamps[-1] == 10.0
    assert np.allclose(np.diff(stamps), 0.01)
    assert np.allclose(angles.sum(axis=0), dtheta * 50) and np.allclose(velocities.sum(axis=0), dv * 50)
