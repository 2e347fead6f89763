"""Filter engine checks against closed-form results (ekf.py, gating.py)."""
import numpy as np
import pytest
from scipy.stats import chi2

from ins_gnss_ros.nav.ekf import ErrorStateEKF, ExtraState, StateSpace
from ins_gnss_ros.nav.error_model import make_layout
from ins_gnss_ros.nav.gating import chi2_gate, normalised_innovation
from ins_gnss_ros.nav.sensor_errors import MEMS_ADIS16405, filter_noise
from ins_gnss_ros.nav.strapdown import NavState

NOISE = filter_noise(MEMS_ADIS16405, "rw")


def scalar_filter(p0, extra=ExtraState(1, 1.0)):
    """A filter whose extra scalar state ("mag") is decoupled from the 9 navigation states."""
    space = StateSpace(make_layout("9"), {"mag": extra})
    P0 = np.eye(space.size)
    P0[9, 9] = p0
    return ErrorStateEKF(space, NOISE, P0), space


def test_random_constant_matches_closed_form():
    # x constant, z_k = x + v_k, v ~ N(0, r): the posterior of a Gaussian prior N(0, p0) after
    # n measurements has variance 1 / (1/p0 + n/r) and mean P_n sum(z)/r.
    rng = np.random.default_rng(1)
    p0, r, x = 4.0, 0.25, 1.3
    ekf, space = scalar_filter(p0)
    H = np.zeros((1, space.size))
    H[0, 9] = 1.0
    z = x + np.sqrt(r) * rng.standard_normal(50)
    for k, zk in enumerate(z, start=1):
        res = ekf.update("c", k, [zk], H, [[r]], gate_prob=None)
        assert res.accepted
        pn = 1.0 / (1.0 / p0 + k / r)
        assert ekf.P[9, 9] == pytest.approx(pn, rel=1e-12)
        assert ekf.x[9] == pytest.approx(pn * z[:k].sum() / r, rel=1e-10)


def test_gauss_markov_variance_propagation():
    # First-order Gauss-Markov: P(t) = P0 e^{-2t/tau} + s^2 (1 - e^{-2t/tau}), psd = 2 s^2 / tau.
    tau, s, p0 = 20.0, 0.3, 0.0
    ekf, _ = scalar_filter(p0, ExtraState(1, 0.0, 2 * s * s / tau, tau))
    state = NavState(0.7, 0.2, 10.0)
    f_b, w_b = np.array([0.0, 0.0, 9.8]), np.zeros(3)
    dt, n = 0.1, 300
    for k in range(n):
        ekf.predict(state, f_b, w_b, dt, refresh=(k == 0))
    t = n * dt
    assert ekf.P[9, 9] == pytest.approx(s * s * (1 - np.exp(-2 * t / tau)), rel=1e-6)


def test_joseph_equals_standard_on_well_conditioned_case():
    rng = np.random.default_rng(2)
    space = StateSpace(make_layout("15", NOISE))
    A = rng.standard_normal((15, 15))
    P0 = A @ A.T + 15 * np.eye(15)
    H = rng.standard_normal((3, 15))
    R = np.diag([0.5, 1.0, 2.0])
    z = rng.standard_normal(3)
    ekfs = [ErrorStateEKF(space, NOISE, P0, joseph=j) for j in (True, False)]
    for e in ekfs:
        e.update("m", 0.0, z, H, R, gate_prob=None)
    np.testing.assert_allclose(ekfs[0].P, ekfs[1].P, rtol=1e-10, atol=1e-12)
    np.testing.assert_allclose(ekfs[0].x, ekfs[1].x, rtol=1e-12)


def test_gate_rejects_outlier_and_keeps_state():
    ekf, space = scalar_filter(1.0)
    H = np.zeros((1, space.size))
    H[0, 9] = 1.0
    P_before = ekf.P.copy()
    res = ekf.update("c", 0.0, [10.0], H, [[1.0]])  # NIS = 100 / 2 = 50
    assert not res.accepted and res.reason == "gated"
    assert res.nis == pytest.approx(50.0)
    assert res.gate == pytest.approx(chi2.ppf(0.9999, 1))
    np.testing.assert_array_equal(ekf.P, P_before)
    assert np.all(ekf.x == 0.0)
    forced = ekf.update("c", 0.0, [10.0], H, [[1.0]], force=True)
    assert forced.accepted and forced.reason == "forced"


def test_take_correction_zeroes_state():
    ekf, space = scalar_filter(1.0)
    H = np.zeros((1, space.size))
    H[0, 9] = 1.0
    ekf.update("c", 0.0, [1.0], H, [[1.0]])
    dx = ekf.take_correction()
    assert dx[9] == pytest.approx(0.5)
    assert np.all(ekf.x == 0.0)


def test_unknown_extra_block_is_refused():
    with pytest.raises(ValueError):
        StateSpace(make_layout("9"), {"speed_of_light": ExtraState()})


def test_nis_and_gate_values():
    S = np.array([[4.0, 1.0], [1.0, 2.0]])
    nu = np.array([1.0, -2.0])
    assert normalised_innovation(nu, S) == pytest.approx(nu @ np.linalg.solve(S, nu))
    assert chi2_gate(3, 0.99) == pytest.approx(11.344866730144373)


