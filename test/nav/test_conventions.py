"""Convention conversions against geometry, scipy and the recorded vessel data (NED/FRD)."""
from pathlib import Path

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from ins_gnss_ros.nav import conventions as cv
from ins_gnss_ros.nav.rotations import (quat_angle_between, quat_conj, quat_from_euler, quat_mul,
                                        quat_rotate, quat_to_rotvec)

SHARED = Path(__file__).resolve().parents[2] / ".." / "shared"
VESSEL = SHARED / "data" / "vessel_waves" / "ains_ahrs_imu.parquet"
RNG = np.random.default_rng(4)


def test_wrap_and_azimuth():
    a = RNG.uniform(-20, 20, 1000)
    w = cv.wrap_pi(a)
    assert np.all((w >= -np.pi) & (w < np.pi))
    np.testing.assert_allclose(np.exp(1j * w), np.exp(1j * a), atol=1e-12)
    w2 = cv.wrap_2pi(a)
    assert np.all((w2 >= 0) & (w2 < 2 * np.pi))
    # Facing East: yaw 0, azimuth 90 deg; facing North: yaw 90 deg, azimuth 0; facing
    # North-West: yaw 135 deg, azimuth 315 deg.
    np.testing.assert_allclose(cv.azimuth_from_yaw([0.0, np.pi / 2, 0.75 * np.pi]),
                               [np.pi / 2, 0.0, 1.75 * np.pi], atol=1e-15)
    np.testing.assert_allclose(cv.yaw_from_azimuth(cv.azimuth_from_yaw(w)), w, atol=1e-12)


def test_rfu_flu_axes():
    np.testing.assert_array_equal(cv.rfu_to_flu([1.0, 0.0, 0.0]), [0.0, -1.0, 0.0])  # starboard
    np.testing.assert_array_equal(cv.rfu_to_flu([0.0, 1.0, 0.0]), [1.0, 0.0, 0.0])  # forward
    v = RNG.normal(size=(10, 3))
    np.testing.assert_array_equal(cv.flu_to_rfu(cv.rfu_to_flu(v)), v)


def test_seed_angles():
    K, theta, gamma = np.deg2rad([[30.0], [10.0], [-5.0]])
    q = cv.quat_from_seed_angles(K, theta, gamma)[0]
    # The seeds' factorisation C_n,rfu = R_up(-K) R_x(theta) R_y(gamma) (seed 001 B2.10), built
    # with scipy (intrinsic "ZXY" = Rz Rx Ry) on the RFU axes.
    C = Rotation.from_euler("ZXY", [-K[0], theta[0], gamma[0]]).as_matrix()
    v_rfu = RNG.normal(size=(5, 3))
    np.testing.assert_allclose(quat_rotate(q, cv.rfu_to_flu(v_rfu)), v_rfu @ C.T, atol=1e-14)
    # Geometry: forward axis points 30 deg east of north and 10 deg up; right wing down.
    fwd = quat_rotate(q, [1.0, 0.0, 0.0])
    assert np.degrees(np.arctan2(fwd[0], fwd[1])) == pytest.approx(30.0)
    assert np.degrees(np.arcsin(fwd[2])) == pytest.approx(10.0)
    right = quat_rotate(q, [0.0, -1.0, 0.0])
    assert right[2] > 0  # gamma = -5 deg: right wing UP
    # Round trip incl. heading in [0, 2 pi).
    h, p, r = RNG.uniform(0, 2 * np.pi, 100), RNG.uniform(-1.5, 1.5, 100), RNG.uniform(-3, 3, 100)
    hh, pp, rr = cv.seed_angles_from_quat(cv.quat_from_seed_angles(h, p, r))
    np.testing.assert_allclose(np.c_[hh, pp, rr], np.c_[h, p, r], atol=1e-12)


def test_ned_frd_to_enu_flu():
    r = Rotation.random(200, random_state=3)
    q_ned = r.as_quat()[:, [3, 0, 1, 2]]
    q_enu = cv.quat_ned_frd_to_enu_flu(q_ned)
    v_frd = RNG.normal(size=(200, 3))
    np.testing.assert_allclose(quat_rotate(q_enu, cv.frd_to_flu(v_frd)),
                               cv.ned_to_enu(r.apply(v_frd)), atol=1e-14)
    assert np.max(quat_angle_between(cv.quat_enu_flu_to_ned_frd(q_enu), q_ned)) < 1e-14
    # Euler angles: scipy "ZYX" is the aerospace yaw-pitch-roll of C_ned,frd.
    yaw, pitch, roll = r.as_euler("ZYX").T
    e = cv.euler_ned_to_enu(roll, pitch, yaw)
    assert np.max(quat_angle_between(quat_from_euler(*e), q_enu)) < 1e-14
    back = cv.euler_enu_to_ned(*e)
    np.testing.assert_allclose(np.c_[back[0], back[1], cv.wrap_pi(back[2])],
                               np.c_[roll, pitch, yaw], atol=1e-12)
    # Heading 90 deg in NED looks East: ENU yaw 0.
    np.testing.assert_allclose(cv.euler_ned_to_enu(0.0, 0.0, np.pi / 2)[2], 0.0, atol=1e-15)


@pytest.mark.skipif(not VESSEL.exists(), reason="../shared data absent")
def test_vessel_data_in_enu_flu():
    """Recorded NED/FRD vessel truth, converted here, must satisfy f_n = a_n - g_n in ENU and
    the gyro rates must match the attitude's rate of change."""
    pd = pytest.importorskip("pandas")
    d = pd.read_parquet(VESSEL)
    dt = 1.0 / 10.24
    rpy = cv.euler_ned_to_enu(*np.deg2rad(d[["Alpha", "Beta", "Gamma"]].to_numpy().T))
    q = quat_from_euler(*rpy)
    f_enu = quat_rotate(q, cv.frd_to_flu(d[["Ax", "Ay", "Az"]].to_numpy()))
    a_enu = np.gradient(cv.ned_to_enu(d[["VX", "VY", "VZ"]].to_numpy()), dt, axis=0)
    res = f_enu - a_enu  # = -g_enu = [0, 0, +g]
    np.testing.assert_allclose(res.mean(0), [0.0, 0.0, 9.80665], atol=1e-4)
    assert np.max(res.std(0)) < 1e-3 < np.min(f_enu.std(0))
    w_flu = cv.frd_to_flu(np.deg2rad(d[["Gx", "Gy", "Gz"]].to_numpy()))
    w_att = quat_to_rotvec(quat_mul(quat_conj(q[:-1]), q[1:])) / dt
    err = w_att - 0.5 * (w_flu[:-1] + w_flu[1:])
    assert np.max(err.std(0)) < 1e-2 * np.min(w_flu.std(0))
