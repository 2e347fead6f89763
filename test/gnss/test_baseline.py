"""Baseline float/fixed solutions against simulated truth (exact ranges, known integers)."""

import numpy as np
import pytest
from scipy.optimize import minimize
from scipy.stats import chi2

from ins_gnss_ros.gnss.baseline import (
    AmbiguityStore, closest_point_on_sphere, fix_ambiguities, fixed_baselines, float_solution)
from ins_gnss_ros.gnss.differences import NoiseModel, form_double_differences, select_references
from ins_gnss_ros.nav.rotations import dcm_from_euler
from phase_sim import PhaseSim, WL1


ANT = np.array([[0.0, 0.0, 0.0], [1.5, 0.0, 0.0]])


def _epoch(sim, t, R, refs=None):
    los = sim.los(t)
    ids = sim.ids
    el = [np.arcsin(los[s][2]) for s in ids]
    refs = select_references(ids, el, [WL1] * len(ids), refs)
    return form_double_differences(sim.observe(t, R), los, refs, sim.noise), refs


def _true_dd_ambiguities(sim, dd):
    out = []
    for j, (s, r) in enumerate(dd.pairs):
        k, i, ir = dd.baseline[j], sim.ids.index(s), sim.ids.index(r)
        out.append(sim.N[k, i] - sim.N[0, i] - sim.N[k, ir] + sim.N[0, ir])
    return np.array(out)


def test_float_solution_is_exact_without_noise():
    sim = PhaseSim(11, ANT, noise=NoiseModel(1e-9, 0, 1e-9, 0))
    R = dcm_from_euler(0.02, -0.03, 1.1)
    dd, _ = _epoch(sim, 0.0, R)
    fs = float_solution(dd, 1)
    # Exact ranges differ from the plane-wave model by |b|²/(2ρ) ~ 1e-7 m.
    np.testing.assert_allclose(fs.baseline, R @ ANT[1], atol=1e-6)
    np.testing.assert_allclose(fs.ambiguities, _true_dd_ambiguities(sim, dd), atol=1e-5)


def test_closest_point_on_sphere_matches_numerical_optimiser():
    """Against a dense latitude/longitude grid of the sphere refined by BFGS."""
    rng = np.random.default_rng(0)
    th, ph = np.meshgrid(np.linspace(0, np.pi, 181), np.linspace(-np.pi, np.pi, 361))

    def on_sphere(p):
        return 1.5 * np.stack([np.sin(p[0]) * np.cos(p[1]), np.sin(p[0]) * np.sin(p[1]),
                               np.cos(p[0])], -1)

    for _ in range(30):
        A = rng.normal(size=(3, 3))
        W = A @ A.T + 0.1 * np.eye(3)
        c = rng.normal(size=3) * rng.uniform(0.2, 3)
        b, cost = closest_point_on_sphere(c, W, 1.5)
        assert np.linalg.norm(b) == pytest.approx(1.5, abs=1e-9)
        r = on_sphere(np.stack([th, ph])) - c
        grid = np.einsum("...i,ij,...j->...", r, W, r)
        i = np.unravel_index(np.argmin(grid), grid.shape)
        f = lambda p: (on_sphere(p) - c) @ W @ (on_sphere(p) - c)   # noqa: E731
        res = minimize(f, [th[i], ph[i]], method="BFGS", options={"gtol": 1e-10})
        assert cost <= res.fun + 1e-8
        assert cost == pytest.approx(res.fun, rel=1e-6, abs=1e-9)


