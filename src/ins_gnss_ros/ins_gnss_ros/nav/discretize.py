"""Discretisation of a continuous linear stochastic model.

For the continuous error model

    dx/dt = F x + G w ,    E[w(t) w(s)^T] = Qc delta(t - s)

held constant over one step Δt, the equivalent discrete model is

    x_k = Φ_k x_{k-1} + w_k ,   Φ_k = exp(F Δt) ,   E[w_k w_k^T] = Q_k = P(Δt)

where P(τ) solves the Lyapunov equation dP/dτ = F P + P F^T + Q, P(0) = 0, with
Q = G Qc G^T (seed 001, Babich, eqs. 1.1-2.3).

Methods provided:

* Picard series of order ν (Babich eqs. 2.5-2.9): Q_k = Σ_{i=1..ν} M_i Δt^i / i!,
  M_1 = Q, M_{i+1} = F M_i + M_i F^T.  Φ_k is the Taylor series of exp(FΔt) truncated at
  the same order, and the one-step covariance prediction P^- = Φ P Φ^T + Q_k is the
  single recursion K_0 = P, K_1 = F K_0 + K_0 F^T + Q, K_{i+1} = F K_i + K_i F^T
  (Babich eq. 4.5: Ψ_k and Q_k truncated at the SAME order).  ν = 1 is the familiar
  "book" rectangle rule Q_k ≈ G Qc G^T Δt; ν = 2 gives an indefinite Q_k for INS models
  (the position block is zero while its cross-covariance with velocity is not).  ν = 3 and
  4 are PSD at 100 Hz for every grade, but not for a MEMS IMU at Δt >= 0.05-0.1 s: the
  position-attitude cross term of order Δt³ appears before the gyro-noise position variance
  of order Δt⁵, and a MEMS gyro noise q_g g² Δt² exceeds the accelerometer noise q_a
  (docs/results/error_model.md).  The default order is therefore 5.
* The trapezoid rule of Savage, *Strapdown Analytics*, p. 12-74 / Brown & Hwang
  (Babich eq. 3.1): Q_k ≈ ½ (Φ Q Φ^T + Q) Δt with Φ = I + FΔt.
* Van Loan's exact method (C. F. Van Loan, "Computing integrals involving the matrix
  exponential", IEEE TAC 1978): exponential of the block matrix
  [[-F, Q], [0, F^T]] Δt.  Used as the reference.
"""

import numpy as np
from scipy.linalg import expm

# The series run at every filter epoch: compiled (nav/_kernels.py), same results as numpy.
from . import _kernels

#: Default Picard order: the lowest order that keeps Q_k positive semi-definite for the
#: INS error models of every sensor grade up to Δt = 1 s (docs/results/error_model.md).
DEFAULT_ORDER = 5


def picard_transition(F, dt, order=DEFAULT_ORDER):
    """Transition matrix Φ = Σ_{i=0..ν} (F Δt)^i / i! (truncated exp(FΔt)).

    Parameters
    ----------
    F : (n, n) array_like
        System matrix of the continuous model [1/s].
    dt : float
        Step Δt [s].
    order : int
        Series order ν >= 1.

    Returns
    -------
    (n, n) ndarray
    """
    return _kernels.picard_transition(np.ascontiguousarray(F, dtype=float), float(dt),
                                      int(order))


def picard_process_noise(F, Q, dt, order=DEFAULT_ORDER):
    """Discrete process-noise covariance Q_k = P_ν(Δt) by the Picard series (Babich eq. 2.9).

    Parameters
    ----------
    F : (n, n) array_like
        System matrix [1/s].
    Q : (n, n) array_like
        Continuous noise spectral density G Qc G^T [state² / s].
    dt : float
        Step Δt [s].
    order : int
        Series order ν >= 1 (ν = 1 is the rectangle rule Q Δt).

    Returns
    -------
    (n, n) ndarray, symmetric by construction.
    """
    return _lyapunov_series(F, np.zeros_like(np.asarray(Q, dtype=float)), Q, dt, order)


