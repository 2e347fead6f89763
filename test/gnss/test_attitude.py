"""Phase-difference attitude: closed forms, Wahba, mounting, and the per-epoch solver against
simulated truth (exact ranges, known integers, known attitude)."""

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from scipy.stats import chi2

from ins_gnss_ros.gnss.attitude import (
    AttitudeSolver, baseline_azimuth_elevation, correlated_variance_factor, estimate_mounting,
    rigid_body_misfit, solve_attitude, wahba_svd)
from ins_gnss_ros.gnss.differences import NoiseModel, form_double_differences
from ins_gnss_ros.gnss.multipath import MultipathModel
from ins_gnss_ros.nav.conventions import azimuth_from_yaw, wrap_pi
from ins_gnss_ros.nav.rotations import dcm_from_euler
from phase_sim import PhaseSim


TWO = np.array([[0.0, 0.0, 0.0], [1.5, 0.0, 0.0]])                  # ISON-1: 1.5 m, fore-aft
FOUR = np.array([[0.0, 0.0, 0.0], [1.5, 0.0, 0.0], [0.0, -1.0, 0.0], [1.5, -1.0, 0.05]])


def test_baseline_azimuth_and_elevation():
    az, el = baseline_azimuth_elevation([1.0, 1.0, 0.0])
    assert (np.degrees(az), np.degrees(el)) == pytest.approx((45.0, 0.0))
    az, el = baseline_azimuth_elevation([-1.0, 0.0, 1.0])
    assert (np.degrees(az), np.degrees(el)) == pytest.approx((270.0, 45.0))
    # Covariance against Monte Carlo, and σ_az ≈ σ_across / L.
    rng = np.random.default_rng(0)
    b = np.array([0.9, -1.2, 0.1])
    P = np.diag([0.003, 0.002, 0.006]) ** 2
    _, _, C = baseline_azimuth_elevation(b, P)
    s = rng.multivariate_normal(b, P, 20000)
    mc = np.array([baseline_azimuth_elevation(x) for x in s])
    scale = np.sqrt(np.outer(np.diag(C), np.diag(C)))
    assert np.max(np.abs(np.cov(mc.T) - C) / scale) < 0.03
    across = np.array([-b[1], b[0], 0]) / np.hypot(b[0], b[1])
    assert np.sqrt(C[0, 0]) == pytest.approx(np.sqrt(across @ P @ across) / np.hypot(*b[:2]),
                                             rel=1e-6)


def test_wahba_matches_scipy_align_vectors():
    rng = np.random.default_rng(1)
    for _ in range(20):
        R = Rotation.random(random_state=rng)
        body = rng.normal(size=(3, 3))
        nav = R.apply(body) + 0.01 * rng.normal(size=(3, 3))
        w = rng.uniform(0.5, 2, 3)
        C = wahba_svd(body, nav, w)
        ref, _ = Rotation.align_vectors(nav, body, weights=w)
        np.testing.assert_allclose(C, ref.as_matrix(), atol=1e-9)


def _mc_euler(b_body, R, P, n, rng):
    """Monte Carlo of solve_attitude: mean-square normalised errors per angle."""
    truth = np.array(Rotation.from_matrix(R).as_euler("ZYX")[::-1])   # roll, pitch, yaw
    b_true = (b_body @ R.T).ravel()
    err, var = [], []
    for x in rng.multivariate_normal(b_true, P, n):
        a = solve_attitude(x.reshape(-1, 3), P, b_body)
        err.append(wrap_pi(np.array([a.roll, a.pitch, a.yaw]) - truth))
        var.append(np.diag(a.cov))
    return np.mean(np.array(err) ** 2 / np.array(var), axis=0)


