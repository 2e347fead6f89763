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

Between the epochs (the filter's covariance interval, 0.1 s by default) :func:`imu_rate_track`
gives a solution at every IMU sample from the increments: each interval is mechanised from the
smoothed state of its first epoch, and the closure to the smoothed state of the next is removed
in proportion to the time elapsed (the usual way post-processors densify a smoothed solution).
The forward pass has its own states at the samples (the navigator's record,
:class:`~ins_gnss_ros.nav.recording.SampleTrack`): :func:`sample_rate_track` gives them with
their rates.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .increments import SensorErrors
from .modes import ALIGNING
from .rotations import quat_conj, quat_from_rotvec, quat_mul, quat_to_rotvec
from .strapdown import apply_correction, run
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


@dataclass
class ImuRateTrack(Track):
    """A solution at the IMU samples (:func:`imu_rate_track`).

    Attributes
    ----------
    omega_b : (k, 3) rad/s
        Compensated body rate of each sample (for velocities at a lever arm).
    """

    omega_b: np.ndarray


def imu_rate_track(track, estimates, t, dtheta, dv):
    """The solution of `track` at the IMU samples between its first and last epoch.

    Each interval (t_k, t_(k+1)] is mechanised from epoch k's state with its sensor errors
    (``estimates`` at k, the model of :class:`~ins_gnss_ros.nav.increments.SensorErrors`); the
    closure x_mech(t_(k+1)) - x(t_(k+1)) in position, velocity and attitude is removed in the
    fraction (t - t_k) / (t_(k+1) - t_k), so the result is continuous and meets every epoch.

    Parameters
    ----------
    track : Track
        Solution at epochs (forward or smoothed pass) whose times are IMU sample times.
    estimates : dict of str to (k, size)
        Its sensor-error estimates by block name.
    t : (N,) s
        End times of the IMU samples, increasing.
    dtheta, dv : (N, 3)
        Their coning/sculling-compensated increments (rad, m/s), sensor errors not removed.

    Returns
    -------
    ImuRateTrack
    """
    t = np.asarray(t, float)
    idx = np.searchsorted(t, track.t, side="right")  # samples of interval k: idx[k]..idx[k+1]-1
    parts = []
    for k in range(len(track.t) - 1):
        i, j = idx[k], idx[k + 1]
        span = track.t[k + 1] - track.t[k]
        if j <= i or span <= 0.0:
            continue
        dts = np.diff(t[i:j], prepend=track.t[k])
        errors = SensorErrors.of_estimates({name: v[k] for name, v in estimates.items()})
        th, dvc = errors.compensate(dtheta[i:j], dv[i:j], dts)
        r = run(track.state(k), th, dvc, float(dts.mean()))
        w = ((t[i:j] - track.t[k]) / span)[:, None]
        closure = np.array([r["lat"][-1] - track.lat[k + 1], r["lon"][-1] - track.lon[k + 1],
                            r["h"][-1] - track.h[k + 1]])
        lla = np.column_stack([r["lat"][1:], r["lon"][1:], r["h"][1:]]) - w * closure
        v = r["v_enu"][1:] - w * (r["v_enu"][-1] - track.v_enu[k + 1])
        phi = quat_to_rotvec(quat_mul(track.q_nb[k + 1], quat_conj(r["q_nb"][-1])))
        q = quat_mul(quat_from_rotvec(w * phi), r["q_nb"][1:])
        parts.append((t[i:j], lla, v, q, th / dts[:, None]))
    if not parts:
        empty = np.zeros((0, 3))
        return ImuRateTrack(np.zeros(0), np.zeros(0), np.zeros(0), np.zeros(0), empty,
                            np.zeros((0, 4)), empty)
    tt, lla, v, q, w_b = (np.concatenate(c) for c in zip(*parts))
    return ImuRateTrack(tt, lla[:, 0], lla[:, 1], lla[:, 2], v, q, w_b)


def sample_rate_track(samples, estimates, t, dtheta, dv):
    """A forward pass's own solution at its IMU samples with each sample's compensated body
    rate: causal, as the strapdown publishes it (:func:`imu_rate_track` closes each interval
    onto the next epoch instead).

    Parameters
    ----------
    samples : SampleTrack
        The pass's states at its samples (``NavigatorOutput.samples``).
    estimates : dict of str to (k, size)
        The pass's sensor-error estimates per epoch: each sample is compensated with those of
        the epoch before it, as the navigator mechanised it.
    t : (N,) s
        End times of the IMU samples the pass was given, increasing (the samples' among them).
    dtheta, dv : (N, 3)
        Their coning/sculling-compensated increments (rad, m/s), sensor errors not removed.

    Returns
    -------
    ImuRateTrack
    """
    t = np.asarray(t, float)
    i = np.searchsorted(t, samples.t)
    # Each increment's interval; the first one's is taken as the second's.
    dts = np.diff(t, prepend=2.0 * t[0] - t[1] if len(t) > 1 else t[0] - 1.0)[i]
    errors = SensorErrors.of_estimates({name: v[samples.epoch - 1]
                                        for name, v in estimates.items()})
    th, _ = errors.compensate(np.asarray(dtheta)[i], np.asarray(dv)[i], dts)
    return ImuRateTrack(samples.t, samples.lat, samples.lon, samples.h, samples.v_enu,
                        samples.q_nb, th / dts[:, None])
