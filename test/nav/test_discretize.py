"""Discretisation: Van Loan against analytic solutions, Picard series against Van Loan.

Reference case "seed" is Babich's (seed 001, extract B3): 33-state SINS model at lat 55.75°,
h = 200 m, V = (150, 100, 5) m/s, f_b = (0.5, 1.0, 9.9) m/s², ω = (0.05, -0.02, 0.1) rad/s,
ARW 0.1 °/√h, VRW 0.05 m/s/√h, in-run biases 10 °/h and 1 mg, T = 3600 s, σ = 1e-4.
"""

import types

import numpy as np
import pytest
from scipy.integrate import solve_ivp
from scipy.linalg import expm

from ins_gnss_ros.nav import discretize as dz
from ins_gnss_ros.nav import error_model as em
from ins_gnss_ros.nav import sensor_errors as se
from ins_gnss_ros.nav.rotations import quat_from_euler

DEG = np.pi / 180.0
HOUR = 3600.0


def nav(lat_deg=55.75, v=(150.0, 100.0, 5.0), euler=(0.1, -0.2, 0.7)):
    return types.SimpleNamespace(lat=lat_deg * DEG, lon=37.6 * DEG, h=200.0,
                                 v_enu=np.array(v), q_nb=quat_from_euler(*euler), t=0.0)


def seed_case():
    """(F, Q) of Babich's 33-state reference case."""
    noise = se.FilterNoise(8.46e-10, 6.94e-7, {
        "bg": se.BlockNoise(10 * se.DEG_PER_HOUR, psd=2 * (10 * se.DEG_PER_HOUR) ** 2 / HOUR),
        "ba": se.BlockNoise(se.MILLI_G, psd=2 * se.MILLI_G ** 2 / HOUR),
        **{k: se.BlockNoise(1e-4, HOUR, 2e-8 / HOUR) for k in ("sg", "sa", "ng", "na")}})
    layout = em.make_layout("33", noise)
    state = nav()
    F = em.system_matrix(layout, state, [0.5, 1.0, 9.9], [0.05, -0.02, 0.1])
    G, Qc = em.noise_input(layout, state, noise)
    return F, G @ Qc @ G.T


def ins_case(spec, grade):
    """(F, Q) of a project layout for a car-like state and an IMU grade."""
    noise = se.filter_noise(grade)
    layout = em.make_layout(spec, noise)
    state = nav(45.0, (15.0, 8.0, 0.3), (0.05, 0.03, 1.0))
    F = em.system_matrix(layout, state, [1.2, -0.8, 9.85], [0.01, -0.02, 0.3])
    G, Qc = em.noise_input(layout, state, noise)
    return F, G @ Qc @ G.T


def rel(a, b):
    return np.linalg.norm(a - b) / np.linalg.norm(b)


def test_van_loan_gauss_markov_analytic():
    tau, q, dt = 50.0, 3.0, 7.0
    phi, Qk = dz.van_loan([[-1 / tau]], [[q]], dt)
    assert phi[0, 0] == pytest.approx(np.exp(-dt / tau), rel=1e-14)
    assert Qk[0, 0] == pytest.approx(q * tau / 2 * (1 - np.exp(-2 * dt / tau)), rel=1e-12)


def test_van_loan_double_integrator_analytic():
    q, dt = 0.3, 2.5
    phi, Qk = dz.van_loan([[0, 1], [0, 0]], np.diag([0, q]), dt)
    np.testing.assert_allclose(phi, [[1, dt], [0, 1]], atol=1e-15)
    np.testing.assert_allclose(Qk, q * np.array([[dt ** 3 / 3, dt ** 2 / 2], [dt ** 2 / 2, dt]]),
                               rtol=1e-12)


def test_van_loan_matches_lyapunov_ode():
    rng = np.random.default_rng(1)
    F = rng.normal(size=(5, 5))
    L = rng.normal(size=(5, 5))
    Q = L @ L.T
    dt = 0.3
    sol = solve_ivp(lambda t, p: (F @ p.reshape(5, 5) + p.reshape(5, 5) @ F.T + Q).ravel(),
                    (0, dt), np.zeros(25), rtol=1e-12, atol=1e-14)
    _, Qk = dz.van_loan(F, Q, dt)
    np.testing.assert_allclose(Qk, sol.y[:, -1].reshape(5, 5), rtol=1e-8, atol=1e-12)