def test_solve_attitude_single_and_multiple_baselines():
    rng = np.random.default_rng(2)
    # Noise-free: exact. Nose up 5 deg is ROS pitch -5 deg (pitch positive nose-down).
    R = dcm_from_euler(0.0, np.radians(-5.0), np.radians(30.0))
    a = solve_attitude((R @ TWO[1])[None], np.eye(3) * 1e-6, TWO[1:])
    assert np.isnan(a.roll) and np.all(np.isnan(a.cov[0]))
    assert (a.pitch, a.yaw) == pytest.approx((np.radians(-5.0), np.radians(30.0)), abs=1e-12)
    assert np.degrees(a.azimuth) == pytest.approx(60.0)
    assert baseline_azimuth_elevation(R @ TWO[1])[1] == pytest.approx(np.radians(5.0))
    # The same attitude seen through a baseline pointing aft (master antenna ahead).
    aft = -TWO[1]
    a = solve_attitude((R @ aft)[None], np.eye(3) * 1e-6, aft[None])
    assert (a.pitch, a.yaw) == pytest.approx((np.radians(-5.0), np.radians(30.0)), abs=1e-12)
    R = dcm_from_euler(0.1, -0.05, 2.5)
    b_body = FOUR[1:] - FOUR[0]
    a = solve_attitude(b_body @ R.T, np.eye(9) * 1e-6, b_body)
    assert (a.roll, a.pitch, a.yaw) == pytest.approx((0.1, -0.05, 2.5), abs=1e-12)
    # Noisy: errors consistent with the propagated covariance.
    nees1 = _mc_euler(TWO[1:], dcm_from_euler(0, 0.02, 1.0), np.diag([2e-3, 2e-3, 5e-3]) ** 2,
                      1200, rng)
    assert np.isnan(nees1[0]) and np.all((0.85 < nees1[1:]) & (nees1[1:] < 1.15))
    A = rng.normal(size=(9, 9))
    P = (A @ A.T / 9 + np.eye(9)) * 3e-3 ** 2       # correlated, as through the master antenna
    nees3 = _mc_euler(b_body, R, P, 1200, rng)
    assert np.all((0.85 < nees3) & (nees3 < 1.15))


def test_rigid_body_misfit_is_chi2_for_the_antenna_geometry_and_flags_one_wrong_baseline():
    rng = np.random.default_rng(3)
    b_body = FOUR[1:] - FOUR[0]
    R = dcm_from_euler(0.1, -0.05, 2.5)
    # Baselines correlated through the master antenna (each baseline's error is remote - master).
    ant = np.diag([0.002, 0.002, 0.005]) ** 2
    P = np.kron(np.ones((3, 3)) + np.eye(3), ant)
    b_true = b_body @ R.T
    draws = [rigid_body_misfit(b_true + x.reshape(3, 3), P, b_body)
             for x in rng.multivariate_normal(np.zeros(9), P, 1000)]
    misfit = np.array([m for m, _ in draws])
    assert {d for _, d in draws} == {6}
    assert np.mean(misfit) == pytest.approx(6.0, rel=0.07)
    assert np.mean(misfit > chi2.ppf(0.99, 6)) < 0.02
    # A wrong fix of baseline 1 alone: its own length right, its direction 4.5 deg off in
    # azimuth (the seed-6 first fix of the 4-antenna sea trial): far from any rigid rotation.
    wrong = b_true.copy()
    wrong[0] = dcm_from_euler(0.0, 0.0, np.radians(4.5)) @ wrong[0]
    assert rigid_body_misfit(wrong, P, b_body)[0] > 10 * chi2.ppf(1 - 1e-4, 6)
    # Collinear baselines leave the rotation about their line free: one degree of freedom more.
    line = np.array([[1.5, 0.0, 0.0], [3.0, 0.0, 0.0]])
    m, dof = rigid_body_misfit(line @ R.T, np.eye(6) * 1e-6, line)
    assert dof == 4 and m == pytest.approx(0.0, abs=1e-9)


def test_mounting_calibration_recovers_offsets():
    rng = np.random.default_rng(3)
    az_off, el_off = np.radians(2.0), np.radians(-1.0)
    u = np.array([np.cos(el_off) * np.cos(az_off), np.cos(el_off) * np.sin(az_off),
                  np.sin(el_off)])
    Cs, bs = [], []
    for i in range(300):
        C = dcm_from_euler(0.1 * np.sin(0.1 * i), 0.05 * np.cos(0.13 * i), 0.02 * i)
        Cs.append(C)
        bs.append(C @ (1.5 * u) + rng.normal(scale=0.003, size=3))
    cal = estimate_mounting(np.array(bs), np.array(Cs))
    assert abs(cal.azimuth_offset - az_off) < 4 * cal.std[0]
    assert abs(cal.elevation_offset - el_off) < 4 * cal.std[1]
    assert np.all(cal.std < np.radians(0.01))


def _truth_dd(sim, dd):
    def n(a, s):
        return sim.N[a, sim.ids.index(s)] + sim.slips.get((a, s), 0.0)
    return np.array([n(k, s) - n(0, s) - n(k, r) + n(0, r)
                     for k, (s, r) in zip(dd.baseline, dd.pairs)])


