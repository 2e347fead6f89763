"""Time per epoch of LAMBDA and of the phase-attitude pipeline; single-epoch fixing success.

Geometry: 10 satellites of one system at random azimuths and elevations 10-85 deg (9 DDs),
GPS L1 (lambda = 0.19 m), plane-wave observables of antennas on a rigid body, white noise per
antenna with sigma² = a² + b²/sin²(el), a = b = 2 mm (phase), 0.3 m (code). Sections:

1. ``integer_least_squares`` (decorrelation + search, 2 candidates) and ``partial_fix`` on
   single-epoch float ambiguities: 9 DDs (one baseline) and 18 DDs (two baselines through one
   master antenna, or two frequencies).
2. Single-epoch, single-baseline (1.5 m) fixing with and without the known length: accepted
   (ratio >= 3) and wrong-accepted rates, time of ``fix_ambiguities``.
3. ``AttitudeSolver.process`` per epoch (2 and 4 antennas, held ambiguities, 1 Hz, rolling and
   turning platform): time, share of FIXED epochs, RMS attitude errors against the truth, the
   mean predicted σ, and the mean squared normalised error (NEES per angle, 1 if honest).
4. Weak geometry (6-7 satellites, 2 antennas, 5 s epochs, new sky every run), white noise or
   sinusoidal multipath: share of FIXED epochs and epochs at which a held ambiguity is wrong,
   for ratio thresholds 3 and 5.

Run: .venv/bin/python bench/bench_lambda.py
"""
import time

import numpy as np

from ins_gnss_ros.gnss.attitude import AttitudeSolver
from ins_gnss_ros.gnss.baseline import fix_ambiguities, float_solution
from ins_gnss_ros.gnss.differences import (
    AntennaEpoch, NoiseModel, elevation_sigma, form_double_differences, select_references)
from ins_gnss_ros.gnss.lambda_search import integer_least_squares, partial_fix
from ins_gnss_ros.nav.conventions import azimuth_from_yaw, wrap_pi
from ins_gnss_ros.nav.rotations import dcm_from_euler

WAVELENGTH = 299792458.0 / 1575.42e6
NOISE = NoiseModel(0.002, 0.002, 0.3, 0.3)


def sky(rng, n_sats):
    az = rng.uniform(0, 2 * np.pi, n_sats)
    el = rng.uniform(np.radians(10), np.radians(85), n_sats)
    e = np.c_[np.cos(el) * np.sin(az), np.cos(el) * np.cos(az), np.sin(el)]
    return {f"G{i + 1:02d}": e[i] for i in range(n_sats)}


def observe(rng, los, antennas_enu, N, multipath=None):
    """Plane-wave RINEX-sign observables of every antenna (see gnss/differences.py).

    Noise is white with σ² = a² + b²/sin²(el); with ``multipath`` = (t, period, phase) arrays
    of shape (antennas, sats), the b term is instead a sinusoid of the same variance, i.e.
    correlated over the period (60-300 s) like real multipath.
    """
    ids = list(los)
    e = np.array([los[s] for s in ids])
    sin_el = np.sin(np.arcsin(e[:, 2]))
    out = []
    for a, r in enumerate(antennas_enu):
        if multipath is None:
            u_ph, u_pr = rng.normal(size=(2, len(ids)))
            m_ph = elevation_sigma(np.arcsin(e[:, 2]), NOISE.phase_a, NOISE.phase_b) * u_ph
            m_pr = elevation_sigma(np.arcsin(e[:, 2]), NOISE.code_a, NOISE.code_b) * u_pr
        else:
            t, period, phase = multipath
            wave = np.sqrt(2) / sin_el * np.sin(2 * np.pi * t / period[a] + phase[a])
            m_ph = NOISE.phase_a * rng.normal(size=len(ids)) + NOISE.phase_b * wave
            m_pr = NOISE.code_a * rng.normal(size=len(ids)) + NOISE.code_b * wave
        rho = -e @ r
        ph = (rho + m_ph) / WAVELENGTH + N[a]
        pr = rho + m_pr
        out.append(AntennaEpoch(ids, ph, pr, np.full(len(ids), WAVELENGTH)))
    return out


