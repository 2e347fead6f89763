"""IMU calibration model: hand-computed cases, round trip within noise, dict/YAML validation."""
import numpy as np
import pytest
import yaml

from ins_gnss_ros.imu.calibration import ImuCalibration, TriadCalibration
from ins_gnss_ros.nav.increments import SensorErrors

DEG = np.pi / 180


def _example(rng):
    """A MEMS-grade error set: ~0.5 deg/s bias with 0.01 deg/s/degC drift (seed 004 §2.3),
    0.3 % scale with a quadratic temperature term, 3 mrad non-orthogonality, g-sensitivity."""
    return ImuCalibration(
        gyro=TriadCalibration(bias=[[0.5 * DEG, -0.3 * DEG, 0.2 * DEG], [0.01 * DEG, -0.01 * DEG, 0.005 * DEG]],
                              scale=[[3e-3, -2e-3, 1e-3], [0, 1e-5, 0], [1e-7, 0, 0]],
                              nonorthogonality=[[0, 3e-3, -1e-3], [-2e-3, 0, 2e-3], [1e-3, 1.5e-3, 0]]),
        accel=TriadCalibration(bias=[[0.05, -0.08, 0.1], [3e-4, -3e-4, 1e-4]],
                               scale=[2e-3, -1e-3, 4e-3],
                               nonorthogonality=[[0, 1e-3, 0], [2e-3, 0, -1e-3], [0, 1e-3, 0]]),
        gyro_g_sensitivity=rng.normal(0, 1e-4, (3, 3)),
        mounting_rpy=[180 * DEG, -6.79 * DEG, 5.35 * DEG],  # car_drive_0708-like mounting
        temperature_ref=25.0)


#: Running sensor-error estimates of a navigation filter, removed after the calibration.
_FILTER_ESTIMATES = SensorErrors(gyro_bias=np.array([1e-4, -2e-4, 3e-4]),
                                 accel_bias=np.array([0.01, 0, -0.02]),
                                 gyro_scale=np.array([1e-3, 0, -1e-3]),
                                 accel_scale=np.array([0, 2e-3, 0]))


def test_single_axis_by_hand():
    # Only an x-gyro bias with a temperature slope of 0.01 deg/s/degC and a 1 % scale error:
    # raw = w / 1.01 + b(T), at T = T_ref + 10 degC b = 0.2 + 0.1 deg/s.
    cal = ImuCalibration(gyro=TriadCalibration(bias=[[0.2 * DEG, 0, 0], [0.01 * DEG, 0, 0]],
                                               scale=[0.01, 0, 0]), temperature_ref=20.0)
    raw = np.array([10 / 1.01 * DEG + 0.3 * DEG, 0, 0])
    w, f = cal.correct(raw, [0, 0, 9.8], temperature=30.0)
    np.testing.assert_allclose(w, [10 * DEG, 0, 0], atol=1e-12)
    np.testing.assert_allclose(f, [0, 0, 9.8], atol=1e-12)


def test_mounting_and_g_sensitivity_by_hand():
    # Sensor yawed +90 deg in base_link: the sensor x axis is base_link y (left).
    cal = ImuCalibration(mounting_rpy=[0, 0, 90 * DEG])
    w, f = cal.correct([1.0, 0, 0], [0, -9.8, 0])
    np.testing.assert_allclose(w, [0, 1.0, 0], atol=1e-12)
    np.testing.assert_allclose(f, [9.8, 0, 0], atol=1e-12)
    # A z-gyro sensitivity of 1e-4 rad/s per m/s² reads 9.8e-4 rad/s when level and at rest.
    cal = ImuCalibration(gyro_g_sensitivity=np.diag([0, 0, 1e-4]))
    g_raw, a_raw = cal.simulate_raw([0, 0, 0], [0, 0, 9.8])
    np.testing.assert_allclose(g_raw, [0, 0, 9.8e-4], atol=1e-15)
    np.testing.assert_allclose(a_raw, [0, 0, 9.8], atol=1e-15)