def _run(ant, seed, epochs, dt, motion, slips=(), prior=False):
    """Run the solver; returns per-epoch normalised squared errors and statuses."""
    sim = PhaseSim(seed, ant)
    solver = AttitudeSolver(ant, noise=sim.noise)
    out, status, detected = [], [], []
    for i in range(epochs):
        t = i * dt
        roll, pitch, yaw = motion(t)
        R = dcm_from_euler(roll, pitch, yaw)
        for (epoch, antenna, k_sat, cycles) in slips:
            if epoch == i:
                s = sim.ids[k_sat] if k_sat is not None else solver.references[("G", 190294)]
                sim.slips[(antenna, s)] = sim.slips.get((antenna, s), 0.0) + cycles
                detected.append(s)
        eps = 1e-4
        dR = (dcm_from_euler(*motion(t + eps)) - R) / eps
        obs = sim.observe(t, R, dR)
        P = np.radians(1.0) ** 2 * np.eye(3)
        sol = solver.process(obs, sim.los(t), t,
                             attitude_prior=(dcm_from_euler(roll, pitch, yaw + 0.01), P)
                             if prior else None)
        status.append(sol.status)
        if detected and detected[-1] is not None and i in [e[0] for e in slips]:
            assert detected[-1] in sol.slipped
        # Every held ambiguity is the true integer (no wrong fix ever kept).
        dd = form_double_differences(obs, sim.los(t), solver.references, sim.noise)
        held = solver.store.lookup(dd)
        ok = np.isfinite(held)
        np.testing.assert_array_equal(held[ok], _truth_dd(sim, dd)[ok])
        if sol.status == "FIXED":
            e = np.array([wrap_pi(sol.roll - roll), sol.pitch - pitch,
                          wrap_pi(sol.azimuth - azimuth_from_yaw(yaw))])
            out.append(e ** 2 / np.array([sol.var_roll, sol.var_pitch, sol.var_azimuth]))
    return np.array(out), status


def _vessel(t):
    return 0.08 * np.sin(0.3 * t), 0.03 * np.sin(0.17 * t + 1), 0.5 + 0.004 * t


def _static(t):
    return 0.0, 0.0, 1.2


@pytest.mark.parametrize("motion", [_static, _vessel])
def test_two_antennas_fix_and_heading_consistent(motion):
    nees, status = [], []
    for seed in range(3):
        e, st = _run(TWO, 30 + seed, 120, 10.0, motion)
        nees.append(e)
        status += st
    nees = np.vstack(nees)
    assert status.count("FIXED") >= 0.95 * len(status)
    assert np.all(np.isnan(nees[:, 0]))                   # roll unobservable with 2 antennas
    assert 0.7 <= np.mean(nees[:, 2]) <= 1.4              # heading
    assert 0.7 <= np.mean(nees[:, 1]) <= 1.4              # pitch


def test_four_antennas_heading_pitch_roll_consistent():
    nees, status = [], []
    for seed in range(3):
        e, st = _run(FOUR, 40 + seed, 100, 10.0, _vessel)
        nees.append(e)
        status += st
    nees = np.vstack(nees)
    assert status.count("FIXED") >= 0.95 * len(status)
    m = np.mean(nees, axis=0)
    assert np.all((0.7 <= m) & (m <= 1.4)), m


def test_cycle_slips_are_detected_and_never_cause_a_wrong_fix():
    # (epoch, antenna, satellite index or None for the GPS reference, cycles)
    slips = [(20, 1, 2, 3.0), (40, 0, None, 1.0), (60, 1, 7, -1.0), (80, 0, 4, 1.0)]
    e, status = _run(TWO, 50, 100, 1.0, _vessel, slips)
    assert status.count("FIXED") >= 95
    assert np.all(e[:, 2] < 25.0)                          # no heading outlier beyond 5 σ


def test_attitude_prior_gives_a_fix_from_the_first_epoch():
    for seed in range(5):
        _, status = _run(TWO, 60 + seed, 1, 1.0, _vessel, prior=True)
        assert status == ["FIXED"]


