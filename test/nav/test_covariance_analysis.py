"""Covariance analysis against Monte Carlo runs of the non-linear mechanisation, and the
statistics of the sensor-error simulator (seed 001 B4.10-B4.11)."""

import allantools
import numpy as np
import pytest
from scipy.stats import chi2

from ins_gnss_ros.nav import covariance_analysis as ca
from ins_gnss_ros.nav import error_model as em
from ins_gnss_ros.nav import sensor_errors as se
from ins_gnss_ros.nav.strapdown import NavState
from ins_gnss_ros.sim.trajectory import Kinematics, generate

DEG = np.pi / 180.0


class Drive:
    """Accelerating car-like drive with a continuous turn."""

    def evaluate(self, t):
        speed, dspeed = 5.0 + 0.5 * t, 0.5 + 0 * t
        yaw, dyaw = 0.3 + 0.05 * t + 0.2 * np.sin(0.2 * t), 0.05 + 0.04 * np.cos(0.2 * t)
        c, s = np.cos(yaw), np.sin(yaw)
        v = np.stack([speed * c, speed * s, 0 * t], -1)
        a = np.stack([dspeed * c - speed * s * dyaw, dspeed * s + speed * c * dyaw, 0 * t], -1)
        zero = 0 * t
        return Kinematics(v, a, np.stack([zero, zero, yaw], -1), np.stack([zero, zero, dyaw], -1))


def drive(duration, dt):
    traj = generate(Drive(), 45.0 * DEG, 7.0 * DEG, 200.0, duration, rate=1 / dt, oversample=2)
    return traj, NavState(traj.lat[0], traj.lon[0], traj.h[0], traj.v_enu[0], traj.q_nb[0])


LAYOUT_BLOCKS = ("pos", "vel", "att", "bg", "ba", "gmg", "gma", "sg", "sa", "ng", "na", "gs")


