"""Cycle-slip detection for single-frequency carrier phase on short baselines.

Two independent tests, both on data of consecutive epochs t-1, t:

1. Phase against integrated Doppler, per antenna and signal (Groves §9.4.1.5 "Doppler
   integration"). With the RINEX signs (phase grows with range, Doppler positive when the
   satellite approaches) dφ/dt = -f_D, so

       r = φ(t) - φ(t-1) + (f_D(t-1) + f_D(t)) Δt / 2        (cycles)

   is noise plus the slip. Receiver clock drift is in both phase and Doppler and cancels; a
   receiver clock jump (millisecond steering) is common to all signals of the antenna and is
   removed by subtracting the median residual. The trapezoid rule leaves a jerk error
   ~ (d³ρ/dt³) Δt³ / 12 / λ, negligible at 1-10 Hz for vehicles.
2. Time-differenced double differences (per baseline, no ambiguity): with g = -(e_i - e_ref),

       λ (DD(t) - DD(t-1)) - (g(t) - g(t-1)) · b(t-1) = g(t) · Δb + λ ΔN + noise,

   Δb = b(t) - b(t-1) unknown. The error of b(t-1) enters only through the line-of-sight change
   g(t) - g(t-1) (about 1e-4 per second), so a float b(t-1) is good enough. Slips are found by
   Baarda's w-test on the least-squares residuals, removing the worst row until none exceeds the
   critical value; this needs at least 5 DDs (1 redundancy to detect, 2 to identify).

A geometry-free test (phase minus code, or the ionosphere-free/wide-lane combinations) needs two
frequencies; with single-frequency phase, phase minus code is limited by code noise (~0.3-1 m,
several cycles) and is not used. A slip of the reference signal shifts every DD of its group
alike: test 1 catches it per signal; test 2 then flags several rows of the group.
"""
from __future__ import annotations

import numpy as np
from scipy.linalg import cho_factor, cho_solve

from .differences import AntennaEpoch, DoubleDifferences


def doppler_phase_residual(phase_prev, phase_curr, doppler_prev, doppler_curr, dt):
    """Phase change minus the change predicted by trapezoid-integrated Doppler (cycles).

    Parameters
    ----------
    phase_prev, phase_curr : array_like
        Carrier phase at t-1 and t (cycles).
    doppler_prev, doppler_curr : array_like
        Doppler at t-1 and t (Hz, RINEX sign).
    dt : float
        t - (t-1) (s).
    """
    return (np.asarray(phase_curr) - np.asarray(phase_prev)
            + 0.5 * (np.asarray(doppler_prev) + np.asarray(doppler_curr)) * dt)


def detect_slips_doppler(prev: AntennaEpoch, curr: AntennaEpoch, dt, threshold=1.0) -> set:
    """Signals of one antenna that slipped between two epochs (test 1 of the module).

    Parameters
    ----------
    prev, curr : AntennaEpoch
        Consecutive epochs of the same antenna, with Doppler.
    dt : float
        Epoch interval (s).
    threshold : float
        Detection threshold on the clock-corrected residual (cycles). Doppler noise σ_D gives a
        residual σ ≈ σ_D Δt / √2; keep the threshold several times above it.

    Returns
    -------
    set of str
        Slipped signals, plus those with the loss-of-lock flag set at ``curr``.
    """
    slipped = set()
    if curr.loss_of_lock is not None:
        slipped |= {s for s, f in zip(curr.signal_ids, curr.loss_of_lock) if f}
    if prev.doppler is None or curr.doppler is None:
        return slipped
    ip = prev.index()
    ids, res = [], []
    for j, s in enumerate(curr.signal_ids):
        i = ip.get(s)
        if i is None:
            continue
        r = doppler_phase_residual(prev.phase[i], curr.phase[j], prev.doppler[i],
                                   curr.doppler[j], dt)
        if np.isfinite(r):
            ids.append(s)
            res.append(r)
    res = np.asarray(res)
    if res.size >= 3:
        res = res - np.median(res)
    return slipped | {s for s, r in zip(ids, res) if abs(r) > threshold}


def detect_slips_dd(prev: DoubleDifferences, curr: DoubleDifferences, baselines_prev,
                    k_crit=4.0) -> set:
    """Signals whose DD phase jumped between two epochs (test 2 of the module).

    Parameters
    ----------
    prev, curr : DoubleDifferences
        Consecutive epochs. Rows are matched by (baseline, signal, reference).
    baselines_prev : ndarray, shape (K, 3)
        Baselines at t-1 (ENU, m), fixed or float.
    k_crit : float
        Critical value of the w-test (standard normal under no slip).

    Returns
    -------
    set of str
        Signals of the rejected rows.
    """
    index_prev = {prev.key(j): j for j in range(prev.phase.size)}
    slipped = set()
    for k in np.unique(curr.baseline):
        rows_c, rows_p = [], []
        for j in curr.rows(k):
            jp = index_prev.get(curr.key(j))
            if jp is not None:
                rows_c.append(j)
                rows_p.append(jp)
        rows_c, rows_p = np.array(rows_c, int), np.array(rows_p, int)
        lam = curr.wavelength[rows_c]
        y = (lam * (curr.phase[rows_c] - prev.phase[rows_p])
             - (curr.geometry[rows_c] - prev.geometry[rows_p]) @ baselines_prev[k - 1])
        A = curr.geometry[rows_c]
        C = (lam[:, None] * lam[None, :]
             * (curr.cov_phase[np.ix_(rows_c, rows_c)] + prev.cov_phase[np.ix_(rows_p, rows_p)]))
        keep = np.ones(rows_c.size, bool)
        while keep.sum() >= 5:
            idx = np.flatnonzero(keep)
            w = _w_statistics(A[idx], y[idx], C[np.ix_(idx, idx)])
            worst = np.argmax(np.abs(w))
            if abs(w[worst]) <= k_crit:
                break
            keep[idx[worst]] = False
            slipped.add(curr.pairs[rows_c[idx[worst]]][0])
    return slipped


def _w_statistics(A, y, C):
    """Baarda's w-test statistics of every observation of the model y = A x + e, e ~ N(0, C)."""
    Cc = cho_factor(C)
    CiA = cho_solve(Cc, A)
    Nx = A.T @ CiA
    x = np.linalg.solve(Nx, CiA.T @ y)
    r = y - A @ x
    Cir = cho_solve(Cc, r)
    # Covariance of C⁻¹ r is C⁻¹ - C⁻¹ A N⁻¹ Aᵀ C⁻¹; its diagonal normalises each statistic.
    Ci = cho_solve(Cc, np.eye(y.size))
    var = np.diag(Ci) - np.einsum("ij,ij->i", CiA, np.linalg.solve(Nx, CiA.T).T)
    return Cir / np.sqrt(np.maximum(var, 1e-300))
