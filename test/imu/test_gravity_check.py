"""imu/gravity_check.py: an accelerometer stream in g, or without gravity, or in axes other than
base_link's FLU, is told apart from the specific force in m/s^2 in FLU (on a simulated car's
accelerations), and the preprocessor reports it."""
import numpy as np
import pytest

from ins_gnss_ros.imu.calibration import ImuCalibration
from ins_gnss_ros.imu.gravity_check import G, WINDOW_S, SpecificForceCheck
from ins_gnss_ros.imu.preprocessor import ImuPreprocessor


def car_specific_force(seconds, rate, seed=0):
    """Specific force of a level car (FLU, m/s^2): gravity up plus braking, accelerating and
    cornering of up to ~3 m/s^2, varying over seconds, and vibration."""
    rng = np.random.default_rng(seed)
    n = int(seconds * rate)
    slow = np.cumsum(rng.normal(0.0, 0.15, (n, 2)), axis=0)
    slow = 3.0 * np.tanh(slow / 3.0)  # bounded like a car's
    f = np.column_stack([slow, np.full(n, G)])
    return f + rng.normal(0.0, 0.3, (n, 3))


def judged(f, rate):
    check = SpecificForceCheck()
    dt = 1.0 / rate
    windows = [check.problem() for dv in f * dt if check.add(dv, dt)]
    return windows


@pytest.mark.parametrize("scale, shift, verdict", [
    (1.0, 0.0, None),
    (1.0 / G, 0.0, "in g, or with gravity removed"),
    (1.0, -G, "in g, or with gravity removed"),
    (3.0, 0.0, "check its units and scale")])
def test_units_and_gravity_of_the_stream(scale, shift, verdict):
    f = car_specific_force(35.0, 100.0)
    f[:, 2] += shift
    windows = judged(scale * f, 100.0)
    assert len(windows) == 3  # one per complete WINDOW_S stretch
    for problem in windows:
        assert problem is None if verdict is None else verdict in problem


@pytest.mark.parametrize("sensor_axes, verdict", [
    (np.eye(3), None),
    (np.diag([1.0, -1.0, -1.0]), "along -z (down)"),               # FRD: y right, z down
    (np.array([[0, 0, 1], [0, 1, 0], [-1, 0, 0]]), "along +x (forward)"),  # x along the vertical
    (np.array([[1, 0, 0], [0, 0, -1], [0, 1, 0]]), "along -y (right)")])   # on its side
def test_axes_other_than_flu_are_named(sensor_axes, verdict):
    """The stream in the sensor's axes (rows: the sensor's axes in base_link FLU)."""
    (problem,) = judged(car_specific_force(11.0, 100.0) @ np.asarray(sensor_axes, float).T,
                        100.0)
    assert problem is None if verdict is None else verdict in problem
    if verdict is not None:
        assert "mounting_rpy_deg" in problem
        assert ("FRD" in problem) == ("down" in verdict)


def test_a_banked_turn_or_hard_braking_is_not_taken_for_wrong_units():
    rate = 100.0
    f = np.tile([0.0, 0.0, G], (int(WINDOW_S * rate) + 1, 1))
    assert judged(np.column_stack([f[:, :2], f[:, 2] * 1.41]), rate) == [None]  # 45 deg bank
    assert judged(f + [-7.0, 0.0, 0.0], rate) == [None]  # 0.7 g braking for 10 s


def test_the_preprocessor_judges_every_stretch_of_its_increments():
    rate = 100.0
    pre = ImuPreprocessor(ImuCalibration(), rate, rate, "one_sample", gyro_range=30.0,
                          accel_range=150.0, max_identical_samples=0)
    f = car_specific_force(2 * WINDOW_S + 1.0, rate) / G  # a driver publishing g
    events = [e for k, a in enumerate(f) for out in pre.add(int(k * 1e7), int(k * 1e7),
                                                            (0.0, 0.0, 0.0), tuple(a))
              for e in out.events]
    assert events.count("specific_force_judged") == 2
    assert "in g" in pre.gravity.problem()