def test_single_epoch_fix_with_length_constraint_never_accepts_wrong_integers():
    """Single epoch, single frequency, 1.5 m, 8-12 satellites: the length-constrained search
    fixes most epochs, more than LAMBDA alone, and no accepted fix (ratio >= 3) is wrong."""
    accepted = accepted_plain = 0
    for seed in range(60):
        sim = PhaseSim(100 + seed, ANT, n_gps=4 + seed % 3, n_gal=4 + (seed // 3) % 3)
        R = dcm_from_euler(0.05, -0.02, seed * 0.3)
        dd, _ = _epoch(sim, 0.0, R)
        fs = float_solution(dd, 1)
        truth = _true_dd_ambiguities(sim, dd)
        fix = fix_ambiguities(fs, 1.5, 0.002)
        if fix is not None and fix.ratio >= 3.0:
            accepted += 1
            np.testing.assert_array_equal(fix.ambiguities, truth)
            # Conditional baseline covariance Q_bb - Q_ba Q_aa⁻¹ Q_ab: the error is consistent.
            Q = fs.cov
            Qc = Q[:3, :3] - Q[:3, 3:] @ np.linalg.solve(Q[3:, 3:], Q[3:, :3])
            err = fix.baseline - R @ ANT[1]
            assert err @ np.linalg.solve(Qc, err) < chi2.ppf(0.9999, 3)
        plain = fix_ambiguities(fs)
        if plain.ratio >= 3.0:
            accepted_plain += 1
            np.testing.assert_array_equal(plain.ambiguities, truth)
    assert accepted >= 40
    assert accepted > accepted_plain
    print(f"single-epoch fixes accepted: {accepted}/60 with length, {accepted_plain}/60 without")


def test_attitude_prior_shrinks_the_float_ambiguities():
    sim = PhaseSim(5, ANT)
    R = dcm_from_euler(0.0, 0.0, 0.7)
    dd, _ = _epoch(sim, 0.0, R)
    P = np.diag([0.02, 0.02, 0.03]) ** 2
    err = np.array([0.01, -0.01, 0.02])              # prior attitude off by ~1 deg
    b_prior = dcm_from_euler(*err) @ R @ ANT[1]
    fs0 = float_solution(dd, 1)
    fs1 = float_solution(dd, 1, prior=(np.eye(3), b_prior, P))
    assert np.trace(fs1.cov[3:, 3:]) < 0.2 * np.trace(fs0.cov[3:, 3:])
    fix = fix_ambiguities(fs1, 1.5, 0.002)
    np.testing.assert_array_equal(fix.ambiguities, _true_dd_ambiguities(sim, dd))


def test_up_component_prior_adds_information_on_the_up_axis_only():
    # A prior on the up component alone (an INS's roll and pitch, heading unknown) is no 3x3
    # covariance with a large horizontal variance: the information of the float solution grows
    # by exactly 1/σ² on the up axis of the baseline and nowhere else.
    sim = PhaseSim(6, ANT)
    R = dcm_from_euler(0.03, -0.02, 2.0)
    dd, _ = _epoch(sim, 0.0, R)
    sigma = 0.013
    fs0 = float_solution(dd, 1)
    fs1 = float_solution(dd, 1, prior=([[0.0, 0.0, 1.0]], [(R @ ANT[1])[2]], [[sigma ** 2]]))
    gain = np.linalg.inv(fs1.cov) - np.linalg.inv(fs0.cov)
    expected = np.zeros_like(gain)
    expected[2, 2] = 1.0 / sigma ** 2
    np.testing.assert_allclose(gain, expected, atol=1e-6 * expected[2, 2])
    assert fs1.cov[2, 2] < sigma ** 2 < fs0.cov[2, 2]


def test_fixed_baseline_error_is_consistent_with_its_covariance():
    ant = np.array([[0, 0, 0], [1.5, 0, 0], [0.2, -1.0, 0.05]])
    nees = []
    for seed in range(40):
        sim = PhaseSim(200 + seed, ant)
        R = dcm_from_euler(0.03, 0.01, seed)
        dd, _ = _epoch(sim, 0.0, R)
        fb = fixed_baselines(dd, _true_dd_ambiguities(sim, dd), 2)
        err = (fb.baselines - ant[1:] @ R.T).ravel()
        nees.append(err @ np.linalg.solve(fb.cov, err) / 6)
        assert fb.consistent()
    assert 0.6 < np.mean(nees) < 1.5
    # A wrong integer on one row is caught by the residual test.
    truth = _true_dd_ambiguities(sim, dd)
    truth[2] += 1
    assert not fixed_baselines(dd, truth, 2).consistent()


def test_correlated_error_is_propagated_through_the_fixed_solution():
    # Errors drawn from dd.cov_correlated added to the DD phases move the fixed baselines with
    # the covariance fixed_baselines reports for them (Monte Carlo, 3000 draws).
    ant = np.array([[0, 0, 0], [1.5, 0, 0], [0.2, -1.0, 0.05]])
    sim = PhaseSim(31, ant)
    dd, _ = _epoch(sim, 0.0, dcm_from_euler(0.02, 0.01, 0.7))
    rng = np.random.default_rng(8)
    a = rng.normal(size=(dd.phase.size, dd.phase.size))
    dd.cov_correlated = 0.02 * a @ a.T / dd.phase.size + 0.01 * dd.cov_phase
    truth = _true_dd_ambiguities(sim, dd)
    fb = fixed_baselines(dd, truth, 2)
    phase = dd.phase.copy()
    moved = []
    for e in rng.multivariate_normal(np.zeros(phase.size), dd.cov_correlated, 3000):
        dd.phase = phase + e
        moved.append((fixed_baselines(dd, truth, 2).baselines - fb.baselines).ravel())
    emp = np.cov(np.array(moved).T)
    scale = np.sqrt(np.outer(np.diag(fb.cov_correlated), np.diag(fb.cov_correlated)))
    assert np.max(np.abs(emp - fb.cov_correlated) / scale) < 0.1
    assert not np.allclose(fb.cov_correlated, fb.cov * np.trace(fb.cov_correlated)
                           / np.trace(fb.cov), rtol=0.1)   # not merely a scaled P


def test_store_rereferencing_keeps_ambiguities_valid():
    sim = PhaseSim(9, ANT)
    dd, refs = _epoch(sim, 0.0, np.eye(3))
    store = AmbiguityStore()
    store.hold(dd, np.arange(dd.phase.size), _true_dd_ambiguities(sim, dd))
    g = next(iter(refs))
    old = refs[g]
    new = next(s for s, r in dd.pairs if r == old)
    store.rereference(old, new)
    refs2 = dict(refs)
    refs2[g] = new
    dd2 = form_double_differences(sim.observe(1.0, np.eye(3)), sim.los(1.0), refs2)
    held = store.lookup(dd2)
    assert np.all(np.isfinite(held))
    np.testing.assert_array_equal(held, _true_dd_ambiguities(sim, dd2))
    store.forget(signals={new})
    assert len(store) == dd2.phase.size - sum(1 for s, _ in dd2.pairs if s == new)


def test_accumulated_float_on_a_rotating_baseline():
    """Ten epochs of a turning platform: each epoch's baseline is eliminated, the shared
    ambiguities tighten and stay consistent with the truth."""
    sim = PhaseSim(13, ANT, n_gps=3, n_gal=3, noise=NoiseModel(0.002, 0.002, 0.3, 0.0))
    refs, history = None, []
    for i in range(10):
        R = dcm_from_euler(0.05 * np.sin(i), 0.0, 0.1 * i)
        dd, refs = _epoch(sim, float(i), R, refs)
        if i < 9:
            history.append(dd)
    single = float_solution(dd, 1)
    multi = float_solution(dd, 1, history=history)
    assert np.trace(multi.cov[3:, 3:]) < 0.3 * np.trace(single.cov[3:, 3:])
    err = multi.ambiguities - _true_dd_ambiguities(sim, dd)
    assert err @ np.linalg.solve(multi.cov[3:, 3:], err) < chi2.ppf(0.999, err.size)
    assert np.linalg.norm(multi.baseline - R @ ANT[1]) < 4 * np.sqrt(np.trace(multi.cov[:3, :3]))
