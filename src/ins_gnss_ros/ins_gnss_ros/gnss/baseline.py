"""Baseline estimation from double differences: float, length-constrained fix, fixed, held.

Model of one baseline b (ENU, m) at one epoch (see :mod:`.differences`):

    DD phase (cycles)  φ_j = g_jᵀ b / λ_j + N_j,      DD code (m)  P_j = g_jᵀ b,

with g_j = -(e_j - e_ref). The float solution estimates b and the unknown N by weighted least
squares (Groves §10.2.4; Teunissen 1995 for the float/fixed split); ambiguities already held
from earlier epochs are moved to the observation side. The fixed solution is the conditional
estimate b̌ = b̂ - Q_b̂â Q_â⁻¹ (â - ǎ).

A known baseline length L (a rigid antenna bracket, e.g. ISON-1's 1.5 m, extract_004 §1.3b)
is used the way the constrained LAMBDA of Teunissen (2010, "Integer least-squares theory for
the GNSS compass", J. Geod. 84) does: each integer candidate z is scored by

    F(z) = ||â - z||²_Q_â  +  min_{|b| = L} ||b̌(z) - b||²_Q_b̌|â,

and candidates are enumerated by increasing ||â - z||² until that alone exceeds the second
best F found, so the two best F are exact. A wrong candidate gives a baseline of wrong length
and orientation and pays a large second term: this is what makes single-epoch,
single-frequency fixing on a short baseline reliable.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.linalg import cho_factor, cho_solve
from scipy.stats import chi2

from .differences import DoubleDifferences
from .lambda_search import enumerate_ellipsoid, integer_least_squares


@dataclass
class FloatSolution:
    """Float solution of one baseline at the current epoch.

    Attributes
    ----------
    baseline : ndarray, shape (3,)
        b̂, ENU (m).
    ambiguities : ndarray, shape (n,)
        â of the free rows (cycles).
    cov : ndarray, shape (3 + n, 3 + n)
        Joint covariance of [b̂, â] (m², m·cycles, cycles²).
    rows : ndarray of int, shape (n,)
        DD rows (in the epoch's DoubleDifferences) of the free ambiguities.
    """

    baseline: np.ndarray
    ambiguities: np.ndarray
    cov: np.ndarray
    rows: np.ndarray


def _epoch_normals(dd: DoubleDifferences, k, known, free, use_code, prior=None):
    """Normal equations of one epoch of baseline k for the unknowns [b (3), N_free].

    ``known`` maps row keys to held ambiguities, ``free`` maps row keys to the column of their
    unknown ambiguity; rows in neither are left out.
    """
    n = len(free)
    rows = [j for j in dd.rows(k) if dd.key(j) in free or dd.key(j) in known]
    rows = np.array(rows, int)
    lam = dd.wavelength[rows]
    # Phase rows: [G/λ | selection of the free ambiguity], held ones moved to the left side.
    A_ph = np.zeros((rows.size, 3 + n))
    A_ph[:, :3] = dd.geometry[rows] / lam[:, None]
    y_ph = dd.phase[rows].copy()
    for i, j in enumerate(rows):
        key = dd.key(j)
        if key in free:
            A_ph[i, 3 + free[key]] = 1.0
        else:
            y_ph[i] -= known[key]
    blocks = [(A_ph, y_ph, dd.cov_phase[np.ix_(rows, rows)])]
    if use_code:
        ok = rows[np.isfinite(dd.code[rows])]
        if ok.size:
            A_pr = np.zeros((ok.size, 3 + n))
            A_pr[:, :3] = dd.geometry[ok]
            blocks.append((A_pr, dd.code[ok], dd.cov_code[np.ix_(ok, ok)]))
    if prior is not None:
        H = np.atleast_2d(np.asarray(prior[0], float))
        A_pb = np.zeros((H.shape[0], 3 + n))
        A_pb[:, :3] = H
        blocks.append((A_pb, np.atleast_1d(np.asarray(prior[1], float)),
                       np.atleast_2d(np.asarray(prior[2], float))))
    Nmat = np.zeros((3 + n, 3 + n))
    rhs = np.zeros(3 + n)
    for A, y, C in blocks:
        Ci = cho_factor(C)
        Nmat += A.T @ cho_solve(Ci, A)
        rhs += A.T @ cho_solve(Ci, y)
    return Nmat, rhs


def float_solution(dd: DoubleDifferences, k: int, held=None, prior=None, use_code=True,
                   history=()):
    """Weighted least-squares float solution of baseline k, over one or several epochs.

    Parameters
    ----------
    dd : DoubleDifferences
        The current epoch.
    k : int
        Remote antenna index of the baseline.
    held : ndarray, shape (len(dd.phase),), optional
        Known DD ambiguities per row (cycles), NaN where unknown.
    prior : (ndarray (m, 3), ndarray (m,), ndarray (m, m)), optional
        A-priori observation y = H b + e, e ~ N(0, C), of the current baseline (H, y in m, C in
        m²): e.g. the INS attitude applied to the body-frame baseline (H = I), or only its up
        component from the INS roll and pitch (H = [0, 0, 1]). Its information Hᵀ C⁻¹ H enters
        the normal equations and none along directions H does not see, so an unknown heading
        needs no large variance. It shrinks the ambiguity search space.
    use_code : bool
        Use the DD pseudoranges.
    history : sequence of DoubleDifferences
        Earlier epochs without slips since. Their rows with the same (baseline, signal,
        reference) share the current unknown ambiguities; each epoch has its own baseline,
        eliminated from the normal equations (Schur complement), so a moving platform needs no
        motion model. Accumulating epochs averages the code noise and adds geometry change.

    Returns
    -------
    FloatSolution or None
        For the current epoch's baseline; None if it is not observable.
    """
    rows = dd.rows(k)
    if held is None:
        held = np.full(dd.phase.size, np.nan)
    known = {dd.key(j): held[j] for j in rows if np.isfinite(held[j])}
    free_rows = np.array([j for j in rows if not np.isfinite(held[j])], int)
    free = {dd.key(j): i for i, j in enumerate(free_rows)}
    Nmat, rhs = _epoch_normals(dd, k, known, free, use_code, prior)
    for past in history:
        Np, rp = _epoch_normals(past, k, known, free, use_code)
        try:
            Nbb = cho_factor(Np[:3, :3])
        except np.linalg.LinAlgError:
            continue
        # Eliminate that epoch's baseline: N_aa - N_ab N_bb⁻¹ N_ba, r_a - N_ab N_bb⁻¹ r_b.
        Nmat[3:, 3:] += Np[3:, 3:] - Np[3:, :3] @ cho_solve(Nbb, Np[:3, 3:])
        rhs[3:] += rp[3:] - Np[3:, :3] @ cho_solve(Nbb, rp[:3])
    n = free_rows.size
    try:
        Nc = cho_factor(Nmat)
    except np.linalg.LinAlgError:
        return None
    x = cho_solve(Nc, rhs)
    return FloatSolution(x[:3], x[3:], cho_solve(Nc, np.eye(3 + n)), free_rows)


def closest_point_on_sphere(center, W, radius):
    """Minimiser of (b - c)ᵀ W (b - c) subject to |b| = radius, and the minimum.

    Stationarity gives (W - μI) b = W c; the global minimiser has μ below the smallest
    eigenvalue w₀ of W (the trust-region argument of Moré & Sorensen 1983, "Computing a trust
    region step"), where |b(μ)| grows monotonically from 0 to ∞, so μ is bracketed and found by
    bisection, for a whole stack of problems at once.

    Parameters
    ----------
    center : ndarray, shape (..., 3)
    W : ndarray, shape (..., 3, 3)
        Symmetric positive definite weights.
    radius : float

    Returns
    -------
    b : ndarray, shape (..., 3)
    cost : ndarray, shape (...)
    """
    center = np.asarray(center, float)
    w, V = np.linalg.eigh(W)
    wc = w * np.einsum("...ji,...j->...i", V, center)
    w0 = w[..., :1]
    # |b(μ)| <= |wc| / (w₀ - μ) gives lo with |b(lo)| <= radius/2; the weakest axis alone
    # gives |b(hi)| >= radius.
    lo = w0 - 2.0 * np.linalg.norm(wc, axis=-1, keepdims=True) / radius
    hi = w0 - np.abs(wc[..., :1]) / radius
    for _ in range(8):
        mid = 0.5 * (lo + hi)
        short = (wc * wc / (w - mid) ** 2).sum(-1, keepdims=True) < radius ** 2
        lo = np.where(short, mid, lo)
        hi = np.where(short, hi, mid)
    mu = 0.5 * (lo + hi)
    for _ in range(6):
        # Newton on φ(μ) = 1/r - 1/|b(μ)|, nearly linear in μ (Moré & Sorensen), inside the
        # bracket; dφ/dμ = Σ wc²/(w - μ)³ / |b|³.
        q2 = wc * wc / (w - mu) ** 2
        nb2 = q2.sum(-1, keepdims=True)
        dphi = (q2 / (w - mu)).sum(-1, keepdims=True) / nb2 ** 1.5
        mu = np.clip(mu - (1.0 / radius - 1.0 / np.sqrt(nb2)) / dphi, lo, hi)
    b = np.einsum("...ij,...j->...i", V, wc / (w - mu))
    # "Hard case" (centre orthogonal to the weakest axis): the radial projection.
    hard = (np.abs(wc[..., 0]) <= 1e-12 * np.linalg.norm(wc, axis=-1))[..., None]
    b = np.where(hard, radius * center / np.linalg.norm(center, axis=-1, keepdims=True), b)
    b *= radius / np.linalg.norm(b, axis=-1, keepdims=True)
    r = b - center
    return b, np.einsum("...i,...ij,...j->...", r, W, r)


@dataclass
class FixResult:
    """Integer solution of the free ambiguities of one baseline.

    Attributes
    ----------
    ambiguities : ndarray of int64, shape (n,)
    baseline : ndarray, shape (3,)
        Conditional (fixed) baseline b̌ (ENU, m), not forced onto the sphere.
    ratio : float
        Second-best over best score (F with the length constraint, else ||â - z||²); a lower
        bound when it exceeds ``enough_ratio`` (see ``fix_ambiguities``).
    score : float
        Best score.
    n_candidates : int
        Candidates scored.
    """

    ambiguities: np.ndarray
    baseline: np.ndarray
    ratio: float
    score: float
    n_candidates: int


def fix_ambiguities(fs: FloatSolution, length=None, sigma_length=0.0, enough_ratio=10.0,
                    n_start=16, n_max=20_000):
    """Integer ambiguities of a float solution, optionally with the known baseline length.

    With a length, F(z) >= ||â - z||² (the search-and-shrink argument of Teunissen 2010): the
    ``n_start`` nearest candidates give a best score F₁ and a runner-up F₂ as upper bounds, so
    every candidate that can beat them lies inside ||â - z||² < χ² = min(F₂, enough_ratio·F₁).
    Ellipsoids of doubling radius are enumerated and scored until the radius reaches χ² (which
    shrinks as better candidates are scored). Candidates outside have F >= χ², so the best is
    exact, and the ratio is exact or (when χ² was capped) a lower bound >= ``enough_ratio``.

    Parameters
    ----------
    fs : FloatSolution
    length : float, optional
        Known baseline length L (m).
    sigma_length : float
        Its uncertainty (m), added to the radial variance of the conditional baseline.
    enough_ratio : float
        Ratio beyond which the exact runner-up is not needed (>= the ratio-test threshold).
    n_start : int
        Candidates of the first search.
    n_max : int
        Largest number of candidates enumerated inside χ².

    Returns
    -------
    FixResult or None
        None if more than ``n_max`` candidates had to be enumerated.
    """
    n = fs.ambiguities.size
    a_hat, Qaa = fs.ambiguities, fs.cov[3:, 3:]
    Qba = fs.cov[:3, 3:]
    K = Qba @ cho_solve(cho_factor(Qaa), np.eye(n))   # b̌(z) = b̂ - K (â - z)
    Q_cond = fs.cov[:3, :3] - K @ Qba.T                 # Q_b̌|â
    if length is None:
        res = integer_least_squares(a_hat, Qaa, 2)
        b = fs.baseline - (a_hat - res.best) @ K.T
        return FixResult(res.best, b, res.ratio, float(res.sqnorms[0]), 2)
    w_min = 1.0 / (np.linalg.eigvalsh(Q_cond)[-1] + sigma_length ** 2)

    def scores(cands, sqnorms):
        """F per candidate; +inf for those proven not to be among the best two."""
        b_z = fs.baseline - (a_hat - cands) @ K.T
        norm = np.linalg.norm(b_z, axis=1, keepdims=True)
        u = b_z / norm
        W = np.linalg.inv(Q_cond + sigma_length ** 2 * np.einsum("ki,kj->kij", u, u))
        # The radial projection is a feasible point (upper bound of F); the weighted distance
        # to the sphere is >= Euclidean distance² times the smallest weight (lower bound).
        dr = (length - norm) * u
        upper = sqnorms + np.einsum("ki,kij,kj->k", dr, W, dr)
        lower = sqnorms + w_min * (norm[:, 0] - length) ** 2
        F = np.full(len(cands), np.inf)
        need = lower <= np.sort(upper)[min(1, len(upper) - 1)]
        F[need] = sqnorms[need] + closest_point_on_sphere(b_z[need], W[need], length)[1]
        return F, b_z

    res = integer_least_squares(a_hat, Qaa, n_start)
    cands, sq = res.candidates, res.sqnorms
    radius = sq[-1]       # every candidate with ||â - z||² < radius has been scored
    while True:
        F, b_z = scores(cands, sq)
        F1, F2 = np.sort(F)[:2]
        chi2_max = min(F2, enough_ratio * F1)
        if radius >= chi2_max:
            break
        # Grow the ellipsoid gradually: the bounds F₁, F₂ usually tighten on the way.
        radius = min(chi2_max, 2.0 * radius)
        cands, sq, complete = enumerate_ellipsoid(a_hat, Qaa, radius, n_max)
        if not complete:
            return None
    best = int(np.argmin(F))
    second = min(F2, chi2_max)
    ratio = np.inf if F[best] <= 0 else second / F[best]
    return FixResult(cands[best], b_z[best], float(ratio), float(F[best]), len(cands))


@dataclass
class FixedBaselines:
    """Baselines from DD phase with all ambiguities known.

    Attributes
    ----------
    baselines : ndarray, shape (K, 3)
        ENU (m), one per remote antenna 1 … K.
    cov : ndarray, shape (3K, 3K)
        Joint covariance (m²), correlated through the master antenna.
    chi2 : float
        Weighted sum of squared phase residuals.
    dof : int
        Its degrees of freedom.
    cov_correlated : ndarray, shape (3K, 3K), or None
        Covariance the time-correlated phase errors (``dd.cov_correlated``) add to ``cov``
        (m²); None when not modelled.
    """

    baselines: np.ndarray
    cov: np.ndarray
    chi2: float
    dof: int
    cov_correlated: np.ndarray | None = None

    def consistent(self, alpha=1e-3) -> bool:
        """Residual χ² test at false-alarm probability alpha (a wrong fix fails it)."""
        return self.dof <= 0 or self.chi2 <= chi2.ppf(1 - alpha, self.dof)


def fixed_baselines(dd: DoubleDifferences, ambiguities, n_baselines: int):
    """Joint weighted least squares of all baselines from DD phase with known ambiguities.

    Parameters
    ----------
    dd : DoubleDifferences
    ambiguities : ndarray, shape (len(dd.phase),)
        DD ambiguity per row (cycles); rows with NaN are left out.
    n_baselines : int
        Number of remote antennas K.

    Returns
    -------
    FixedBaselines or None
        None if a baseline has fewer than 3 fixed rows. The weights are ``dd.cov_phase``; the
        correlated errors ``dd.cov_correlated``, if any, are propagated through the same
        estimator, x̂ = P Aᵀ C⁻¹ y: P Aᵀ C⁻¹ C_c C⁻¹ A P.
    """
    use = np.flatnonzero(np.isfinite(ambiguities))
    A = np.zeros((use.size, 3 * n_baselines))
    for r, j in enumerate(use):
        k = dd.baseline[j] - 1
        A[r, 3 * k:3 * k + 3] = dd.geometry[j] / dd.wavelength[j]
    per_baseline = np.bincount(dd.baseline[use], minlength=n_baselines + 1)[1:]
    if np.any(per_baseline < 3):
        return None
    y = dd.phase[use] - ambiguities[use]
    Cc = cho_factor(dd.cov_phase[np.ix_(use, use)])
    CiA = cho_solve(Cc, A)
    Nmat = A.T @ CiA
    try:
        P = np.linalg.inv(Nmat)
    except np.linalg.LinAlgError:
        return None
    x = P @ (CiA.T @ y)
    r = y - A @ x
    cov_correlated = None
    if dd.cov_correlated is not None:
        gain = P @ CiA.T
        cov_correlated = gain @ dd.cov_correlated[np.ix_(use, use)] @ gain.T
    return FixedBaselines(x.reshape(n_baselines, 3), P, float(r @ cho_solve(Cc, r)),
                          use.size - 3 * n_baselines, cov_correlated)


class AmbiguityStore:
    """DD ambiguities held across epochs, keyed by (baseline, signal, reference).

    A slip of signal s invalidates the entries of s. When a group's reference changes from o to
    n and N(n, o) is held, every N(i, o) becomes N(i, n) = N(i, o) - N(n, o): the ambiguity of o
    cancels, so this stays valid even when o itself slipped or set.
    """

    def __init__(self):
        self._n: dict = {}

    def __len__(self):
        return len(self._n)

    def lookup(self, dd: DoubleDifferences) -> np.ndarray:
        """Held ambiguity per DD row (cycles), NaN where unknown."""
        return np.array([self._n.get(dd.key(j), np.nan) for j in range(dd.phase.size)])

    def hold(self, dd: DoubleDifferences, rows, values):
        """Hold integer ``values`` for the DD ``rows``."""
        for j, v in zip(rows, values):
            self._n[dd.key(int(j))] = int(v)

    def forget(self, signals=None):
        """Drop the entries whose signal (not reference) is in ``signals``, or all if None."""
        if signals is None:
            self._n.clear()
            return
        self._n = {key: v for key, v in self._n.items() if key[1] not in signals}

    def retain(self, signals):
        """Keep only the entries whose signal and reference are both in ``signals`` (drop
        signals that stopped being tracked: their ambiguity is not trusted on return)."""
        self._n = {key: v for key, v in self._n.items()
                   if key[1] in signals and key[2] in signals}

    def known_signals(self, reference) -> set:
        """Signals with a held ambiguity against ``reference`` (on any baseline)."""
        return {key[1] for key in self._n if key[2] == reference}

    def rereference(self, old: str, new: str, keep_old=True):
        """Move the entries referenced to ``old`` onto ``new`` (see the class docstring).

        ``keep_old`` creates N(old, new) = -N(new, old); pass False when old slipped.
        """
        moved = {}
        for key, v in self._n.items():
            b, s, r = key
            if r != old:
                continue
            base = self._n.get((b, new, old))
            if base is None:
                continue
            if s != new:
                moved[(b, s, new)] = v - base
            elif keep_old:
                moved[(b, old, new)] = -v
        self._n = {key: v for key, v in self._n.items() if key[2] != old}
        self._n.update(moved)
