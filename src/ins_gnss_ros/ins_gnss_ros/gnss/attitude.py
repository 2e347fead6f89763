"""Attitude from GNSS antenna baselines (interferometric / phase-difference attitude).

* One baseline (ISON-1: two antennas 1.5 m apart, extract_004 §1.3b, §2.7): the baseline's
  azimuth (clockwise from North) and elevation, and the vehicle heading and pitch with roll
  unobservable (taken as zero). σ_azimuth ≈ σ(b ⟂ horizontal) / L_horizontal.
* Two or more non-collinear baselines (ISON-2: four antennas, 0.05° 1σ, §1.3c): the rotation
  C_nb that best maps the body-frame (FLU) antenna baselines onto the measured ENU ones, i.e.
  Wahba's problem, solved by SVD (Markley 1988, "Attitude determination using vector
  observations and the singular value decomposition") and refined by Gauss-Newton with the full
  baseline covariance, which also gives the attitude covariance.
* Mounting calibration: the body-frame direction of a baseline from a period with a reference
  attitude.
* :class:`AttitudeSolver`: the per-epoch pipeline (slip detection, double differences, float,
  length-constrained LAMBDA fix, held ambiguities, attitude) that a ROS node calls.

Angles: azimuth clockwise from North in [0, 2π); pitch and roll ROS-style (C_nb = Rz(yaw)
Ry(pitch) Rx(roll), pitch positive nose-down), all in radians.
"""
from __future__ import annotations

from collections import deque
from dataclasses import dataclass, field

import numpy as np
from scipy.stats import chi2

from ..nav.conventions import azimuth_from_yaw, wrap_pi
from ..nav.rotations import dcm_from_euler, dcm_to_quat, quat_from_rotvec, quat_to_dcm, \
    quat_to_euler, skew
from .baseline import AmbiguityStore, fix_ambiguities, fixed_baselines, float_solution
from .cycle_slip import detect_slips_dd, detect_slips_doppler
from .differences import NoiseModel, common_signals, form_double_differences, select_references
from .multipath import MultipathModel


#: A fix from scratch of a single baseline with fewer double differences than this is held only
#: once confirmed (``AttitudeSolver._confirmed``): with 5 DDs 12 of 241 accepted single-epoch
#: fixes were wrong, with 7 one of 744 (``docs/results/phase_heading.md``, bench_lambda §2).
WEAK_FIX_DDS = 6


def baseline_azimuth_elevation(b_enu, cov=None):
    """Azimuth (clockwise from North, [0, 2π)) and elevation of an ENU baseline, rad.

    Parameters
    ----------
    b_enu : array_like, shape (3,)
        Baseline master → remote, ENU (m).
    cov : array_like, shape (3, 3), optional
        Its covariance (m²).

    Returns
    -------
    azimuth, elevation : float
    cov_ae : ndarray, shape (2, 2)
        Covariance of (azimuth, elevation) (rad²), only if ``cov`` is given: first-order
        propagation, σ_az = σ(horizontal, across) / L_h and σ_el = σ(vertical-ish) / L.
    """
    e, n, u = np.asarray(b_enu, float)
    h2 = e * e + n * n
    az = float(np.arctan2(e, n) % (2 * np.pi))
    el = float(np.arctan2(u, np.sqrt(h2)))
    if cov is None:
        return az, el
    L2 = h2 + u * u
    h = np.sqrt(h2)
    J = np.array([[n / h2, -e / h2, 0.0],
                  [-e * u / (L2 * h), -n * u / (L2 * h), h / L2]])
    return az, el, J @ np.asarray(cov, float) @ J.T


def _heading_pitch_one_baseline(b_enu, b_body):
    """Yaw and pitch (rad) with roll = 0 such that Rz(yaw) Ry(pitch) b_body ∥ b_enu."""
    x, y, z = b_body / np.linalg.norm(b_body)
    u = b_enu / np.linalg.norm(b_enu)
    # Ry(p) b_body has up component ρ sin(α - p), ρ = √(x² + z²), α = atan2(z, x).
    rho, alpha = np.hypot(x, z), np.arctan2(z, x)
    s = np.arcsin(np.clip(u[2] / rho, -1.0, 1.0))
    # Two pitch angles give the baseline its measured elevation, alpha - s and alpha - pi + s;
    # with roll taken as zero the vehicle's is the one within +-90 deg (for a baseline pointing
    # aft the other one is the vehicle turned upside down and about).
    p = min(wrap_pi(alpha - s), wrap_pi(alpha - np.pi + s), key=abs)
    beta = np.arctan2(y, x * np.cos(p) + z * np.sin(p))
    return wrap_pi(np.arctan2(u[1], u[0]) - beta), p