def test_a_weak_first_fix_is_held_once_confirmed_a_strong_one_at_once():
    # With an attitude prior every epoch's fix passes the ratio test. From 5 Galileo satellites
    # (4 DDs, fewer than WEAK_FIX_DDS) the fix is held at the second epoch that agrees; from 5
    # GPS + 5 Galileo (8 DDs) at the first.
    R = dcm_from_euler(0.02, -0.01, 0.7)
    prior = (dcm_from_euler(0.02, -0.01, 0.71), np.radians(1.0) ** 2 * np.eye(3))
    for n_gps, expected in ((0, ["FLOAT", "FIXED", "FIXED"]), (5, ["FIXED"] * 3)):
        sim = PhaseSim(90, TWO, n_gps=n_gps, n_gal=5)
        solver = AttitudeSolver(TWO, noise=sim.noise, confirm_epochs=2)
        status = []
        for i in range(3):
            t = 0.2 * i
            sol = solver.process(sim.observe(t, R), sim.los(t), t, attitude_prior=prior)
            status.append(sol.status)
        assert status == expected
        dd = form_double_differences(sim.observe(0.4, R), sim.los(0.4), solver.references,
                                     sim.noise)
        np.testing.assert_array_equal(solver.store.lookup(dd), _truth_dd(sim, dd))


def test_tilt_prior_is_free_of_the_heading_and_makes_weak_single_epoch_fixes_reliable():
    # The prior is the up component of each baseline from roll and pitch only: exactly the same
    # whatever the heading, with the variance of the tilt error σ² (|b|² - b_U²) + σ_L².
    solver = AttitudeSolver(FOUR, sigma_length=0.002)
    sigma = np.radians(0.5)
    priors = [solver._priors(None, (dcm_from_euler(0.05, -0.03, yaw), sigma))
              for yaw in (0.0, 1.0, 3.0)]
    for k, bb in enumerate(solver.b_body):
        H, up, var = priors[0][k]
        np.testing.assert_array_equal(H, [[0.0, 0.0, 1.0]])
        p = dcm_from_euler(0.05, -0.03, 0.0) @ bb
        assert up[0] == pytest.approx(p[2], abs=1e-12)
        assert var[0, 0] == pytest.approx(sigma ** 2 * (bb @ bb - p[2] ** 2) + 0.002 ** 2)
        for other in priors[1:]:
            np.testing.assert_allclose(other[k][1], up, atol=1e-12)
            np.testing.assert_allclose(other[k][2], var, rtol=1e-12)
    # Single epoch, 5 Galileo satellites (4 DDs), no confirmation: without a prior few fixes pass
    # the ratio test and some are wrong; with the tilt of an INS whose heading is 115 deg off
    # (and tilt 0.5 deg) most pass and none is wrong (seeds 0-39: 2 right + 1 wrong; 28 + 0).
    right, wrong = {False: 0, True: 0}, {False: 0, True: 0}
    for seed in range(40):
        R = dcm_from_euler(0.05, -0.03, 0.3 * seed)
        ins = dcm_from_euler(0.058, -0.035, 0.3 * seed + 2.0)
        for use in (False, True):
            sim = PhaseSim(seed, TWO, n_gps=0, n_gal=5)
            solver = AttitudeSolver(TWO, noise=sim.noise, window=1)
            obs = sim.observe(0.0, R)
            sol = solver.process(obs, sim.los(0.0), 0.0,
                                 tilt_prior=(ins, np.radians(0.5)) if use else None)
            if sol.status == "FIXED":
                dd = form_double_differences(obs, sim.los(0.0), solver.references, sim.noise)
                ok = np.array_equal(solver.store.lookup(dd), _truth_dd(sim, dd))
                right[use] += ok
                wrong[use] += not ok
    assert wrong[True] == 0 and wrong[False] >= 1
    assert right[True] >= 20 >= 5 >= right[False]


def test_a_signal_without_phase_is_no_reference_and_is_used_once_valid():
    # The highest GPS satellite has no phase on antenna 1 for 3 epochs (half-cycle ambiguity not
    # yet resolved): the rest of its group is double differenced meanwhile, and it joins at once.
    sim = PhaseSim(70, TWO)
    solver = AttitudeSolver(TWO, noise=sim.noise)
    R = dcm_from_euler(0.0, 0.0, 1.2)
    gps = {s for s in sim.ids if s[0] == "G"}
    highest = max(gps, key=lambda s: sim.los(0.0)[s][2])
    for i in range(6):
        obs = sim.observe(float(i), R)
        if i < 3:
            obs[1].phase[sim.ids.index(highest)] = np.nan
        sol = solver.process(obs, sim.los(float(i)), float(i))
        used = {s for s in sol.satellites if s[0] == "G"}
        assert used == (gps - {highest} if i < 3 else gps)


