"""Double differences against ranges computed from satellite positions (independent truth)."""
import numpy as np
import pytest

from ins_gnss_ros.gnss.differences import (
    AntennaEpoch, NoiseModel, elevation_sigma, form_double_differences, second_differences,
    select_references)
from ins_gnss_ros.gnss.multipath import MultipathModel
from phase_sim import WL1, PhaseSim


def test_double_differences_remove_clocks_and_leave_integers():
    ant = np.array([[0, 0, 0], [1.5, 0, 0], [0, 1.0, 0.2]])
    sim = PhaseSim(1, ant, noise=NoiseModel(0, 0, 0, 0))
    R = np.eye(3)
    obs = sim.observe(0.0, R)
    los = sim.los(0.0)
    az, el = sim.azel(0.0)
    refs = select_references(sim.ids, el, np.full(el.size, WL1))
    dd = form_double_differences(obs, los, refs)
    assert len(dd.pairs) == 2 * (len(sim.ids) - 2)      # 2 baselines, 2 systems
    for j, (s, r) in enumerate(dd.pairs):
        assert s[0] == r[0]                              # within one system only
        k = dd.baseline[j]
        b = ant[k]
        i, ir = sim.ids.index(s), sim.ids.index(r)
        true_N = sim.N[k, i] - sim.N[0, i] - sim.N[k, ir] + sim.N[0, ir]
        assert dd.phase[j] - dd.geometry[j] @ b / WL1 == pytest.approx(true_N, abs=1e-5)
        assert dd.code[j] == pytest.approx(dd.geometry[j] @ b, abs=1e-6)


def test_dd_covariance_matches_monte_carlo():
    ant = np.array([[0, 0, 0], [1.5, 0, 0], [0, 1.0, 0]])
    noise = NoiseModel(0.002, 0.003, 0.3, 0.3)
    sim = PhaseSim(2, ant, noise=noise)
    los = sim.los(0.0)
    el = np.arcsin(np.array([los[s][2] for s in sim.ids]))
    refs = select_references(sim.ids, el, np.full(el.size, WL1))
    rng = np.random.default_rng(5)
    sig = elevation_sigma(el, noise.phase_a, noise.phase_b) / WL1
    zero = np.zeros(el.size)
    samples = []
    for _ in range(8000):
        obs = [AntennaEpoch(sim.ids, sig * rng.normal(size=el.size), zero, np.full(el.size, WL1))
               for _ in ant]
        samples.append(form_double_differences(obs, los, refs, noise).phase)
    dd = form_double_differences(obs, los, refs, noise)
    emp = np.cov(np.array(samples).T)
    scale = np.sqrt(np.outer(np.diag(dd.cov_phase), np.diag(dd.cov_phase)))
    assert np.max(np.abs(emp - dd.cov_phase) / scale) < 0.05
    # Correlations through the reference and the master are present (not a diagonal model).
    assert np.max(np.abs(dd.cov_phase / scale - np.eye(len(dd.pairs)))) > 0.2


def test_correlated_dd_covariance_written_out_for_one_baseline():
    # One baseline: var DD(i, r) = 2 (s_i² + s_r²), cov(DD(i, r), DD(j, r)) = 2 s_r² (both
    # antennas of the common reference), with s the undifferenced multipath sigma in cycles.
    ant = np.array([[0, 0, 0], [1.5, 0, 0]])
    sim = PhaseSim(4, ant)
    los = sim.los(0.0)
    el = np.arcsin(np.array([los[s][2] for s in sim.ids]))
    refs = select_references(sim.ids, el, np.full(el.size, WL1))
    model = MultipathModel(phase_sigma0=0.01, elevation_scale=np.radians(20.0))
    dd = form_double_differences(sim.observe(0.0, np.eye(3)), los, refs, sim.noise,
                                 multipath=model)
    assert form_double_differences(sim.observe(0.0, np.eye(3)), los, refs).cov_correlated is None
    s = dict(zip(sim.ids, model.phase_sigma0 * np.exp(-el / model.elevation_scale) / WL1))
    expect = np.array([[2 * (s[a] ** 2 + s[r] ** 2) if (a, r) == (b, q) else
                        2 * s[r] ** 2 if r == q else 0.0
                        for b, q in dd.pairs] for a, r in dd.pairs])
    np.testing.assert_allclose(dd.cov_correlated, expect, rtol=1e-12)


def test_reference_selection_rules():
    ids = ["G01", "G02", "G03", "E01", "E02", "R01", "R02"]
    el = np.radians([30, 80, 50, 60, 20, 85, 40])
    lam = np.array([WL1] * 5 + [0.1871, 0.1872])         # two GLONASS slots: no DD
    refs = select_references(ids, el, lam)
    assert set(refs.values()) == {"G02", "E01"}
    # Kept while tracked even if no longer the highest; replaced when excluded.
    refs2 = select_references(["G01", "G02", "G03"], np.radians([85, 70, 50]), [WL1] * 3, refs)
    assert refs2[("G", round(WL1 * 1e6))] == "G02"
    refs3 = select_references(["G01", "G02", "G03"], np.radians([85, 70, 50]), [WL1] * 3, refs,
                              exclude={"G02"}, preferred={"G03"})
    assert refs3[("G", round(WL1 * 1e6))] == "G03"


def test_second_differences_are_direction_cosine_differences():
    ant = np.array([[0, 0, 0], [0.3, 1.4, 0.1]])
    sim = PhaseSim(3, ant, noise=NoiseModel(0, 0, 0, 0))
    sim.N[:] = 0.0
    los = sim.los(0.0)
    el = np.arcsin(np.array([los[s][2] for s in sim.ids]))
    dd = form_double_differences(sim.observe(0.0, np.eye(3)), los,
                                 select_references(sim.ids, el, np.full(el.size, WL1)))
    b = ant[1]
    S = second_differences(dd.phase, dd.wavelength, np.linalg.norm(b))
    expect = [(los[s] - los[r]) @ b / np.linalg.norm(b) for s, r in dd.pairs]
    np.testing.assert_allclose(S, expect, atol=1e-7)