def _euler_rates_matrix(roll, pitch, yaw):
    """M with δθ_n = M [δroll, δpitch, δyaw] for C = Rz(yaw) Ry(pitch) Rx(roll)."""
    cy, sy, cp, sp = np.cos(yaw), np.sin(yaw), np.cos(pitch), np.sin(pitch)
    return np.array([[cy * cp, -sy, 0.0],
                     [sy * cp, cy, 0.0],
                     [-sp, 0.0, 1.0]])


def wahba_svd(body, nav, weights):
    """Rotation C_nb minimising Σ w_k |nav_k - C body_k|² (Markley 1988).

    Parameters
    ----------
    body, nav : array_like, shape (K, 3)
        Vector pairs in body (FLU) and navigation (ENU) axes.
    weights : array_like, shape (K,)

    Returns
    -------
    ndarray, shape (3, 3)
    """
    B = np.einsum("k,ki,kj->ij", np.asarray(weights, float), np.asarray(nav, float),
                  np.asarray(body, float))
    U, _, Vt = np.linalg.svd(B)
    return U @ np.diag([1.0, 1.0, np.linalg.det(U) * np.linalg.det(Vt)]) @ Vt


@dataclass
class AttitudeEstimate:
    """Attitude from baselines.

    Attributes
    ----------
    roll, pitch, yaw : float
        ROS-style Euler angles (rad); roll NaN when not observed.
    azimuth : float
        Heading clockwise from North (rad, [0, 2π)).
    cov : ndarray, shape (3, 3)
        Covariance of (roll, pitch, yaw) (rad²); NaN row/column for unobserved roll.
    q_nb : ndarray, shape (4,)
        Quaternion [w, x, y, z] (with roll = 0 if not observed).
    """

    roll: float
    pitch: float
    yaw: float
    azimuth: float
    cov: np.ndarray
    q_nb: np.ndarray


def solve_attitude(b_enu, cov, b_body, iterations=3) -> AttitudeEstimate:
    """Attitude from K measured baselines and their body-frame coordinates.

    Parameters
    ----------
    b_enu : array_like, shape (K, 3)
        Measured baselines (ENU, m).
    cov : array_like, shape (3K, 3K)
        Their joint covariance (m²).
    b_body : array_like, shape (K, 3)
        The same baselines in the body frame (FLU, m), from the antenna positions.
    iterations : int
        Gauss-Newton iterations after the SVD start.

    Returns
    -------
    AttitudeEstimate
        With one baseline, or collinear ones, roll is unobservable: it is set to 0 for the
        solution and reported NaN, and yaw/pitch come from the longest baseline.
    """
    b_enu = np.atleast_2d(np.asarray(b_enu, float))
    b_body = np.atleast_2d(np.asarray(b_body, float))
    cov = np.asarray(cov, float)
    sv = np.linalg.svd(b_body / np.linalg.norm(b_body, axis=1, keepdims=True),
                       compute_uv=False)
    if len(b_body) < 2 or sv[1] < 0.1 * sv[0]:
        k = int(np.argmax(np.linalg.norm(b_body, axis=1)))
        Pk = cov[3 * k:3 * k + 3, 3 * k:3 * k + 3]
        yaw, pitch = _heading_pitch_one_baseline(b_enu[k], b_body[k])
        # First-order covariance by central differences of the closed form (it is smooth).
        J = np.zeros((2, 3))
        h = 1e-6 * np.linalg.norm(b_enu[k])
        for i in range(3):
            d = np.zeros(3)
            d[i] = h
            yp, pp = _heading_pitch_one_baseline(b_enu[k] + d, b_body[k])
            ym, pm = _heading_pitch_one_baseline(b_enu[k] - d, b_body[k])
            J[:, i] = [wrap_pi(yp - ym) / (2 * h), (pp - pm) / (2 * h)]
        C2 = J @ Pk @ J.T
        C = np.full((3, 3), np.nan)
        C[1:, 1:] = C2[::-1, ::-1]
        q = dcm_to_quat(dcm_from_euler(0.0, pitch, yaw))
        return AttitudeEstimate(np.nan, float(pitch), float(yaw), float(azimuth_from_yaw(yaw)),
                                C, q)
    P_inv = np.linalg.inv(cov)
    w = 1.0 / np.array([np.trace(cov[3 * k:3 * k + 3, 3 * k:3 * k + 3])
                        for k in range(len(b_body))])
    C_nb = wahba_svd(b_body, b_enu, w)
    for _ in range(iterations):
        pred = b_body @ C_nb.T
        r = (b_enu - pred).ravel()
        # b_enu = (I + [δθ×]) C b + v, so r = δθ × (C b) + v = -[(C b)×] δθ + v.
        H = np.vstack([-skew(p) for p in pred])
        N = H.T @ P_inv @ H
        dtheta = np.linalg.solve(N, H.T @ P_inv @ r)
        C_nb = quat_to_dcm(quat_from_rotvec(dtheta)) @ C_nb
    P_theta = np.linalg.inv(N)
    q = dcm_to_quat(C_nb)
    roll, pitch, yaw = (float(a) for a in quat_to_euler(q))
    Minv = np.linalg.inv(_euler_rates_matrix(roll, pitch, yaw))
    return AttitudeEstimate(roll, pitch, yaw, float(azimuth_from_yaw(yaw)),
                            Minv @ P_theta @ Minv.T, q)