def test_discretize_dispatch_uses_g_qc_gt():
    F, _ = ins_case("15", se.TACTICAL)
    G = np.random.default_rng(0).normal(size=(15, 4))
    Qc = np.diag([1.0, 2.0, 3.0, 4.0])
    phi_p, Q_p = dz.discretize(F, G, Qc, 0.01, order=6)
    phi_v, Q_v = dz.discretize(F, G, Qc, 0.01, method="van_loan")
    np.testing.assert_allclose(phi_p, expm(F * 0.01), atol=1e-14)
    assert rel(Q_p, Q_v) < 1e-12 and rel(Q_v, dz.van_loan(F, G @ Qc @ G.T, 0.01)[1]) < 1e-14
    with pytest.raises(ValueError):
        dz.discretize(F, G, Qc, 0.1, method="euler")


@pytest.mark.parametrize("order", [1, 2, 3, 4])
def test_picard_q_convergence_rate_in_dt(order):
    """Local truncation error of Q_k is O(Δt^(ν+1)): fit the log-log slope (Babich B3)."""
    F, Q = seed_case()
    dts = 0.2 / 2.0 ** np.arange(5)
    err = [rel(dz.picard_process_noise(F, Q, dt, order), dz.van_loan(F, Q, dt)[1]) for dt in dts]
    slope = np.polyfit(np.log(dts), np.log(err), 1)[0]
    # Relative error: ‖Q_k‖ itself grows like Δt, so the relative error grows like Δt^ν.
    assert slope == pytest.approx(order, abs=0.1)


@pytest.mark.parametrize("order", [1, 2, 3])
def test_picard_phi_convergence_rate_in_dt(order):
    F, _ = seed_case()
    dts = 0.1 / 2.0 ** np.arange(4)
    err = [np.abs(dz.picard_transition(F, dt, order) - expm(F * dt)).max() for dt in dts]
    slope = np.polyfit(np.log(dts), np.log(err), 1)[0]
    assert slope == pytest.approx(order + 1, abs=0.1)


def test_picard_error_falls_with_order():
    F, Q = seed_case()
    for dt in (0.01, 0.1):
        _, Qref = dz.van_loan(F, Q, dt)
        err = [rel(dz.picard_process_noise(F, Q, dt, nu), Qref) for nu in range(1, 6)]
        assert all(b < 0.1 * a for a, b in zip(err, err[1:]))
    # Babich B4.1: ν >= 5 is exact to 1e-10 at Δt <= 0.1 s.
    assert rel(dz.picard_process_noise(F, Q, 0.1, 5), dz.van_loan(F, Q, 0.1)[1]) < 1e-10


def test_position_block_needs_order_3():
    """Position noise starts at F_rv Q_a F_rv^T Δt³/3: zero for ν <= 2 (Babich B3)."""
    F, Q = seed_case()
    dt = 0.1
    Qref = dz.van_loan(F, Q, dt)[1][:3, :3]
    assert np.all(dz.picard_process_noise(F, Q, dt, 2)[:3, :3] == 0.0)
    assert rel(dz.picard_process_noise(F, Q, dt, 3)[:3, :3], Qref) < 1e-3
    assert rel(dz.picard_process_noise(F, Q, dt, 5)[:3, :3], Qref) < 1e-9


def test_book_formula_identity_and_position_half():
    """(3.1) - P_2 = ½ F Q F^T Δt³ exactly; its position block is ½ instead of ⅓ q Δt³."""
    F, Q = seed_case()
    dt = 0.05
    diff = dz.book_process_noise(F, Q, dt) - dz.picard_process_noise(F, Q, dt, 2)
    np.testing.assert_allclose(diff, 0.5 * F @ Q @ F.T * dt ** 3, rtol=1e-7,
                               atol=1e-12 * np.abs(diff).max())
    ratio = np.diag(dz.book_process_noise(F, Q, dt))[:3] / np.diag(dz.van_loan(F, Q, dt)[1])[:3]
    np.testing.assert_allclose(ratio, 1.5, rtol=0.01)


