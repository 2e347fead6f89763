"""The vessel reader: the converted truth must be self-consistent in ENU/FLU.

Finite differences of position must give the velocity, integrating the body rate from the
attitude must reproduce the later attitude, and the attitude must rotate the kinematic
acceleration minus gravity into the recorded specific force: together these prove the NED->ENU,
FRD->FLU and Euler->quaternion conversions (a wrong sign or axis fails at least one of them).
"""
import numpy as np
import pymap3d
import pytest
from conftest import shared_path
from scipy.spatial.transform import Rotation

from ins_gnss_ros.trial.vessel import DEFAULT_DATUM, load_vessel

G0 = 9.80665  # the simulation's gravity, m/s^2


@pytest.fixture(scope="module")
def vessel():
    return load_vessel(shared_path("data", "vessel_waves", "ains_ahrs_imu.parquet"))


def _enu(trajectory, datum=DEFAULT_DATUM):
    """Local ENU of a trajectory about the datum, by pymap3d (independent of the project)."""
    return np.column_stack(pymap3d.geodetic2enu(trajectory.lat, trajectory.lon,
                                                trajectory.height, *datum, deg=False))


def _rotation(q_nb):
    return Rotation.from_quat(q_nb[:, [1, 2, 3, 0]])


def test_shape_and_rate(vessel):
    assert len(vessel.time) == 3686
    assert 1.0 / np.mean(np.diff(vessel.time)) == pytest.approx(10.24)
    assert vessel.accel_flu.shape == vessel.gyro_flu_true.shape == (3686, 3)


def test_position_differences_give_velocity(vessel):
    pos = _enu(vessel.truth)
    fd = np.gradient(pos, vessel.time, axis=0)
    assert np.abs(fd - vessel.truth.vel_enu).max() < 0.01   # m/s; |v| reaches 0.86 m/s
    # Heave: up is minus the source's Z (down).
    assert np.abs(vessel.truth.vel_enu[:, 2]).max() > 0.5


def test_integrated_rate_reproduces_attitude(vessel):
    q = _rotation(vessel.truth.q_nb)
    w = vessel.gyro_flu_true
    dt = np.diff(vessel.time)
    worst = 0.0
    for start in range(0, len(dt) - 40, 150):
        attitude = q[start]
        for i in range(start, start + 31):   # 3 s
            # Body-frame rate: right-multiply (q_nb' = q_nb (x) exp(w dt)), trapezoidal rate.
            attitude = attitude * Rotation.from_rotvec(0.5 * (w[i] + w[i + 1]) * dt[i])
        worst = max(worst, (attitude.inv() * q[start + 31]).magnitude())
    assert np.degrees(worst) < 0.005


def test_specific_force_matches_kinematics(vessel):
    acc = np.gradient(vessel.truth.vel_enu, vessel.time, axis=0)
    gravity = np.array([0.0, 0.0, -G0])
    f_body = _rotation(vessel.truth.q_nb).inv().apply(acc - gravity)
    assert np.abs(f_body - vessel.accel_flu_true)[2:-2].max() < 0.01
    # At rest on average: up along body +z.
    assert vessel.accel_flu_true[:, 2].mean() == pytest.approx(G0, abs=0.01)


def test_attitude_ranges(vessel):
    yaw, pitch, roll = _rotation(vessel.truth.q_nb).as_euler("ZYX").T
    azimuth = np.degrees(np.pi / 2 - yaw) % 360.0
    assert azimuth.mean() == pytest.approx(120.0, abs=1.0)    # station keeping near 120 deg
    assert 2.0 < np.degrees(np.abs(roll)).max() < 4.0          # roll about +-3 deg


def test_compass_noise(vessel):
    yaw = _rotation(vessel.truth.q_nb).as_euler("ZYX")[:, 0]
    error = (vessel.compass_azimuth - (np.pi / 2 - yaw) + np.pi) % (2 * np.pi) - np.pi
    assert np.degrees(np.std(error)) == pytest.approx(0.1, abs=0.01)
    assert abs(np.degrees(np.mean(error))) < 0.01


def test_gnss_noise_and_datum(vessel):
    error = _enu(vessel.gnss) - _enu(vessel.truth)
    assert np.std(error, axis=0) == pytest.approx([0.05, 0.05, 0.05], abs=0.005)
    assert np.linalg.norm(_enu(vessel.truth), axis=1).max() < 3.0  # near the datum
    moved = load_vessel(shared_path("data", "vessel_waves", "ains_ahrs_imu.parquet"),
                        datum=(np.radians(-33.0), np.radians(151.0), 20.0))
    assert np.allclose(_enu(moved.truth, moved.datum), _enu(vessel.truth), atol=1e-6)


def test_measured_imu_close_to_truth(vessel):
    assert np.std(vessel.gyro_flu - vessel.gyro_flu_true, axis=0).max() < np.radians(0.05)
    assert np.std(vessel.accel_flu - vessel.accel_flu_true, axis=0).max() < 0.01
