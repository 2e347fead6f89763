"""Coning/sculling algorithms against the analytic classic coning and sculling motions.

The increments are integrated in a non-rotating reference frame (q_k = q_{k-1} ⊗ q(phi_k),
v_k = v_{k-1} + C(q_{k-1}) dv_k), so only the algorithms' errors remain. Theoretical residual
drift rates (derived in ins_gnss_ros.nav.coning, Ignagni 1996): coning
sin(beta)^2 Omega (Omega T)^4 / 960 (two-sample) and / 60 (one-sample); sculling
beta A (Omega T)^4 / 960 and / 60; T = navigation interval.
"""
import numpy as np
import pytest
from scipy.special import j1

from ins_gnss_ros.nav.coning import Integrator, coning_sculling, to_navigation_rate
from ins_gnss_ros.nav.rotations import (quat_conj, quat_from_rotvec, quat_mul, quat_rotate,
                                        quat_to_rotvec)
from ins_gnss_ros.sim import imu_truth

OMEGA = 2 * np.pi * 5.0  # 5 Hz motion
T = 0.01  # 100 Hz navigation
DUR = 10.0  # 50 full periods
N_SUB = {"one_sample": 1, "two_sample": 2}  # same navigation interval, 100 or 200 Hz sensor


def _integrate(phis, dvs, q0):
    q, v = q0, np.zeros(3)
    for p, d in zip(phis, dvs):
        v = v + quat_rotate(q, d)
        q = quat_mul(q, quat_from_rotvec(p))
    return q, v


def _coning_drift(method, beta):
    n_sub = N_SUB[method]
    h = T / n_sub
    dth = imu_truth.coning(beta, OMEGA, h, int(round(DUR / h)))
    phi, dv = to_navigation_rate(dth, np.zeros_like(dth), n_sub, method)
    q, _ = _integrate(phi, dv, imu_truth.coning_attitude(beta, OMEGA, 0.0))
    err = quat_to_rotvec(quat_mul(quat_conj(imu_truth.coning_attitude(beta, OMEGA, DUR)), q))
    return np.linalg.norm(err) / DUR


def _sculling_drift(method, beta, accel):
    n_sub = N_SUB[method]
    h = T / n_sub
    dth, dv = imu_truth.sculling(beta, accel, OMEGA, h, int(round(DUR / h)))
    phi, dvn = to_navigation_rate(dth, dv, n_sub, method)
    q, v = _integrate(phi, dvn, np.array([1.0, 0.0, 0.0, 0.0]))
    truth = np.array([0.0, 0.0, accel * j1(beta) * DUR])
    assert np.linalg.norm(quat_to_rotvec(q)) < 1e-12  # the roll returns to zero
    return np.linalg.norm(v - truth) / DUR


def test_classic_coning():
    beta = 0.05
    one = _coning_drift("one_sample", beta)
    two = _coning_drift("two_sample", beta)
    theory_two = np.sin(beta) ** 2 * OMEGA * (OMEGA * T) ** 4 / 960
    assert one >= 10 * two
    assert theory_two / 2 < two < 2 * theory_two
    assert one == pytest.approx(16 * theory_two, rel=0.5)
    # Without any coning term the drift is the full coning rate sin(beta)^2 (...): much larger.
    dth = imu_truth.coning(beta, OMEGA, T, int(DUR / T))
    q, _ = _integrate(dth, np.zeros_like(dth), imu_truth.coning_attitude(beta, OMEGA, 0.0))
    err = quat_to_rotvec(quat_mul(quat_conj(imu_truth.coning_attitude(beta, OMEGA, DUR)), q))
    assert np.linalg.norm(err) / DUR > 30 * one


def test_classic_sculling():
    beta, accel = 0.01, 5.0
    one = _sculling_drift("one_sample", beta, accel)
    two = _sculling_drift("two_sample", beta, accel)
    theory_two = beta * accel * (OMEGA * T) ** 4 / 960
    assert one >= 10 * two
    assert theory_two / 2 < two < 2 * theory_two