def double_differences(rng, los, antennas_enu):
    N = rng.integers(-10**6, 10**6, (len(antennas_enu), len(los)))
    obs = observe(rng, los, antennas_enu, N)
    ids = list(los)
    refs = select_references(ids, [np.arcsin(los[s][2]) for s in ids], [WAVELENGTH] * len(ids))
    dd = form_double_differences(obs, los, refs, NOISE)
    col = {s: i for i, s in enumerate(ids)}
    truth = np.array([N[k, col[s]] - N[0, col[s]] - N[k, col[r]] + N[0, col[r]]
                      for k, (s, r) in zip(dd.baseline, dd.pairs)])
    return dd, truth


def bench_lambda(label, n_baselines, epochs=2000, seed=0):
    rng = np.random.default_rng(seed)
    ant = np.array([[0, 0, 0], [1.5, 0, 0], [0.0, -1.0, 0.0]])[:n_baselines + 1]
    problems = []
    for _ in range(epochs):
        dd, truth = double_differences(rng, sky(rng, 10), ant)
        # Joint float solution of all baselines: stack the per-baseline systems' ambiguities.
        fs = [float_solution(dd, k) for k in range(1, n_baselines + 1)]
        a = np.concatenate([f.ambiguities for f in fs])
        Q = np.zeros((a.size, a.size))
        i = 0
        for f in fs:
            n = f.ambiguities.size
            Q[i:i + n, i:i + n] = f.cov[3:, 3:]
            i += n
        problems.append((a, Q, truth))
    integer_least_squares(*problems[0][:2])       # compile / load the numba cache
    partial_fix(*problems[0][:2])
    t_ils, t_pf, correct = [], [], 0
    for a, Q, truth in problems:
        t0 = time.perf_counter()
        res = integer_least_squares(a, Q)
        t1 = time.perf_counter()
        partial_fix(a, Q)
        t2 = time.perf_counter()
        t_ils.append(t1 - t0)
        t_pf.append(t2 - t1)
        correct += np.array_equal(res.best, truth)
    t_ils, t_pf = np.array(t_ils) * 1e3, np.array(t_pf) * 1e3
    print(f"{label:>3} DDs: integer_least_squares median {np.median(t_ils):.3f} ms, "
          f"p95 {np.percentile(t_ils, 95):.3f} ms; partial_fix median {np.median(t_pf):.3f} ms, "
          f"p95 {np.percentile(t_pf, 95):.3f} ms; best = truth in {correct / epochs:.3f} "
          f"of {epochs} epochs (no ratio test, no length constraint)")


def bench_length_constraint(n_sats, epochs=1000, seed=1):
    rng = np.random.default_rng(seed)
    stats = {"length": [0, 0, []], "plain": [0, 0, []]}
    for i in range(epochs):
        R = dcm_from_euler(0.0, 0.0, rng.uniform(-np.pi, np.pi))
        dd, truth = double_differences(rng, sky(rng, n_sats),
                                       np.array([[0, 0, 0], R @ [1.5, 0, 0]]))
        fs = float_solution(dd, 1)
        for key, length in (("length", 1.5), ("plain", None)):
            t0 = time.perf_counter()
            fix = fix_ambiguities(fs, length, 0.002)
            stats[key][2].append(time.perf_counter() - t0)
            if fix is not None and fix.ratio >= 3.0:
                stats[key][0] += 1
                stats[key][1] += not np.array_equal(fix.ambiguities, truth)
    for key, (acc, wrong, t) in stats.items():
        t = np.array(t) * 1e3
        print(f"{n_sats} sats, 1.5 m, single epoch, {key:>6}: accepted {acc / epochs:.3f}, "
              f"wrong among accepted {wrong}/{acc}; fix_ambiguities median {np.median(t):.3f} ms,"
              f" p95 {np.percentile(t, 95):.3f} ms")


