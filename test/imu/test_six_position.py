"""Six-face and multi-position static calibration on simulated static data with known errors."""
import numpy as np
import pytest

from ins_gnss_ros.imu.six_position import (FACES, face_attitude, fit_accel_gravity_norm,
                                           fit_accel_known_faces, fit_gyro_bias,
                                           static_earth_rate, static_specific_force)
from ins_gnss_ros.nav.rotations import dcm_from_euler

G = 9.8190          # m/s², about 60 deg N
LAT = np.radians(59.94)
OMEGA = 7.292115e-5
RATE, SECONDS = 100.0, 30.0  # each position is averaged over 30 s at 100 Hz
N_AVG = int(RATE * SECONDS)


def _truth(rng):
    a = np.eye(3) + np.diag([3e-3, -2e-3, 5e-3]) + rng.normal(0, 1e-3, (3, 3)) * (1 - np.eye(3))
    return a, np.array([0.05, -0.12, 0.08])  # raw = A f + b


def _measure(rng, a, b, f, sigma=0.01):
    """Mean of N_AVG raw samples with white noise sigma (m/s²)."""
    return f @ a.T + b + rng.normal(0, sigma / np.sqrt(N_AVG), np.shape(f))


def test_face_attitudes_point_the_axis_up():
    for face in FACES:
        axis = np.zeros(3)
        axis["xyz".index(face[1])] = 1.0 if face[0] == "+" else -1.0
        up_in_body = face_attitude(face, yaw=0.7).T @ [0, 0, 1]
        np.testing.assert_allclose(up_in_body, axis, atol=1e-12)
    # Level, facing north (yaw 90 deg): f = [0, 0, g], Earth rate along forward and up.
    c = face_attitude("+z", np.pi / 2)
    np.testing.assert_allclose(static_specific_force(c, G), [0, 0, G], atol=1e-12)
    np.testing.assert_allclose(static_earth_rate(c, LAT),
                               [OMEGA * np.cos(LAT), 0, OMEGA * np.sin(LAT)], atol=1e-15)


def test_six_faces_recover_accelerometer_errors():
    rng = np.random.default_rng(11)
    a, b = _truth(rng)
    c = np.array([face_attitude(f) for f in FACES])
    f_true = static_specific_force(c, G)
    tri = fit_accel_known_faces(_measure(rng, a, b, f_true), f_true)
    # Noise on each mean is 0.01/sqrt(3000) = 1.8e-4 m/s²: bias and M within a few times that.
    np.testing.assert_allclose(tri.bias[0], b, atol=5e-4)
    m = np.eye(3) + np.diag(tri.scale[0]) + tri.nonorthogonality
    np.testing.assert_allclose(m, np.linalg.inv(a), atol=1e-4)
    # A new attitude is corrected to the truth.
    f_new = static_specific_force(dcm_from_euler(0.5, -0.3, 1.0), G)
    np.testing.assert_allclose(tri.correct(f_new @ a.T + b, 0.0), f_new, atol=1e-3)


def test_gravity_norm_fit_from_unknown_orientations():
    rng = np.random.default_rng(12)
    a, b = _truth(rng)
    # Make A's rotation-free part the truth the norm fit can see: A = U^-1 with U upper triangular.
    u = np.triu(np.linalg.inv(a))
    a = np.linalg.inv(u)
    rpy = rng.uniform(-np.pi, np.pi, (18, 3))
    rpy[:, 1] /= 2
    c = np.array([dcm_from_euler(*r) for r in rpy])
    f_true = static_specific_force(c, G)
    tri = fit_accel_gravity_norm(_measure(rng, a, b, f_true), G)
    np.testing.assert_allclose(tri.bias[0], b, atol=1e-3)
    m = np.eye(3) + np.diag(tri.scale[0]) + tri.nonorthogonality
    np.testing.assert_allclose(m, u, atol=2e-4)
    with pytest.raises(ValueError, match="at least 9"):
        fit_accel_gravity_norm(np.ones((6, 3)), G)


def test_gyro_bias_with_earth_rate():
    rng = np.random.default_rng(13)
    bias = np.array([2e-5, -1e-5, 3e-5])  # tactical-grade gyro, rad/s (about 4 deg/h)
    c = np.array([face_attitude(f, yaw=0.3) for f in FACES])
    raw = static_earth_rate(c, LAT) + bias + rng.normal(0, 1e-4 / np.sqrt(N_AVG), (6, 3))
    np.testing.assert_allclose(fit_gyro_bias(raw, c, LAT), bias, atol=2e-6)
    # Ignoring Earth rate leaves an error of the order of the Earth rate itself.
    assert np.max(abs(fit_gyro_bias(raw) - bias)) > 1e-5


def test_degenerate_positions_rejected():
    c = np.array([face_attitude("+z")] * 6)
    f = static_specific_force(c, G)
    with pytest.raises(ValueError, match="non-coplanar"):
        fit_accel_known_faces(f, f)
