"""Rotation utilities against scipy.spatial.transform.Rotation (scalar-last quaternions)."""
import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from ins_gnss_ros.nav import rotations as rot

N = 2000


@pytest.fixture(scope="module")
def rand():
    r = Rotation.random(N, random_state=7)
    q = r.as_quat()[:, [3, 0, 1, 2]]  # scipy [x, y, z, w] -> ours [w, x, y, z]
    return r, q


def test_skew():
    a, b = np.random.default_rng(1).normal(size=(2, 50, 3))
    np.testing.assert_allclose(np.einsum("nij,nj->ni", rot.skew(a), b), np.cross(a, b),
                               atol=1e-15)


def test_mul_conj_rotate(rand):
    r, q = rand
    p = q[::-1]
    r_p = r[::-1]
    # Hamilton composition q_ab ⊗ q_bc = q_ac <-> scipy r_ab * r_bc.
    expect = (r * r_p).as_quat()[:, [3, 0, 1, 2]]
    assert np.max(rot.quat_angle_between(rot.quat_mul(q, p), expect)) < 1e-14
    v = np.random.default_rng(2).normal(size=(N, 3))
    np.testing.assert_allclose(rot.quat_rotate(q, v), r.apply(v), atol=1e-14)
    np.testing.assert_allclose(rot.quat_rotate(rot.quat_conj(q), v), r.inv().apply(v),
                               atol=1e-14)
    np.testing.assert_allclose(rot.quat_normalize(3.0 * -q)[:, 0] >= 0, True)


def test_dcm(rand):
    r, q = rand
    np.testing.assert_allclose(rot.quat_to_dcm(q), r.as_matrix(), atol=1e-15)
    back = rot.dcm_to_quat(r.as_matrix())
    assert np.max(rot.quat_angle_between(back, q)) < 1e-14
    assert np.all(back[:, 0] >= 0)
    # Shepperd branches: 180 deg rotations about each axis (w = 0).
    for axis in np.eye(3):
        qq = rot.dcm_to_quat(Rotation.from_rotvec(np.pi * axis).as_matrix())
        np.testing.assert_allclose(np.abs(qq), np.r_[0.0, axis], atol=1e-15)


def test_rotvec(rand):
    r, q = rand
    rv = r.as_rotvec()
    assert np.max(rot.quat_angle_between(rot.quat_from_rotvec(rv), q)) < 1e-14
    np.testing.assert_allclose(rot.quat_to_rotvec(q), rv, atol=2e-15)
    # Small-angle series, both sides of the switch at 1e-4 rad, against scipy.
    for a in (0.0, 1e-12, 1e-8, 0.99e-4, 1.01e-4, 1e-3):
        v = a * np.array([0.48, -0.6, 0.64])
        expect = Rotation.from_rotvec(v).as_quat()[[3, 0, 1, 2]]
        np.testing.assert_allclose(rot.quat_from_rotvec(v), expect, atol=1e-17, rtol=1e-15)
        np.testing.assert_allclose(rot.quat_to_rotvec(expect), v, atol=1e-20, rtol=1e-13)


def test_euler(rand):
    r, q = rand
    ypr = r.as_euler("ZYX")  # intrinsic z-y'-x'' = Rz(yaw) Ry(pitch) Rx(roll)
    yaw, pitch, roll = ypr.T
    assert np.max(rot.quat_angle_between(rot.quat_from_euler(roll, pitch, yaw), q)) < 1e-14
    np.testing.assert_allclose(rot.dcm_from_euler(roll, pitch, yaw), r.as_matrix(), atol=1e-15)
    ro, pi, ya = rot.quat_to_euler(q)
    np.testing.assert_allclose(np.c_[ya, pi, ro], ypr, atol=1e-12)
    # Gimbal lock still reproduces the rotation.
    for pitch in (np.pi / 2, -np.pi / 2, np.pi / 2 - 1e-9, np.pi / 2 - 1e-7):
        ql = rot.quat_from_euler(0.3, pitch, -0.2)
        assert rot.quat_angle_between(rot.quat_from_euler(*rot.quat_to_euler(ql)), ql) < 3e-8


def test_angle_between():
    q1 = rot.quat_from_euler(0.1, 0.2, 0.3)
    dq = rot.quat_from_rotvec([0.0, 0.0, 0.25])
    assert rot.quat_angle_between(q1, rot.quat_mul(q1, dq)) == pytest.approx(0.25, abs=1e-15)
    assert rot.quat_angle_between(q1, -q1) == pytest.approx(0.0, abs=1e-15)


def test_single_vectors_equal_rows_of_stacks(rand):
    # skew, cross and quat_to_dcm take Python floats for one vector (faster): the results must
    # be bit-identical to those of a stack, in either broadcasting position.
    _, q = rand
    a, b = np.random.default_rng(3).normal(size=(2, 20, 3))
    for k in range(20):
        np.testing.assert_array_equal(rot.quat_to_dcm(q[k]), rot.quat_to_dcm(q[:20])[k])
        np.testing.assert_array_equal(rot.skew(a[k]), rot.skew(a)[k])
        np.testing.assert_array_equal(rot.cross(a[k], b[k]), rot.cross(a, b)[k])
        np.testing.assert_array_equal(rot.cross(a[k], b), rot.cross(a[k][None], b))
    assert rot.cross(a[0], b[0]).shape == (3,) and rot.skew(a[0]).shape == (3, 3)