def test_round_trip_within_noise():
    rng = np.random.default_rng(1)
    cal = _example(rng)
    n = 2000
    w_true = rng.normal(0, 60 * DEG, (n, 3))
    f_true = rng.normal(0, 8.0, (n, 3))
    temp = rng.uniform(-20, 60, n)
    g_raw, a_raw = cal.simulate_raw(w_true, f_true, temp, _FILTER_ESTIMATES)
    sg, sa = 0.01 * DEG, 0.005  # white noise per sample, rad/s and m/s²
    g_raw = g_raw + rng.normal(0, sg, g_raw.shape)
    a_raw = a_raw + rng.normal(0, sa, a_raw.shape)
    w, f = cal.correct(g_raw, a_raw, temp, _FILTER_ESTIMATES)
    # The errors sit far above the noise before correction...
    assert np.sqrt(np.mean((g_raw - w_true) ** 2)) > 50 * sg
    # ...and the corrected values match the truth within the noise (scale/coupling grow it <2 %).
    assert np.sqrt(np.mean((w - w_true) ** 2)) == pytest.approx(sg, rel=0.1)
    assert np.sqrt(np.mean((f - f_true) ** 2)) == pytest.approx(sa, rel=0.1)


def test_correct_sample_is_correct_in_python_floats():
    """The per-sample path gives correct()'s values up to the rounding of the 3x3 sums (numpy's
    kernels may fuse multiply-adds), keeps M(T) and b(T) only while the temperature is unchanged,
    and removes the filter's sensor-error estimates."""
    rng = np.random.default_rng(3)
    cal = _example(rng)
    gyro, accel = rng.normal(0, 1.0, (8, 3)), rng.normal(0, 10.0, (8, 3))
    temperatures = [None, 40.0, 40.0, -5.0, None, None, 40.0, 25.0]
    for k, temp in enumerate(temperatures):
        res = _FILTER_ESTIMATES if k % 2 else None
        w, f = cal.correct_sample(tuple(gyro[k].tolist()), accel[k].tolist(), temp, res)
        assert all(type(x) is float for x in w + f)
        w_ref, f_ref = cal.correct(gyro[k], accel[k], temp, res)
        np.testing.assert_allclose(w, w_ref, rtol=0, atol=1e-15)   # ~4 ulp of the 1 rad/s inputs
        np.testing.assert_allclose(f, f_ref, rtol=0, atol=1e-14)   # ~4 ulp of the 10 m/s² inputs
    # With the ideal sensor nothing is rounded: the readings come back bit for bit.
    w, f = ImuCalibration().correct_sample((0.1, -0.2, 0.3), (1.0, 2.0, 9.8))
    assert (w, f) == ((0.1, -0.2, 0.3), (1.0, 2.0, 9.8))


def test_dict_yaml_round_trip():
    cal = _example(np.random.default_rng(2))
    text = yaml.safe_dump(cal.to_dict())
    back = ImuCalibration.from_dict(yaml.safe_load(text))
    x = np.array([[0.1, -0.2, 0.3]])
    for a, b in zip(cal.correct(x, 10 * x, 40.0), back.correct(x, 10 * x, 40.0)):
        np.testing.assert_array_equal(a, b)
    # Missing entries mean the ideal sensor.
    w, f = ImuCalibration.from_dict({}).correct([1, 2, 3], [4, 5, 6])
    np.testing.assert_array_equal(w, [1, 2, 3])


@pytest.mark.parametrize("patch, field", [
    ({"gyro": {"bias": [1, 2]}}, "gyro.bias"),
    ({"accel": {"scale": [[0, 0, float("nan")]]}}, "accel.scale"),
    ({"accel": {"nonorthogonality": np.eye(3).tolist()}}, "accel.nonorthogonality"),
    ({"gyro": {"nonorthogonality": [[0, 1], [1, 0]]}}, "gyro.nonorthogonality"),
    ({"gyro_g_sensitivity": [[0] * 3] * 2}, "gyro_g_sensitivity"),
    ({"mounting_rpy": [0, 0, float("inf")]}, "mounting_rpy"),
    ({"temperature_ref": "warm"}, "temperature_ref"),
    ({"gyro": {"offset": [0, 0, 0]}}, "gyro: unknown"),
    ({"magnetometer": {}}, "unknown calibration fields"),
])
def test_validation_names_the_field(patch, field):
    with pytest.raises(ValueError, match=field):
        ImuCalibration.from_dict(patch)
