"""Innovation gating: chi-square test of each measurement before it updates the filter.

For a consistent filter the innovation nu = z - H x of an m-dimensional measurement is zero-mean
Gaussian with covariance S = H P H^T + R, so the normalised innovation squared
NIS = nu^T S^-1 nu is chi-square with m degrees of freedom (Bar-Shalom, Li and Kirubarajan,
"Estimation with Applications to Tracking and Navigation", section 5.4). A measurement whose NIS
exceeds the `gate_prob` quantile of that distribution is rejected as anomalous.

This is the memoryless ("безынерционный") innovation test of seed 004 section 2.10 item 2
(residual against k_z sigma of the covariance channel), generalised from per-component
k_z sigma to the joint chi-square of the whole measurement vector, and the anomalous-measurement
rejection of seed 000 (Dishel) section A2.10.
"""
from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache

import numpy as np
from scipy.stats import chi2

#: Default probability of the gate: a consistent filter rejects 1 in 10,000 clean measurements.
DEFAULT_GATE_PROB = 0.9999


@dataclass(frozen=True)
class UpdateResult:
    """Outcome of one measurement update (what ``nav/status`` reports).

    Attributes
    ----------
    name : str
        Measurement kind ("gnss_pos", "gnss_vel", "heading", ...).
    t : float
        Epoch the measurement refers to, s.
    innovation : ndarray, shape (m,)
        z - H x, in the measurement's units.
    s_diag : ndarray, shape (m,)
        Diagonal of the innovation covariance S = H P H^T + R.
    nis : float
        Normalised innovation squared nu^T S^-1 nu (dimensionless).
    gate : float
        Chi-square threshold the NIS was compared with (inf when gating is off).
    accepted : bool
        True if the measurement updated the filter.
    reason : str
        "ok", "gated", "forced", or the reason a caller rejected it before the test.
    """

    name: str
    t: float
    innovation: np.ndarray
    s_diag: np.ndarray
    nis: float
    gate: float
    accepted: bool
    reason: str


@lru_cache(maxsize=256)
def chi2_gate(dof: int, prob: float = DEFAULT_GATE_PROB) -> float:
    """Chi-square quantile: the NIS threshold for `dof` degrees of freedom at `prob`."""
    return float(chi2.ppf(prob, dof))


def normalised_innovation(innovation, S) -> float:
    """NIS = nu^T S^-1 nu, computed through a Cholesky factor of S (S must be positive definite)."""
    L = np.linalg.cholesky(S)
    w = np.linalg.solve(L, innovation)
    return float(w @ w)


def rejected(name: str, t: float, innovation, S, reason: str) -> UpdateResult:
    """UpdateResult of a measurement refused before (or without) the chi-square test."""
    innovation = np.asarray(innovation, float)
    return UpdateResult(name, float(t), innovation, np.diag(S).copy(), np.nan, np.inf, False,
                        reason)
