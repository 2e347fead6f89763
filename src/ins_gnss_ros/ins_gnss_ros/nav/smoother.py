"""Rauch-Tung-Striebel fixed-interval smoother over a stored forward pass (error-state form).

Post-processing ("камеральная обработка") mode of the seeds: after the trial, the forward pass of
:class:`~ins_gnss_ros.nav.navigator.Navigator` is run backwards (H. E. Rauch, F. Tung and
C. T. Striebel, "Maximum likelihood estimates of linear dynamic systems", AIAA J. 3(8), 1965;
Groves, "Principles of GNSS, Inertial and Multisensor Integrated Navigation", 2nd ed.,
section 3.4.2).

Closed-loop form. At each epoch k the forward filter stores its corrected solution, the
covariance P_k after the updates, the prediction P-_(k+1) and transition Phi_(k+1), and the
correction dx_(k+1) fed back at epoch k+1. Relative to the corrected solution the forward
estimate is zero, and the predicted error relative to the uncorrected solution at k+1 is zero,
so with e_k the smoothed error of the corrected solution at k (computed minus true, ekf.py):

    e_N = 0,   e_k = A_k (e_(k+1) + dx_(k+1)),   A_k = P_k Phi_(k+1)^T (P-_(k+1))^-1
    Ps_k = P_k + A_k (Ps_(k+1) - P-_(k+1)) A_k^T

(dx_(k+1) turns the error of the corrected solution at k+1 back into that of the uncorrected
one, which is what the prediction refers to). The smoothed solution is the forward one with e_k
removed by :func:`~ins_gnss_ros.nav.strapdown.apply_correction`.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .modes import ALIGNING
from .strapdown import apply_correction
from .track import Track


@dataclass
class SmoothedOutput(Track):
    """Smoothed solution at the epochs of the forward pass.

    Attributes
    ----------
    t, lat, lon, h : (k,)
    v_enu : (k, 3)
    q_nb : (k, 4)
    P : (k, n, n)
        Smoothed covariance.
    estimates : dict of str to (k, size)
        Smoothed sensor / clock / extra estimates.
    """

    P: np.ndarray
    estimates: dict


def rts_smooth(out):
    """RTS smoothing of a forward pass.

    Epochs before the heading alignment (mode ALIGNING) are returned unchanged: the alignment
    rotates the solution outside the linear model, so the smoother does not cross it.

    Parameters
    ----------
    out : NavigatorOutput
        Forward pass recorded with ``store_covariance=True``.

    Returns
    -------
    SmoothedOutput
    """
    if out.P is None:
        raise ValueError("the forward pass was run without store_covariance")
    n_ep = len(out.t)
    aligning = np.flatnonzero(out.mode == ALIGNING)
    start = aligning[-1] + 1 if len(aligning) else 0
    e = np.zeros((n_ep, out.space.size))
    Ps = out.P.copy()
    for k in range(n_ep - 2, start - 1, -1):
        Pp = out.P_prior[k + 1]
        # A = P Phi^T Pp^-1, through a solve with the symmetric Pp.
        try:
            A = np.linalg.solve(Pp, out.phi[k + 1] @ out.P[k]).T
        except np.linalg.LinAlgError:
            A = out.P[k] @ out.phi[k + 1].T @ np.linalg.pinv(Pp)
        e[k] = A @ (e[k + 1] + out.dx[k + 1])
        Ps[k] = out.P[k] + A @ (Ps[k + 1] - Pp) @ A.T
    S = out.space
    lat, lon, h = out.lat.copy(), out.lon.copy(), out.h.copy()
    v, q = out.v_enu.copy(), out.q_nb.copy()
    for k in range(start, n_ep):
        st = apply_correction(out.state(k), e[k, S["pos"]], e[k, S["vel"]], e[k, S["att"]])
        lat[k], lon[k], h[k], v[k], q[k] = st.lat, st.lon, st.h, st.v_enu, st.q_nb
    est = {name: values + e[:, S[name]] for name, values in out.estimates.items()}
    return SmoothedOutput(out.t.copy(), lat, lon, h, v, q, Ps, est)