def rigid_body_misfit(b_enu, cov, b_body) -> tuple[float, int]:
    """How far measured baselines are from one rigid rotation of the antenna geometry.

    χ² = min_C (b - C b_body)ᵀ P⁻¹ (b - C b_body) over all K baselines jointly, at the attitude
    of :func:`solve_attitude` (the weighted Wahba / Gauss-Newton minimiser; for collinear
    baselines the longest one's direction), with 3K - 3 degrees of freedom (3K - 2 for collinear
    baselines: the rotation about their line is free). It tests the lengths and the angles
    between the baselines at once: the orthonormality constraint of the multivariate constrained
    LAMBDA (Teunissen 2007, "A general multivariate formulation of the multi-antenna GNSS
    attitude determination problem", Artificial Satellites 42; Teunissen, Giorgi & Buist 2011,
    GPS Solutions 15), used here as a test of fixes made baseline by baseline. With correct
    integers it is χ²(dof) when ``cov`` holds all the errors; a wrong integer set moves its
    baseline by decimetres in a direction no common rotation of the others follows.

    Parameters
    ----------
    b_enu : array_like, shape (K, 3)
        Measured baselines (ENU, m).
    cov : array_like, shape (3K, 3K)
        Their covariance, including the uncertainty of the body geometry (m²).
    b_body : array_like, shape (K, 3)
        The baselines in the body frame (FLU, m).

    Returns
    -------
    chi2 : float
    dof : int
    """
    b_enu = np.atleast_2d(np.asarray(b_enu, float))
    b_body = np.atleast_2d(np.asarray(b_body, float))
    att = solve_attitude(b_enu, cov, b_body)
    r = (b_enu - b_body @ quat_to_dcm(att.q_nb).T).ravel()
    collinear = np.isnan(att.roll)
    return float(r @ np.linalg.solve(cov, r)), 3 * len(b_body) - (2 if collinear else 3)


@dataclass
class MountingCalibration:
    """Body-frame direction of a baseline estimated against a reference attitude.

    Attributes
    ----------
    direction_flu : ndarray, shape (3,)
        Unit baseline direction in the body frame.
    azimuth_offset : float
        Its angle in the body x-y plane, counter-clockwise from x (rad): the heading offset
        to subtract from the baseline yaw.
    elevation_offset : float
        Its elevation above the body x-y plane (rad).
    std : ndarray, shape (2,)
        Standard errors of the two offsets (rad), from the scatter over the epochs.
    """

    direction_flu: np.ndarray
    azimuth_offset: float
    elevation_offset: float
    std: np.ndarray