def test_correlated_variance_factor_equals_the_variance_of_an_ar1_mean():
    a = np.exp(-0.2 / 30.0)
    for n in (1, 2, 7, 300):
        lags = np.abs(np.subtract.outer(np.arange(n), np.arange(n)))
        assert correlated_variance_factor(a, n) == pytest.approx(np.sum(a ** lags) / n, rel=1e-9)
    assert correlated_variance_factor(a, np.inf) == pytest.approx(1 / np.tanh(0.1 / 30.0))
    assert correlated_variance_factor(0.0, 50) == 1.0


def test_published_variance_counts_the_correlated_part_for_the_averaging_time():
    # The same epochs (5 Hz) through four solvers: white only; multipath (τ = 30 s) counted once
    # (averaging time 0), for a 1 s average (5 epochs) and for an infinite one (coth(Δt/2τ) ≈
    # 300 times). The first epoch, with no predecessor, counts it once. Fixing is unchanged.
    sim = PhaseSim(80, TWO)
    model = MultipathModel(phase_sigma0=0.01, phase_tau=30.0)
    white = AttitudeSolver(TWO, noise=sim.noise)
    solvers = [AttitudeSolver(TWO, noise=sim.noise, multipath=model, averaging_time=T)
               for T in (0.0, 1.0, np.inf)]
    a = np.exp(-0.2 / 30.0)
    factors = [1.0, correlated_variance_factor(a, 5), 1.0 / np.tanh(0.1 / 30.0)]
    for i in range(5):
        t = 0.2 * i
        obs, los = sim.observe(t, dcm_from_euler(0.0, 0.01, 0.9)), sim.los(t)
        s0, *sols = (s.process(obs, los, t) for s in [white, *solvers])
        assert {s.status for s in [s0, *sols]} == {"FIXED"}
        assert sols[0].azimuth == pytest.approx(s0.azimuth, abs=1e-12)
        extra = sols[0].var_azimuth - s0.var_azimuth
        assert extra > 0.05 * s0.var_azimuth
        for sol, f in zip(sols[1:], factors[1:]):
            assert sol.var_azimuth - s0.var_azimuth == pytest.approx(extra * (f if i else 1.0),
                                                                     rel=1e-9)


def test_fixed_double_differences_are_the_baselines_seen_along_the_lines_of_sight():
    # A FIXED epoch of the 4-antenna solver hands out its DDs with the integers removed: each
    # value is (e_ref - e_i) . (C b) of the true attitude (exact ranges: the plane-wavefront
    # error (|b|^2 / range) is ~1e-7 m) up to the phase noise, with the DD covariance in m^2.
    sim = PhaseSim(61, FOUR, noise=NoiseModel(1e-4, 1e-4, 0.05, 0.05))
    solver = AttitudeSolver(FOUR, noise=sim.noise)
    R = dcm_from_euler(0.05, -0.03, 1.1)
    sol = solver.process(sim.observe(0.0, R), sim.los(0.0), 0.0)
    assert sol.status == "FIXED"
    dds = sol.double_differences
    assert set(dds.remote) == {1, 2, 3} and len(dds.value) == len(dds.pairs)
    np.testing.assert_array_equal(dds.baseline_b, FOUR[dds.remote] - FOUR[0])
    los = sim.los(0.0)
    np.testing.assert_allclose(dds.geometry,
                               [los[r] - los[s] for s, r in dds.pairs], atol=1e-15)
    predicted = np.einsum("ij,ij->i", dds.geometry, dds.baseline_b @ R.T)
    np.testing.assert_allclose(dds.value, predicted, atol=2e-3)
    dd = form_double_differences(sim.observe(0.0, R), los, solver.references, sim.noise)
    assert np.all(np.linalg.eigvalsh(dds.cov) > 0)
    np.testing.assert_allclose(np.diag(dds.cov), dd.wavelength ** 2 * np.diag(dd.cov_phase),
                               rtol=1e-12)
    # The white part of the published covariance is the one the fixing used: the values scatter
    # by it (normalised squared residual about 1 per row, over many rows).
    r = dds.value - predicted
    assert r @ np.linalg.solve(dds.cov, r) / len(r) < 3.0