def picard_predict(P, F, Q, dt, order=DEFAULT_ORDER):
    """One-step covariance prediction P^- = Ψ_ν + Q_ν with Ψ and Q of the same order ν.

    Implements the single recursion that follows from Babich eq. (4.5):
    K_0 = P, K_1 = F K_0 + K_0 F^T + Q, K_{i+1} = F K_i + K_i F^T, P^- = Σ K_i Δt^i / i!.

    Parameters
    ----------
    P : (n, n) array_like
        Covariance at the start of the step.
    F, Q, dt, order : as in :func:`picard_process_noise`

    Returns
    -------
    (n, n) ndarray
    """
    return _lyapunov_series(F, P, Q, dt, order)


def _lyapunov_series(F, P0, Q, dt, order):
    """Σ_{i=0..ν} K_i Δt^i / i! for dP/dτ = FP + PF^T + Q, P(0) = P0."""
    F, P0, Q = (np.ascontiguousarray(A, dtype=float) for A in (F, P0, Q))
    return _kernels.lyapunov_series(F, P0, Q, float(dt), int(order))


def book_process_noise(F, Q, dt):
    """Trapezoid rule Q_k ≈ ½ (Φ Q Φ^T + Q) Δt, Φ = I + FΔt (Savage; Babich eq. 3.1).

    Second order in Δt except for the term F Q F^T Δt³/2 (which makes its position block
    half the exact value, Babich §3).

    Parameters
    ----------
    F, Q, dt : as in :func:`picard_process_noise`

    Returns
    -------
    (n, n) ndarray
    """
    F = np.asarray(F, dtype=float)
    phi = np.eye(F.shape[0]) + F * dt
    return 0.5 * (phi @ Q @ phi.T + Q) * dt


def van_loan(F, Q, dt):
    """Exact Φ_k = exp(FΔt) and Q_k = ∫_0^Δt e^{Fs} Q e^{F^T s} ds (Van Loan 1978).

    Parameters
    ----------
    F, Q, dt : as in :func:`picard_process_noise`

    Returns
    -------
    phi : (n, n) ndarray
    Qk : (n, n) ndarray
    """
    F = np.asarray(F, dtype=float)
    n = F.shape[0]
    A = np.zeros((2 * n, 2 * n))
    A[:n, :n] = -F
    A[:n, n:] = Q
    A[n:, n:] = F.T
    B = expm(A * dt)
    phi = B[n:, n:].T
    Qk = phi @ B[:n, n:]
    return phi, 0.5 * (Qk + Qk.T)


def discretize(F, G, Qc, dt, order=DEFAULT_ORDER, method="picard"):
    """Discrete (Φ_k, Q_k) of dx/dt = F x + G w, E[w w^T] = Qc δ, over one step.

    Parameters
    ----------
    F : (n, n) array_like
        System matrix [1/s].
    G : (n, m) array_like
        Noise input matrix.
    Qc : (m, m) array_like
        Spectral density of w [unit² · s].
    dt : float
        Step [s].
    order : int
        Picard order ν (ignored by "van_loan").
    method : {"picard", "van_loan"}

    Returns
    -------
    phi : (n, n) ndarray
    Qk : (n, n) ndarray
    """
    G = np.asarray(G, dtype=float)
    Q = G @ np.asarray(Qc, dtype=float) @ G.T
    if method == "picard":
        return picard_transition(F, dt, order), picard_process_noise(F, Q, dt, order)
    if method == "van_loan":
        return van_loan(F, Q, dt)
    raise ValueError(f"unknown discretisation method {method!r}")


def psd_margin(Q):
    """Smallest eigenvalue of the correlation-scaled covariance (dimensionless).

    Scaling by the standard deviations makes the test independent of the states' units
    (a clock block in m² must not hide an indefinite attitude block in rad²).  A PSD matrix
    gives a value >= -(round-off); a state with zero variance but non-zero covariance (Picard
    ν = 2 position block) cannot be PSD and gives -inf.

    Parameters
    ----------
    Q : (n, n) array_like, symmetric

    Returns
    -------
    float
    """
    Q = np.asarray(Q, dtype=float)
    d = np.diag(Q)
    live = d > 0.0
    if np.any(d < 0.0) or np.any(Q[~live] != 0.0):
        return -np.inf
    s = np.sqrt(d[live])
    return float(np.linalg.eigvalsh(Q[np.ix_(live, live)] / np.outer(s, s))[0])