def estimate_mounting(b_enu, C_nb) -> MountingCalibration:
    """Baseline mounting (heading and pitch offset) from epochs with a reference attitude.

    Each epoch gives the body-frame direction C_nbᵀ b / |b|; their mean, renormalised, is the
    least-squares direction on the sphere.

    Parameters
    ----------
    b_enu : array_like, shape (T, 3)
        Measured (fixed) baselines, ENU (m).
    C_nb : array_like, shape (T, 3, 3)
        Reference attitude at the same epochs (e.g. a navigation-grade INS).
    """
    b_enu = np.asarray(b_enu, float)
    u_body = np.einsum("tji,tj->ti", np.asarray(C_nb, float), b_enu)
    u_body /= np.linalg.norm(u_body, axis=1, keepdims=True)
    u = u_body.mean(axis=0)
    u /= np.linalg.norm(u)
    az = np.arctan2(u_body[:, 1], u_body[:, 0])
    el = np.arcsin(np.clip(u_body[:, 2], -1, 1))
    az0 = float(np.arctan2(u[1], u[0]))
    std = np.array([np.std(wrap_pi(az - az0)), np.std(el)]) / np.sqrt(len(b_enu))
    return MountingCalibration(u, az0, float(np.arcsin(u[2])), std)


def correlated_variance_factor(a: float, n: float) -> float:
    """How many times to count the variance σ² of a first-order Gauss-Markov error sampled with
    correlation ``a`` = exp(-Δt/τ) between epochs, for a consumer that averages ``n`` epochs as
    if they were independent.

    The mean of n samples of an AR(1) sequence has the variance (σ²/n) [1 + 2 Σ_{k<n} (1 - k/n)
    aᵏ] = (σ²/n) [(1 + a)/(1 - a) - 2a (1 - aⁿ) / (n (1 - a)²)]; n independent samples of
    variance f σ² give f σ²/n, so f is the bracket: 1 for n = 1 (one epoch), (1 + a)/(1 - a) =
    coth(Δt/2τ) ≈ 2τ/Δt for n → ∞ (the long-run variance; 300 at 5 Hz with τ = 30 s).
    """
    if a <= 0.0:
        return 1.0
    tail = 0.0 if np.isinf(n) else 2.0 * a * (1.0 - a ** n) / (n * (1.0 - a) ** 2)
    return float((1.0 + a) / (1.0 - a) - tail)


@dataclass
class FixedDoubleDifferences:
    """The fixed double differences of an epoch as attitude measurements (the seeds' direct use
    of second differences in the filter, extract_004 §2.2.2-2.2.3 and §2.5).

    Row j: ``value[j] = geometry[j] · (C_nb baseline_b[j]) + noise`` (m), the plane-wavefront
    model of :mod:`.differences` with the integer removed, λ (DD - N) = -(e_i - e_ref) · b_enu.

    Attributes
    ----------
    remote : ndarray of int, shape (m,)
        Remote antenna index of each row (the master is antenna 0).
    baseline_b : ndarray, shape (m, 3)
        Remote minus master antenna in the body frame (FLU, m).
    pairs : list of (str, str)
        (signal, reference signal).
    wavelength : ndarray, shape (m,)
        (m).
    value : ndarray, shape (m,)
        λ (DD phase - fixed ambiguity), m.
    geometry : ndarray, shape (m, 3)
        e_ref - e_i, unit lines of sight toward the satellites (ENU).
    cov : ndarray, shape (m, m)
        Covariance (m²): the white part and the time-correlated part counted as for the
        published attitude (:meth:`AttitudeSolver._correlated_factor`).
    """

    remote: np.ndarray
    baseline_b: np.ndarray
    pairs: list
    wavelength: np.ndarray
    value: np.ndarray
    geometry: np.ndarray
    cov: np.ndarray