@pytest.mark.parametrize("grade,duration,sig_att", [
    (se.TACTICAL, 60.0, (1e-3, 1e-3, 5e-3)),
    (se.MEMS_ADIS16405, 20.0, (3e-3, 3e-3, 2e-2)),
], ids=["tactical", "mems"])
def test_monte_carlo_matches_covariance(grade, duration, sig_att):
    """Per-state variance ratio inside the χ² 99 % interval (Bonferroni over all checks)."""
    dt, runs = 0.1, 150
    traj, s0 = drive(duration, dt)
    noise = se.filter_noise(grade, "gm")
    layout = em.make_layout(LAYOUT_BLOCKS, noise)
    sig = (4.0, 0.2, np.array(sig_att))
    P0 = em.initial_covariance(layout, noise, *sig)
    n = len(traj.dtheta)
    record = [n // 3, 2 * n // 3, n]
    P = ca.propagate_covariance(layout, s0, traj.dtheta, traj.dv, dt, noise, P0, record)
    err = ca.monte_carlo(s0, traj.dtheta, traj.dv, dt, grade, runs,
                         np.random.default_rng(2024), *sig, record)
    var_mc = np.mean(err ** 2, axis=0)               # zero-mean errors: N degrees of freedom
    var_pred = np.diagonal(P, axis1=1, axis2=2)[:, :9]
    ratio = var_mc / var_pred
    alpha = 0.01 / ratio.size
    lo, hi = chi2.ppf(alpha / 2, runs) / runs, chi2.ppf(1 - alpha / 2, runs) / runs
    assert np.all((ratio > lo) & (ratio < hi)), ratio
    # The errors really grow: the check is not one of the initial covariance only.
    assert np.all(var_pred[-1, :6] > 1.5 * var_pred[0, :6] - 1e-30) or duration < 30


def test_mean_of_monte_carlo_is_zero():
    dt, runs = 0.1, 150
    traj, s0 = drive(20.0, dt)
    err = ca.monte_carlo(s0, traj.dtheta, traj.dv, dt, se.TACTICAL, runs,
                         np.random.default_rng(7), 4.0, 0.2, 1e-3, [len(traj.dtheta)])
    z = err.mean(axis=0) / (err.std(axis=0) / np.sqrt(runs))
    assert np.all(np.abs(z) < 4.0)


def test_gauss_markov_stationary_variance_and_correlation():
    sigma, tau, dt = 2.0, 5.0, 0.1
    grade = se.ImuGrade("gm", se.TriadErrors(0.0, 0.0, sigma, tau), se.TriadErrors(0.0, 0.0))
    sim = se.ImuErrorSimulator(grade, dt, np.random.default_rng(0), 400)
    dth, _ = sim.corrupt(np.zeros((500, 3)), np.zeros((500, 3)))
    b = dth / dt                                            # (R, N, 3) bias samples
    assert b.var() == pytest.approx(sigma ** 2, rel=0.03)
    lag = int(tau / dt)
    rho = np.mean(b[:, :-lag] * b[:, lag:]) / sigma ** 2
    assert rho == pytest.approx(np.exp(-1.0), abs=0.03)
    # Continuing the sequence keeps the process (no restart at the stationary draw).
    nxt, _ = sim.corrupt(np.zeros((1, 3)), np.zeros((1, 3)))
    assert np.corrcoef(b[:, -1].ravel(), nxt[:, 0].ravel() / dt)[0, 1] > 0.95


def test_random_walk_variance_growth():
    q, dt, n = 1e-3, 0.5, 400
    grade = se.ImuGrade("rw", se.TriadErrors(0.0, 0.0, rw_density=np.sqrt(q)),
                        se.TriadErrors(0.0, 0.0))
    sim = se.ImuErrorSimulator(grade, dt, np.random.default_rng(1), 2000)
    dth, _ = sim.corrupt(np.zeros((n, 3)), np.zeros((n, 3)))
    b = dth / dt
    assert b[:, -1].var() == pytest.approx(q * (n - 1) * dt, rel=0.05)


def test_white_noise_allan_deviation():
    """White rate noise of density N has Allan deviation N/√τ (IEEE Std 952)."""
    density, dt = 0.01, 0.01
    grade = se.ImuGrade("w", se.TriadErrors(density, 0.0), se.TriadErrors(0.0, 0.0))
    sim = se.ImuErrorSimulator(grade, dt, np.random.default_rng(3), 1)
    dth, _ = sim.corrupt(np.zeros((100000, 3)), np.zeros((100000, 3)))
    taus, adev, _, _ = allantools.oadev(dth[0, :, 0] / dt, rate=1 / dt, data_type="freq",
                                        taus=np.array([0.1, 1.0, 10.0]))[:4]
    np.testing.assert_allclose(adev, density / np.sqrt(taus), rtol=0.1)


def test_scale_misalignment_and_g_sensitivity_application():
    """Measured = (I + S + N) x + G_s Δv: Babich's linear form with Γ (eq. 5.4-5.5)."""
    grade = se.ImuGrade("sm", se.TriadErrors(0.0, 0.0, scale_sigma=1e-3, misalign_sigma=1e-3),
                        se.TriadErrors(0.0, 0.0, scale_sigma=1e-3, misalign_sigma=1e-3),
                        g_sensitivity_sigma=1e-4)
    sim = se.ImuErrorSimulator(grade, 0.1, np.random.default_rng(4), 1)
    w = np.array([[0.3, -0.2, 0.1]])
    f = np.array([[0.5, 0.2, 9.8]])
    dth_m, dv_m = sim.corrupt(w, f)
    s = sim.gyro
    expected = w[0] + np.diag(s.scale[0]) @ w[0] + se.misalign_jacobian(w[0]) @ s.misalign[0] \
        + sim.g_sensitivity[0] @ f[0]
    np.testing.assert_allclose(dth_m[0, 0], expected, rtol=1e-14)
    # Γ layout: β_XY is the x sensor's response to the y input.
    beta = np.zeros(6)
    beta[0] = 1.0
    np.testing.assert_allclose(se.error_matrix(np.zeros(3), beta) @ [0, 1, 0], [1, 0, 0])


def test_filter_noise_models():
    gm = se.filter_noise(se.TACTICAL, "gm")
    rw = se.filter_noise(se.TACTICAL, "rw")
    g = se.TACTICAL.gyro
    assert gm.blocks["gmg"].psd == pytest.approx(2 * g.gm_sigma ** 2 / g.gm_tau)
    assert rw.blocks["bg"].psd == pytest.approx(2 * g.gm_sigma ** 2 / g.gm_tau)
    assert rw.blocks["bg"].sigma0 == pytest.approx(np.hypot(g.bias_sigma, g.gm_sigma))
    assert "gmg" not in rw.blocks
    with pytest.raises(ValueError):
        se.filter_noise(se.TACTICAL, "ar2")


def test_the_exact_bias_model_only_in_a_layout_with_its_gauss_markov_states():
    """bias_model gm in a layout without gmg/gma would leave the in-run instability to no state
    and no noise (constant biases): the ekf's noise is then the reduced model's."""
    from ins_gnss_ros.nav.filter_config import PARAMS, noise_model
    p = {param.name: param.default for param in PARAMS}
    reduced = se.filter_noise(se.GRADES[p["imu_grade"]], "rw")
    for layout, exact in (("15", False), ("21", False), ("21gm", True)):
        noise = noise_model({**p, "layout": layout, "bias_model": "gm"})
        assert ("gmg" in noise.blocks) == exact
        if not exact:
            assert noise.blocks["bg"].psd == reduced.blocks["bg"].psd > 0.0
            assert noise.blocks["ba"].psd == reduced.blocks["ba"].psd > 0.0