def test_linear_rates_are_exact():
    """Both algorithms are exact to second order for angular rate and specific force linear in
    time: compare with a fine-step integration. The rates are chosen so that the coning and
    sculling terms (~1e-6) dwarf the unmodelled third-order terms (~1e-8)."""
    rng = np.random.default_rng(3)
    w0, w1, f0, f1 = rng.normal(size=(4, 3)) * [[0.05], [20.0], [1.0], [200.0]]
    Tn = 0.01

    def increments(n, t0=0.0, t1=Tn):
        edges = np.linspace(t0, t1, n + 1)
        a, b = edges[:-1], edges[1:]
        dth = np.outer(b - a, w0) + np.outer((b ** 2 - a ** 2) / 2, w1)
        dv = np.outer(b - a, f0) + np.outer((b ** 2 - a ** 2) / 2, f1)
        return dth, dv

    # Reference: 4000 fine steps, attitude by exact quaternion products, velocity increments
    # rotated with the mid-step attitude.
    fine_th, fine_v = increments(4000)
    q, v = np.array([1.0, 0, 0, 0]), np.zeros(3)
    for th_i, v_i in zip(fine_th, fine_v):
        v = v + quat_rotate(quat_mul(q, quat_from_rotvec(0.5 * th_i)), v_i)
        q = quat_mul(q, quat_from_rotvec(th_i))
    phi_ref = quat_to_rotvec(q)
    th2, v2 = increments(2)
    th1, v1 = increments(1)
    th_prev, v_prev = increments(1, -Tn, 0.0)  # the linear rates extrapolated back
    # Size of what the algorithms add beyond the plain sums and the rotation term.
    alpha, ups = th2.sum(0), v2.sum(0)
    coning = np.linalg.norm(phi_ref - alpha)
    sculling = np.linalg.norm(v - ups - 0.5 * np.cross(alpha, ups))
    assert min(coning, sculling) > 1e-7
    for phi, dv in (coning_sculling(th2, v2, "two_sample"),
                    coning_sculling(th1, v1, "one_sample", prev=(th_prev[0], v_prev[0]))):
        assert np.linalg.norm(phi - phi_ref) < 1e-3 * coning
        assert np.linalg.norm(dv - v) < 2e-2 * sculling


def test_streaming_integrator_matches_batch():
    rng = np.random.default_rng(5)
    dth, dv = rng.normal(size=(2, 48, 3)) * 1e-3
    for method, n_sub in (("two_sample", 4), ("one_sample", 3)):
        phi_b, dv_b = to_navigation_rate(dth, dv, n_sub, method)
        integ = Integrator(n_sub, method)
        outs = [o for o in (integ.add(a, b, 0.005) for a, b in zip(dth, dv)) if o is not None]
        assert len(outs) == len(phi_b)
        np.testing.assert_allclose(np.array([o[0] for o in outs]), phi_b, atol=1e-18)
        np.testing.assert_allclose(np.array([o[1] for o in outs]), dv_b, atol=1e-18)
        assert outs[0][2] == pytest.approx(0.005 * n_sub)
    integ = Integrator(2)
    assert integ.add_rates([0.1, 0, 0], [0, 0, 9.8], 0.01) is None
    phi, dvn, dt = integ.add_rates([0.1, 0, 0], [0, 0, 9.8], 0.01)
    np.testing.assert_allclose(phi, [0.002, 0, 0], atol=1e-18)
    # Rotation term: dv_z rotates into -y as the body rolls: 1/2 dtheta x dv.
    assert dvn[1] == pytest.approx(-0.5 * 0.002 * 0.196, rel=1e-9)
    with pytest.raises(ValueError):
        Integrator(3, "two_sample")
    with pytest.raises(ValueError):
        coning_sculling(np.zeros((3, 3)), np.zeros((3, 3)), "two_sample")