@dataclass
class AttitudeSolution:
    """Output of :meth:`AttitudeSolver.process` (fields of ins_gnss_msgs/Heading).

    Attributes
    ----------
    status : str
        "NONE", "FLOAT" or "FIXED".
    azimuth, pitch, roll : float
        rad (azimuth clockwise from North, ROS pitch/roll); NaN where not observed.
    var_azimuth, var_pitch, var_roll : float
        rad²; NaN where not observed.
    ratio : float
        Smallest ratio-test statistic of the fixes in use (NaN if none).
    satellites : tuple of str
        Signals in the double differences.
    baselines : ndarray, shape (K, 3)
        ENU baselines used (m), NaN if none.
    slipped : set of str
        Signals detected as slipped at this epoch.
    double_differences : FixedDoubleDifferences or None
        The fixed double differences the FIXED attitude was solved from (None otherwise).
    """

    status: str
    azimuth: float = np.nan
    pitch: float = np.nan
    roll: float = np.nan
    var_azimuth: float = np.nan
    var_pitch: float = np.nan
    var_roll: float = np.nan
    ratio: float = np.nan
    satellites: tuple = ()
    baselines: np.ndarray = field(default_factory=lambda: np.full((1, 3), np.nan))
    slipped: set = field(default_factory=set)
    double_differences: FixedDoubleDifferences | None = None