def test_equal_order_prediction_is_psi_plus_q():
    F, Q = seed_case()
    rng = np.random.default_rng(3)
    A = rng.normal(size=F.shape) * 1e-2
    P = A @ A.T + np.diag(np.linspace(1e-6, 1.0, F.shape[0]))
    dt = 0.05
    for nu in (2, 3, 5):
        psi = dz.picard_predict(P, F, np.zeros_like(Q), dt, nu)  # Ψ_ν alone
        np.testing.assert_allclose(dz.picard_predict(P, F, Q, dt, nu),
                                   psi + dz.picard_process_noise(F, Q, dt, nu), rtol=1e-12,
                                   atol=1e-16)
    phi, Qk = dz.van_loan(F, Q, dt)
    assert rel(dz.picard_predict(P, F, Q, dt, 6), phi @ P @ phi.T + Qk) < 1e-12


def test_order_2_is_indefinite_on_seed_case():
    F, Q = seed_case()
    for dt in (0.01, 0.1):
        Q2 = dz.picard_process_noise(F, Q, dt, 2)
        ev = np.linalg.eigvalsh(Q2)
        assert ev[0] < -1e-6 * ev[-1]  # far beyond round-off
        assert dz.psd_margin(Q2) == -np.inf
        with pytest.raises(np.linalg.LinAlgError):
            np.linalg.cholesky(Q2)
        for nu in (3, 4, 5):
            Qn = dz.picard_process_noise(F, Q, dt, nu)
            assert dz.psd_margin(Qn) > -1e-12
            np.linalg.cholesky(Qn)


@pytest.mark.parametrize("spec", ["15", "21", "24"])
@pytest.mark.parametrize("grade", [se.MEMS_ADIS16405, se.TACTICAL, se.NAVIGATION],
                         ids=lambda g: g.name)
def test_order_3_psd_on_ins_models(spec, grade):
    F, Q = ins_case(spec, grade)
    for dt in (0.005, 0.01, 0.02):
        assert dz.psd_margin(dz.picard_process_noise(F, Q, dt, 2)) == -np.inf
        for nu in (3, 4, 5, 6):
            assert dz.psd_margin(dz.picard_process_noise(F, Q, dt, nu)) > -1e-12


def test_psd_margin_on_known_matrices():
    assert dz.psd_margin(np.diag([1e-20, 1.0, 0.0])) == pytest.approx(1.0)
    assert dz.psd_margin(np.array([[1.0, 2.0], [2.0, 1.0]])) == pytest.approx(-1.0)
    assert dz.psd_margin(np.array([[0.0, 1e-30], [1e-30, 1.0]])) == -np.inf


def test_mems_at_10_hz_needs_order_5():
    """A MEMS gyro's noise reaches position at order Δt⁵ while the Δt³ position-attitude
    cross term is already present at ν = 3: at Δt = 0.1 s ν = 3, 4 are indefinite."""
    F, Q = ins_case("21", se.MEMS_ADIS16405)
    for nu in (3, 4):
        assert dz.psd_margin(dz.picard_process_noise(F, Q, 0.1, nu)) < -0.1
    for nu in (5, 6):
        assert dz.psd_margin(dz.picard_process_noise(F, Q, 0.1, nu)) > 0.0
    assert dz.DEFAULT_ORDER >= 5


def test_compiled_series_equal_the_dense_formulas():
    # The compiled series against the plain numpy formulas of Babich eqs. 2.5-2.9 and 4.5.
    F, Q = seed_case()
    rng = np.random.default_rng(4)
    A = rng.normal(size=F.shape) * 1e-2
    P = A @ A.T + np.eye(F.shape[0]) * 1e-4
    dt, order = 0.1, 5
    phi, term = np.eye(len(F)), np.eye(len(F))
    K, Pk = P.copy(), P.copy()
    for i in range(1, order + 1):
        term = term @ F * (dt / i)
        phi += term
        K = F @ K + K @ F.T + (Q if i == 1 else 0.0)
        Pk += K * dt ** i / np.prod(np.arange(1, i + 1))
    np.testing.assert_allclose(dz.picard_transition(F, dt, order), phi, rtol=1e-13, atol=1e-16)
    np.testing.assert_allclose(dz.picard_predict(P, F, Q, dt, order), Pk, rtol=1e-12,
                               atol=1e-18)
    # Any array layout is accepted (the kernels are compiled for C-contiguous float64).
    np.testing.assert_array_equal(dz.picard_transition(np.asfortranarray(F), dt, order),
                                  dz.picard_transition(F, dt, order))
