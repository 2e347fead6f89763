"""Single and double differences of carrier phase and pseudorange between antennas.

Observation model (undifferenced, antenna A, signal i, RINEX sign: phase grows with range):

    λ φ_A,i = ρ_A,i + c δt_A - c δt^i + λ N_A,i + ε,      ρ_A,i ≈ ρ_0,i - e_i · r_A,

with e_i the unit line of sight from the antennas to the satellite (ENU) and r_A the antenna
position. Between a master antenna M and a remote antenna R on a baseline b = r_R - r_M (short
enough that the lines of sight are parallel, the plane-wavefront assumption):

* single difference  SD_i = φ_R,i - φ_M,i:  λ SD_i = -e_i · b + c(δt_R - δt_M) + λ N_RM,i,
  the satellite clock and, on short baselines, the atmosphere cancel;
* double difference  DD_i = SD_i - SD_ref:  λ DD_i = -(e_i - e_ref) · b + λ N_i,ref,
  the receiver clocks cancel and N_i,ref is an integer when both signals share one wavelength.

The reference satellite of each group is the highest one (the seeds' "reference SV near
zenith", extract_004 §2.7), kept across epochs while it is tracked. Groups are (system,
wavelength): no differences across systems (inter-system biases) or across GLONASS FDMA slots
(the ambiguity of such a difference is not an integer), so GLONASS signals on distinct slots
form one-satellite groups and drop out.

Noise: every undifferenced phase has variance σ² = a² + b²/sin²(el) (the elevation model of
e.g. RTKLIB's manual and Groves §9.4.1.3, a = b = 2-3 mm), independent between antennas and
signals; the DD covariance is D Σ Dᵀ, correlated through the reference satellite and, with
several baselines, through the master antenna. Multipath (:mod:`multipath`, correlated in time)
can be given as well: its DD covariance is kept apart (``cov_correlated``), so the fixing keeps
its weights and the attitude covariance can count it for the consumer
(:class:`~ins_gnss_ros.gnss.attitude.AttitudeSolver`).
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Mapping, Sequence

import numpy as np

from .multipath import MultipathModel


@dataclass
class AntennaEpoch:
    """Raw observations of one antenna at one epoch.

    Attributes
    ----------
    signal_ids : sequence of str
        One id per tracked signal, unique per antenna, first character the RINEX system
        letter ("G05", "E11", "G05L2" ...). The same signal has the same id on every antenna.
    phase : array_like, shape (n,)
        Carrier phase (cycles), NaN if not tracked.
    pseudorange : array_like, shape (n,)
        Pseudorange (m), NaN if absent.
    wavelength : array_like, shape (n,)
        Carrier wavelength (m).
    doppler : array_like, shape (n,), optional
        Doppler (Hz, positive for an approaching satellite, RINEX sign), NaN if absent.
    loss_of_lock : array_like of bool, shape (n,), optional
        Receiver's loss-of-lock indicator (a possible cycle slip since the previous epoch).
    """

    signal_ids: Sequence[str]
    phase: np.ndarray
    pseudorange: np.ndarray
    wavelength: np.ndarray
    doppler: np.ndarray | None = None
    loss_of_lock: np.ndarray | None = None

    def index(self) -> dict:
        """Map signal id -> position in the arrays."""
        return {s: i for i, s in enumerate(self.signal_ids)}


@dataclass(frozen=True)
class NoiseModel:
    """Undifferenced measurement noise, σ² = a² + b²/sin²(el).

    Attributes
    ----------
    phase_a, phase_b : float
        Phase constant and elevation-dependent terms (m).
    code_a, code_b : float
        Pseudorange terms (m).
    """

    phase_a: float = 0.002
    phase_b: float = 0.002
    code_a: float = 0.3
    code_b: float = 0.3


def elevation_sigma(elevation, a, b):
    """Standard deviation sqrt(a² + b²/sin²(el)) (units of a and b) at elevation (rad)."""
    s = np.maximum(np.sin(np.asarray(elevation, float)), 0.05)  # bounded below 3 deg
    return np.sqrt(a * a + (b / s) ** 2)


def group_key(signal_id: str, wavelength: float) -> tuple:
    """Group of signals that may be double differenced together: (system, wavelength in µm)."""
    return signal_id[0], round(float(wavelength) * 1e6)


def select_references(signal_ids, elevations, wavelengths, previous=None, exclude=(),
                      preferred=()) -> dict:
    """Reference signal of every group.

    The previous reference is kept while it is present and not excluded (e.g. slipped); else
    the highest signal among ``preferred`` (those whose ambiguity is still known, so the held
    ambiguities can be re-referenced), else the highest of the group.

    Parameters
    ----------
    signal_ids : sequence of str
        Signals common to all antennas.
    elevations : array_like
        Their elevations (rad).
    wavelengths : array_like
        Their wavelengths (m).
    previous : mapping group -> id, optional
        References of the previous epoch.
    exclude : collection of str
        Signals that must not be the reference (cycle slip, loss of lock).
    preferred : collection of str
        Signals preferred as a new reference.

    Returns
    -------
    dict group -> reference signal id (only groups with at least two signals).
    """
    previous = previous or {}
    groups: dict = {}
    for s, el, lam in zip(signal_ids, elevations, wavelengths):
        groups.setdefault(group_key(s, lam), []).append((el, s))
    refs = {}
    for g, members in groups.items():
        if len(members) < 2:
            continue
        ids = {s for _, s in members}
        if previous.get(g) in ids and previous[g] not in exclude:
            refs[g] = previous[g]
            continue
        usable = [(el, s) for el, s in members if s not in exclude] or members
        pref = [(el, s) for el, s in usable if s in preferred]
        refs[g] = max(pref or usable)[1]
    return refs


@dataclass
class DoubleDifferences:
    """Double differences of one epoch, all baselines (master antenna 0 to antenna k).

    Row j is baseline ``baseline[j]``, signal ``pairs[j][0]`` minus reference ``pairs[j][1]``.

    Attributes
    ----------
    pairs : list of (str, str)
    baseline : ndarray of int, shape (m,)
        Remote antenna index (1 … n_antennas-1) of each row.
    wavelength : ndarray, shape (m,)
        (m).
    phase : ndarray, shape (m,)
        DD carrier phase (cycles).
    code : ndarray, shape (m,)
        DD pseudorange (m), NaN if a pseudorange is missing.
    geometry : ndarray, shape (m, 3)
        -(e_i - e_ref) in ENU: DD range (m) = geometry @ b_enu.
    cov_phase : ndarray, shape (m, m)
        Covariance of ``phase`` (cycles²).
    cov_code : ndarray, shape (m, m)
        Covariance of ``code`` (m²).
    references : dict group -> reference id
    cov_correlated : ndarray, shape (m, m), or None
        Covariance of the time-correlated part of the phase errors (multipath), not included
        in ``cov_phase`` (cycles²); None when not modelled.
    """

    pairs: list
    baseline: np.ndarray
    wavelength: np.ndarray
    phase: np.ndarray
    code: np.ndarray
    geometry: np.ndarray
    cov_phase: np.ndarray
    cov_code: np.ndarray
    references: dict = field(default_factory=dict)
    cov_correlated: np.ndarray | None = None

    def rows(self, k: int) -> np.ndarray:
        """Indices of the rows of baseline k."""
        return np.flatnonzero(self.baseline == k)

    def key(self, j: int) -> tuple:
        """Identity of row j for holding its ambiguity: (baseline, signal, reference)."""
        return int(self.baseline[j]), self.pairs[j][0], self.pairs[j][1]


def common_signals(epochs: Sequence[AntennaEpoch], los_enu: Mapping[str, np.ndarray]) -> list:
    """Signals with a phase on every antenna and a known line of sight, in a stable order."""
    sets = []
    for ep in epochs:
        ph = np.asarray(ep.phase, float)
        sets.append({s for s, p in zip(ep.signal_ids, ph) if np.isfinite(p)})
    return sorted(set.intersection(*sets) & set(los_enu))


def form_double_differences(epochs: Sequence[AntennaEpoch], los_enu: Mapping[str, np.ndarray],
                            references: Mapping, noise: NoiseModel = NoiseModel(),
                            exclude=(), multipath: MultipathModel | None = None
                            ) -> DoubleDifferences:
    """Double differences of all baselines from antenna 0, with their joint covariance.

    Parameters
    ----------
    epochs : sequence of AntennaEpoch
        Antenna 0 is the master; baselines are 0→1, 0→2, …
    los_enu : mapping signal id -> ndarray (3,)
        Unit line of sight from the antennas to the satellite, ENU.
    references : mapping group -> reference id
        From :func:`select_references`.
    noise : NoiseModel
        Undifferenced noise model.
    exclude : collection of str
        Signals to leave out (not as the reference).
    multipath : MultipathModel, optional
        Time-correlated phase error of every undifferenced phase, independent between antennas
        and signals, σ(el) = ``multipath.sigma(el)[1]``: gives ``cov_correlated``.

    Returns
    -------
    DoubleDifferences
    """
    ids = common_signals(epochs, los_enu)
    n_ant, n_sig = len(epochs), len(ids)
    col = {s: i for i, s in enumerate(ids)}
    ph = np.empty((n_ant, n_sig))
    pr = np.empty((n_ant, n_sig))
    lam = np.empty(n_sig)
    for a, ep in enumerate(epochs):
        idx = ep.index()
        sel = [idx[s] for s in ids]
        ph[a] = np.asarray(ep.phase, float)[sel]
        pr[a] = np.asarray(ep.pseudorange, float)[sel]
        if a == 0:
            lam = np.asarray(ep.wavelength, float)[sel]
    e = np.array([los_enu[s] for s in ids], float).reshape(n_sig, 3)
    el = np.arcsin(np.clip(e[:, 2] / np.linalg.norm(e, axis=1), -1, 1))

    pairs, base, rows = [], [], []
    for k in range(1, n_ant):
        for s in ids:
            g = group_key(s, lam[col[s]])
            r = references.get(g)
            if r is None or r == s or r not in col or s in exclude:
                continue
            pairs.append((s, r))
            base.append(k)
            rows.append((k, col[s], col[r]))
    m = len(rows)
    # D maps the undifferenced vector (antenna-major: a * n_sig + i) to the double differences.
    D = np.zeros((m, n_ant * n_sig))
    for j, (k, i, r) in enumerate(rows):
        D[j, k * n_sig + i] += 1.0
        D[j, k * n_sig + r] -= 1.0
        D[j, i] -= 1.0
        D[j, r] += 1.0
    sig_ph = np.tile(elevation_sigma(el, noise.phase_a, noise.phase_b) / lam, n_ant)
    sig_pr = np.tile(elevation_sigma(el, noise.code_a, noise.code_b), n_ant)
    iref = np.array([r for _, _, r in rows], int)
    isig = np.array([i for _, i, _ in rows], int)
    cov_correlated = None
    if multipath is not None:
        sig_mp = np.tile(multipath.sigma(el)[1] / lam, n_ant)
        cov_correlated = (D * sig_mp ** 2) @ D.T
    return DoubleDifferences(
        pairs=pairs,
        baseline=np.array(base, int),
        wavelength=lam[isig] if m else np.zeros(0),
        phase=D @ ph.ravel(),
        code=D @ pr.ravel(),
        geometry=-(e[isig] - e[iref]) if m else np.zeros((0, 3)),
        cov_phase=(D * sig_ph ** 2) @ D.T,
        cov_code=(D * sig_pr ** 2) @ D.T,
        references=dict(references),
        cov_correlated=cov_correlated,
    )


def second_differences(dd_phase, wavelength, baseline_length):
    """The seeds' second differences S_i,ref = s_i - s_ref (extract_004 eq. 2.2.6).

    s_i is the direction cosine of the line of sight to satellite i with respect to the baseline,
    measured as a path difference (positive when the remote antenna is nearer the satellite),
    hence the sign flip from the RINEX phase convention: S = -λ DD / |b|. The result still holds
    the ambiguity λ N / |b|.

    Parameters
    ----------
    dd_phase : array_like
        DD carrier phase (cycles).
    wavelength : array_like
        (m).
    baseline_length : float
        |b| (m).
    """
    return -np.asarray(wavelength) * np.asarray(dd_phase) / baseline_length