def test_update_matches_textbook_joseph_form():
    # The compiled update (Cholesky NIS and gain, products skipping H's zero columns) against
    # the plain formulas: K = P H^T S^-1, x + K nu, (I - K H) P (I - K H)^T + K R K^T.
    rng = np.random.default_rng(5)
    space = StateSpace(make_layout("21", NOISE), {"td": ExtraState(1, 0.01)})
    n = space.size
    A = rng.standard_normal((n, n))
    P = A @ A.T + np.eye(n)
    x = rng.normal(0.0, 0.1, n)
    H = np.zeros((3, n))
    H[:, 3:9] = rng.standard_normal((3, 6))   # velocity and attitude columns only
    H[:, space["bg"]] = rng.standard_normal((3, 3))
    R = np.diag([0.5, 1.0, 2.0])
    z = rng.standard_normal(3)
    ekf = ErrorStateEKF(space, NOISE, P)
    ekf.x = x.copy()
    res = ekf.update("m", 0.0, z, H, R, gate_prob=None)
    nu = z - H @ x
    S = H @ P @ H.T + R
    K = P @ H.T @ np.linalg.inv(S)
    I_KH = np.eye(n) - K @ H
    assert res.accepted
    np.testing.assert_allclose(res.innovation, nu, rtol=1e-14)
    np.testing.assert_allclose(res.s_diag, np.diag(S), rtol=1e-14)
    assert res.nis == pytest.approx(nu @ np.linalg.solve(S, nu), rel=1e-12)
    np.testing.assert_allclose(ekf.x, x + K @ nu, rtol=1e-11, atol=1e-14)
    np.testing.assert_allclose(ekf.P, I_KH @ P @ I_KH.T + K @ R @ K.T, rtol=1e-11, atol=1e-13)
    np.testing.assert_array_equal(ekf.P, ekf.P.T)


def test_consider_block_is_never_estimated_and_keeps_its_schmidt_covariance():
    # Schmidt-Kalman (Simon, "Optimal State Estimation", section 7.5): the consider states' gain
    # rows are zero, the rest of the gain is the optimal one, and the covariance is the Joseph
    # form with that gain.
    rng = np.random.default_rng(11)
    space = StateSpace(make_layout("15", NOISE), {"lever_y": ExtraState(1, 1.0, consider=True),
                                                  "lever_z": ExtraState(1, 1.0, consider=True)})
    n, c = space.size, slice(space["lever_y"].start, space["lever_z"].stop)
    np.testing.assert_array_equal(space.consider, np.arange(n)[c])
    A = rng.standard_normal((n, n))
    P = A @ A.T + np.eye(n)
    H = np.zeros((3, n))
    H[:, 0:3] = np.eye(3)
    H[:, c] = -rng.standard_normal((3, 2))
    R, z = 0.1 * np.eye(3), rng.standard_normal(3)
    ekf = ErrorStateEKF(space, NOISE, P)
    assert ekf.update("m", 0.0, z, H, R, gate_prob=None).accepted
    K = P @ H.T @ np.linalg.inv(H @ P @ H.T + R)
    K[c] = 0.0
    I_KH = np.eye(n) - K @ H
    np.testing.assert_array_equal(ekf.x[c], 0.0)
    np.testing.assert_allclose(ekf.x, K @ z, rtol=1e-11, atol=1e-14)
    np.testing.assert_allclose(ekf.P, I_KH @ P @ I_KH.T + K @ R @ K.T, rtol=1e-11, atol=1e-13)
    np.testing.assert_allclose(ekf.P[c, c], P[c, c], rtol=1e-12)  # nothing learned about it
    with pytest.raises(ValueError, match="Joseph"):
        ErrorStateEKF(space, NOISE, P, joseph=False)


def test_consider_block_keeps_a_constant_offset_inside_the_covariance():
    # A position measured through an unknown constant offset (sigma 1 m): the consider filter's
    # variance of the position stays near the offset's (the optimal filter's would be 0.99:
    # 100 - 100^2 / 101), where an ordinary filter that ignores the offset grows sure of a
    # position up to 1 m off (0.01 / 50).
    layout = make_layout("9")
    for consider, floor in ((True, 1.0), (False, 0.0)):
        extras = {name: ExtraState(1, 1.0, consider=True)
                  for name in ("lever_x", "lever_y", "lever_z")} if consider else {}
        space = StateSpace(layout, extras)
        P0 = 100.0 * np.eye(space.size)
        P0[9:, 9:] = np.eye(space.size - 9)  # the offset's own sigma
        ekf = ErrorStateEKF(space, NOISE, P0)
        H = np.zeros((3, space.size))
        H[:, 0:3] = np.eye(3)
        if consider:
            H[:, 9:] = -np.eye(3)
        for _ in range(50):
            ekf.update("pos", 0.0, np.zeros(3), H, 0.01 * np.eye(3), gate_prob=None)
        assert np.diag(ekf.P)[0:3] == pytest.approx(np.full(3, floor), abs=0.01)


def test_update_refuses_an_indefinite_innovation_covariance():
    ekf, space = scalar_filter(1.0)
    H = np.zeros((1, space.size))
    H[0, 9] = 1.0
    with pytest.raises(np.linalg.LinAlgError):
        ekf.update("c", 0.0, [1.0], H, [[-5.0]])  # S = 1 - 5 < 0, as np.linalg.cholesky does