def bench_solver(antennas, epochs=600, seed=2):
    rng = np.random.default_rng(seed)
    los = sky(rng, 10)
    N = rng.integers(-10**6, 10**6, (len(antennas), len(los)))
    solver = AttitudeSolver(antennas, noise=NOISE)
    times, fixed, err, var = [], 0, [], []
    for i in range(epochs):
        truth = (0.05 * np.sin(0.3 * i), 0.02 * np.sin(0.2 * i), 0.01 * i)
        R = dcm_from_euler(*truth)
        obs = observe(rng, los, antennas @ R.T, N)
        t0 = time.perf_counter()
        sol = solver.process(obs, los, float(i))
        times.append(time.perf_counter() - t0)
        if sol.status == "FIXED":
            fixed += 1
            err.append([wrap_pi(sol.roll - truth[0]), sol.pitch - truth[1],
                        wrap_pi(sol.azimuth - azimuth_from_yaw(truth[2]))])
            var.append([sol.var_roll, sol.var_pitch, sol.var_azimuth])
    t = np.array(times[1:]) * 1e3
    err, var = np.array(err), np.array(var)
    rms = np.degrees(np.sqrt(np.mean(err ** 2, axis=0)))
    sig = np.degrees(np.sqrt(np.mean(var, axis=0)))
    nees = np.mean(err ** 2 / var, axis=0)
    print(f"AttitudeSolver.process, {len(antennas)} antennas, 10 sats: median {np.median(t):.2f}"
          f" ms, p95 {np.percentile(t, 95):.2f} ms per epoch; FIXED {fixed}/{epochs}")
    for k, name in enumerate(("roll", "pitch", "heading")):
        print(f"    {name:>7}: RMS error {rms[k]:.4f} deg, predicted sigma {sig[k]:.4f} deg, "
              f"mean squared normalised error {nees[k]:.2f}")


def bench_weak(n_sats, ratio, multipath, runs=10, epochs=100, seed=3):
    rng = np.random.default_rng(seed)
    antennas = np.array([[0, 0, 0], [1.5, 0, 0]], float)
    fixed = wrong = 0
    for _ in range(runs):
        az0 = rng.uniform(0, 2 * np.pi, n_sats)
        el0 = rng.uniform(np.radians(15), np.radians(80), n_sats)
        N = rng.integers(-10**6, 10**6, (2, n_sats))
        period = rng.uniform(60, 300, (2, n_sats))
        phase = rng.uniform(0, 2 * np.pi, (2, n_sats))
        solver = AttitudeSolver(antennas, noise=NOISE, ratio_threshold=ratio)
        for i in range(epochs):
            az = az0 + np.radians(0.25) / 60 * 5 * i         # satellites drift 0.25 deg/min
            e = np.c_[np.cos(el0) * np.sin(az), np.cos(el0) * np.cos(az), np.sin(el0)]
            los = {f"G{j + 1:02d}": e[j] for j in range(n_sats)}
            R = dcm_from_euler(0.05 * np.sin(1.5 * i), 0.02 * np.sin(i), 0.02 * i)
            obs = observe(rng, los, antennas @ R.T, N,
                          (5.0 * i, period, phase) if multipath else None)
            sol = solver.process(obs, los, 5.0 * i)
            fixed += sol.status == "FIXED"
            dd = form_double_differences(obs, los, solver.references, NOISE)
            held = solver.store.lookup(dd)
            truth = np.array([N[1, int(s[1:]) - 1] - N[0, int(s[1:]) - 1]
                              - N[1, int(r[1:]) - 1] + N[0, int(r[1:]) - 1] for s, r in dd.pairs])
            ok = np.isfinite(held)
            wrong += bool(np.any(held[ok] != truth[ok]))
    print(f"weak geometry, {n_sats} sats, {'multipath' if multipath else 'white noise'}, "
          f"ratio threshold {ratio}: FIXED {fixed}/{runs * epochs}"
          f", epochs holding a wrong ambiguity {wrong}/{runs * epochs}")


if __name__ == "__main__":
    bench_lambda(9, 1)
    bench_lambda(18, 2)
    for n in (6, 8, 10):
        bench_length_constraint(n)
    bench_solver(np.array([[0, 0, 0], [1.5, 0, 0]], float))
    bench_solver(np.array([[0, 0, 0], [1.5, 0, 0], [0, -1.0, 0], [1.5, -1.0, 0.05]]))
    for multipath in (False, True):
        for n in (6, 7):
            for ratio in (3.0, 5.0):
                bench_weak(n, ratio, multipath)