class AttitudeSolver:
    """Per-epoch GNSS phase-difference attitude for 2-4 antennas on a rigid body.

    Parameters
    ----------
    antennas_flu : array_like, shape (K+1, 3)
        Antenna phase-centre positions in the body frame (FLU, m); row 0 is the master.
    noise : NoiseModel
        Undifferenced phase and code noise.
    ratio_threshold : float
        Ratio-test threshold for accepting a fix.
    sigma_length : float
        Uncertainty of the known baseline lengths (m).
    elevation_mask : float
        Satellites below are ignored (rad).
    slip_threshold : float
        Doppler test threshold (cycles).
    w_critical : float
        Critical value of the DD w-test for slips.
    max_gap : float
        Longest interval between epochs for the time-difference tests (s).
    window : int
        Epochs accumulated in the float solution while ambiguities are unfixed (1 = single
        epoch); emptied at every detected slip or gap.
    multipath : MultipathModel, optional
        Time-correlated phase error (σ(el), correlation time ``phase_tau``) besides ``noise``.
        It leaves the fixing alone and enters the FIXED attitude covariance.
    averaging_time : float
        Time over which the consumer of the attitude averages it (s), taking every epoch as an
        independent measurement: the correlated part of the covariance is counted so that the
        average over that time has the right variance (:func:`correlated_variance_factor`).
        0: once (the variance of one epoch); inf: the long-run limit ≈ 2τ/Δt.
    confirm_epochs : int
        With one baseline, a fix from scratch from fewer than ``WEAK_FIX_DDS`` double
        differences is held once the same integers have passed the ratio test at this many
        consecutive epochs (1: at once; see ``_confirmed``).

    Every epoch the held ambiguities must pass the residual χ² test, the known baseline lengths
    and, with two or more baselines, the rigid-body test (:func:`rigid_body_misfit`); a failure
    drops them all.
    """

    def __init__(self, antennas_flu, noise=NoiseModel(), ratio_threshold=3.0,
                 sigma_length=0.002, elevation_mask=np.radians(10.0), slip_threshold=1.0,
                 w_critical=4.0, max_gap=5.0, window=5, multipath: MultipathModel | None = None,
                 averaging_time=0.0, confirm_epochs=1):
        ant = np.asarray(antennas_flu, float)
        self.b_body = ant[1:] - ant[0]
        self.lengths = np.linalg.norm(self.b_body, axis=1)
        self.noise = noise
        self.ratio_threshold = ratio_threshold
        self.sigma_length = sigma_length
        self.elevation_mask = elevation_mask
        self.slip_threshold = slip_threshold
        self.w_critical = w_critical
        self.max_gap = max_gap
        self.multipath = multipath
        self.averaging_time = averaging_time
        self.confirm_epochs = confirm_epochs
        self._t_last = None     # last epoch processed; reset() keeps it (the output goes on)
        self.store = AmbiguityStore()
        self._refs: dict = {}
        self._ratio = {}
        self._candidate = None  # one baseline: ((row keys, integers), epochs passed in a row)
        self._prev = None   # (t, epochs, dd, baselines)
        self._window = deque(maxlen=max(window - 1, 0))   # earlier epochs' DDs

    @property
    def references(self) -> dict:
        """Reference signal of each (system, wavelength) group at the last epoch."""
        return dict(self._refs)

    def reset(self):
        """Forget the held ambiguities and the previous epoch."""
        self.store.forget()
        self._refs, self._ratio, self._prev = {}, {}, None
        self._candidate = None
        self._window.clear()

    def process(self, epochs, los_enu, t, attitude_prior=None, tilt_prior=None
                ) -> AttitudeSolution:
        """Attitude of one epoch.

        Parameters
        ----------
        epochs : sequence of AntennaEpoch
            Observations of every antenna at time t, in the order of ``antennas_flu``.
        los_enu : mapping signal id -> ndarray (3,)
            Unit line of sight to each satellite (ENU), e.g. from the ephemeris and the
            master antenna position.
        t : float
            Epoch time (s).
        attitude_prior : (ndarray (3, 3), ndarray (3, 3)), optional
            Predicted C_nb and the covariance of its small-angle error (rad², ENU), e.g. from
            the INS: it becomes an a-priori baseline in the float solution.
        tilt_prior : (ndarray (3, 3), float), optional
            C_nb whose roll and pitch are known, to the 1σ error given (rad), and whose heading is
            not (e.g. an INS levelled by its accelerometers before its heading is aligned): it
            becomes an a-priori up component of every baseline (:meth:`_priors`). Not used with
            ``attitude_prior``, which holds the tilt already.

        Returns
        -------
        AttitudeSolution
        """
        K = len(self.b_body)
        los = {s: np.asarray(e, float) / np.linalg.norm(e) for s, e in los_enu.items()
               if np.arcsin(e[2] / np.linalg.norm(e)) >= self.elevation_mask}
        slipped = self._detect_doppler(epochs, t)
        # Only signals with a phase on every antenna: one without (e.g. its half-cycle ambiguity
        # still unresolved) must not become a reference and silence its whole group.
        ids = common_signals(epochs, los)
        lam0 = dict(zip(epochs[0].signal_ids, epochs[0].wavelength))
        el = [np.arcsin(los[s][2]) for s in ids]
        self.store.forget(signals=slipped)
        preferred = set().union(*(self.store.known_signals(r) for r in self._refs.values())) \
            if self._refs else set()
        refs = select_references(ids, el, [lam0[s] for s in ids], self._refs, slipped, preferred)
        for g, r in refs.items():
            old = self._refs.get(g)
            if old is not None and old != r:
                self.store.rereference(old, r, keep_old=old not in slipped)
        self._refs = refs
        dd = form_double_differences(epochs, los, refs, self.noise, multipath=self.multipath)
        interval = t - self._t_last if self._t_last is not None else np.inf
        self._t_last = t
        self.store.retain({s for p in dd.pairs for s in p})
        if dd.phase.size == 0:
            self._prev = None
            return AttitudeSolution("NONE", slipped=slipped)
        prev = self._prev
        if prev is not None and t - prev[0] <= self.max_gap:
            dd_slips = detect_slips_dd(prev[2], dd, prev[3], self.w_critical)
            self.store.forget(signals=dd_slips)
            slipped |= dd_slips
        if slipped or prev is None or t - prev[0] > self.max_gap:
            self._window.clear()
        history = list(self._window)
        self._window.append(dd)
        priors = self._priors(attitude_prior, tilt_prior)
        held = self.store.lookup(dd)
        for k in range(1, K + 1):
            if np.all(np.isfinite(held[dd.rows(k)])):
                continue            # nothing to fix: the held ambiguities cover this baseline
            fs = float_solution(dd, k, held, priors[k - 1], history=history)
            if fs is None:
                continue
            fix = fix_ambiguities(fs, self.lengths[k - 1], self.sigma_length,
                                  enough_ratio=max(10.0, self.ratio_threshold))
            if fix is None or fix.ratio < self.ratio_threshold:
                self._candidate = None
                continue
            weak = K == 1 and fs.rows.size == dd.rows(k).size and fs.rows.size < WEAK_FIX_DDS
            if weak and not self._confirmed(dd, fs, fix):
                continue
            self._candidate = None
            self.store.hold(dd, fs.rows, fix.ambiguities)
            self._ratio[k] = fix.ratio
        fixed = fixed_baselines(dd, self.store.lookup(dd), K)
        if fixed is not None and not (fixed.consistent() and self._lengths_ok(fixed)
                                      and self._rigid_ok(fixed)):
            # A wrong fix or an undetected slip: start the ambiguities afresh.
            self.store.forget()
            self._ratio = {}
            fixed = None
        sats = tuple(sorted({s for p in dd.pairs for s in p}))
        if fixed is not None:
            self._prev = (t, epochs, dd, fixed.baselines)
            factor = self._correlated_factor(interval)
            sol = self._solution("FIXED", fixed.baselines, self._published_cov(fixed, factor),
                                 sats, slipped,
                                 min(self._ratio.values()) if self._ratio else np.nan)
            sol.double_differences = self._fixed_differences(dd, self.store.lookup(dd), factor)
            return sol
        held = self.store.lookup(dd)
        floats = [float_solution(dd, k, held, priors[k - 1]) for k in range(1, K + 1)]
        if any(f is None for f in floats):
            self._prev = None
            return AttitudeSolution("NONE", satellites=sats, slipped=slipped)
        b = np.array([f.baseline for f in floats])
        cov = np.zeros((3 * K, 3 * K))
        for k, f in enumerate(floats):
            cov[3 * k:3 * k + 3, 3 * k:3 * k + 3] = f.cov[:3, :3]
        self._prev = (t, epochs, dd, b)
        return self._solution("FLOAT", b, cov, sats, slipped, np.nan)

    def _correlated_factor(self, interval: float) -> float:
        """How many times the published covariances count the time-correlated part:
        :func:`correlated_variance_factor` for the epoch interval, the correlation time and
        ``averaging_time`` (1 without a multipath model)."""
        a, n = 0.0, 1.0          # the first epoch (no predecessor): the variance once
        if self.multipath is not None and 0.0 < interval < np.inf:
            a = np.exp(-interval / self.multipath.phase_tau)
            n = max(self.averaging_time / interval, 1.0)
        return correlated_variance_factor(a, n)

    def _published_cov(self, fixed, factor: float) -> np.ndarray:
        """Baseline covariance for the published attitude: the white part plus ``factor`` times
        the correlated part."""
        if fixed.cov_correlated is None:
            return fixed.cov
        return fixed.cov + factor * fixed.cov_correlated

    def _fixed_differences(self, dd, ambiguities, factor: float) -> FixedDoubleDifferences:
        """The rows of ``dd`` with a held ambiguity, in metres, with their joint covariance (the
        correlated part ``factor`` times, as for the attitude)."""
        use = np.flatnonzero(np.isfinite(ambiguities))
        lam = dd.wavelength[use]
        cov = dd.cov_phase[np.ix_(use, use)]
        if dd.cov_correlated is not None:
            cov = cov + factor * dd.cov_correlated[np.ix_(use, use)]
        remote = dd.baseline[use]
        return FixedDoubleDifferences(
            remote, self.b_body[remote - 1], [dd.pairs[j] for j in use], lam,
            lam * (dd.phase[use] - ambiguities[use]), dd.geometry[use],
            lam[:, None] * cov * lam[None, :])

    def _detect_doppler(self, epochs, t) -> set:
        slipped = set()
        prev = self._prev
        for a, ep in enumerate(epochs):
            if prev is not None and t - prev[0] <= self.max_gap:
                slipped |= detect_slips_doppler(prev[1][a], ep, t - prev[0],
                                                self.slip_threshold)
            elif ep.loss_of_lock is not None:
                slipped |= {s for s, f in zip(ep.signal_ids, ep.loss_of_lock) if f}
        return slipped

    def _priors(self, attitude_prior, tilt_prior):
        """A-priori observation (H, y, C) of each baseline for :func:`float_solution`, or None.

        A full attitude gives the whole baseline C b. A tilt alone gives its up component
        (C b)_U = c₃ᵀ b, with c₃ the third row of C_nb, which depends on roll and pitch only: a
        heading error of any size leaves it unchanged, so nothing is linearised in the heading.
        A tilt error δθ (about E and N, σ each) moves it by δθ_E p_N - δθ_N p_E, p = C b, of
        variance σ² (p_E² + p_N²) = σ² (|b|² - p_U²), free of the heading too; the body geometry
        adds ``sigma_length``². With the length constraint of the fix this leaves the integer
        search one unknown direction, the heading, instead of the weak vertical of a geometry
        with satellites on one side of the horizon only.
        """
        if attitude_prior is not None:
            C, P_theta = attitude_prior
            out = []
            for bb in self.b_body:
                p = C @ bb
                S = skew(p)       # δb = δθ × (C b) = -[(C b)×] δθ
                out.append((np.eye(3), p, S @ P_theta @ S.T + 1e-6 * np.eye(3)))
            return out
        if tilt_prior is not None:
            C, sigma = tilt_prior
            out = []
            for bb in self.b_body:
                up = float(C[2] @ bb)
                var = sigma ** 2 * (bb @ bb - up ** 2) + self.sigma_length ** 2
                out.append((np.array([[0.0, 0.0, 1.0]]), np.array([up]), np.array([[var]])))
            return out
        return [None] * len(self.b_body)

    def _lengths_ok(self, fixed, k_sigma=6.0) -> bool:
        for k, b in enumerate(fixed.baselines):
            u = b / np.linalg.norm(b)
            s2 = u @ fixed.cov[3 * k:3 * k + 3, 3 * k:3 * k + 3] @ u + self.sigma_length ** 2
            if abs(np.linalg.norm(b) - self.lengths[k]) > k_sigma * np.sqrt(s2):
                return False
        return True

    def _confirmed(self, dd, fs, fix) -> bool:
        """Whether a fix from scratch of the single baseline (none of its ambiguities held) from
        fewer than ``WEAK_FIX_DDS`` double differences may be held: the same integers of the
        same rows have passed the ratio test at ``confirm_epochs`` consecutive epochs.

        The solver tries a fix at every epoch until one passes, so the chance that a wrong
        candidate passes once grows with the number of tries; held, it is never tested by the
        ratio again. With few double differences the winner drifts between a few candidates
        from epoch to epoch (time-correlated multipath moves the float solution); a wrong one
        seldom passes twice in a row, a right one keeps winning: the "minimum fix count to hold
        ambiguity" of fix-and-hold RTK (RTKLIB manual, option pos2-arminfix). Fixes next to held
        ambiguities (after a slip) are constrained by them and held at once; with two or more
        baselines the rigid-body test (:meth:`_rigid_ok`) is the stronger check and fixes are
        held at once.
        """
        key = (tuple(dd.key(j) for j in fs.rows), tuple(fix.ambiguities.tolist()))
        last, count = self._candidate or (None, 0)
        count = count + 1 if last == key else 1
        self._candidate = (key, count)
        return count >= self.confirm_epochs

    def _rigid_ok(self, fixed, alpha=1e-4) -> bool:
        """With two or more baselines, :func:`rigid_body_misfit` at false-alarm probability
        ``alpha`` per epoch. It catches a wrong fix that each baseline's own tests pass: with few
        double differences (e.g. the first fix from 5 Galileo satellites, 4 per baseline) the
        residual χ² has 1 degree of freedom per baseline and epoch, and a length-constrained
        wrong candidate has the right length by construction. The covariance is that of one
        epoch: the white part, the time-correlated multipath once, and the body geometry
        (``sigma_length`` on every axis)."""
        K = len(self.b_body)
        if K < 2:
            return True
        cov = fixed.cov + self.sigma_length ** 2 * np.eye(3 * K)
        if fixed.cov_correlated is not None:
            cov = cov + fixed.cov_correlated
        misfit, dof = rigid_body_misfit(fixed.baselines, cov, self.b_body)
        return misfit <= chi2.ppf(1.0 - alpha, dof)

    def _solution(self, status, b, cov, sats, slipped, ratio) -> AttitudeSolution:
        att = solve_attitude(b, cov, self.b_body)
        return AttitudeSolution(status, att.azimuth, att.pitch, att.roll, att.cov[2, 2],
                                att.cov[1, 1], att.cov[0, 0], ratio, sats, b, slipped)
