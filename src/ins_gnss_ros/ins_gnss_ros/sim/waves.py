"""Wave-induced ship motion: roll, pitch, yaw and heave as seeded sums of sinusoids.

The sea surface is a JONSWAP spectrum (Pierson–Moskowitz for γ = 1), as given in DNV-RP-C205
"Environmental conditions and environmental loads", §3.5.5. Each motion component is a
Gaussian process whose spectrum is the wave spectrum shaped by a second-order (mass-spring-
damper) response of the hull:

    S_j(ω) = |H_j(ω)|² (ω²/g)^{p_j} S_η(ω),   |H_j|² = 1 / ((1 − (ω/ω_j)²)² + (2 ζ_j ω/ω_j)²)

with p_j = 2 for the angular motions (driven by the wave slope k·η, k = ω²/g in deep water)
and p_j = 0 for heave (driven by the elevation η). Heave keeps the physical level that
results; the angular motions are scaled to configured standard deviations, because their
level depends on the hull far more than on this simple shaping (a real vessel's response
amplitude operators would replace it).

Each process is drawn as Σ a_i cos(ω_i t + φ_i) with a_i = √(2 S_j(ω_i) Δω) (the random-phase
model, e.g. Fossen, "Handbook of Marine Craft Hydrodynamics and Motion Control", §10.2.1), the
frequencies jittered inside their bins so that the record does not repeat. Its derivatives are
analytic, which the IMU simulation needs. The encounter-frequency shift of a moving vessel
is not modelled: the spectra are understood as already in encounter frequency.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

G0 = 9.80665  # m/s², standard gravity for the deep-water dispersion relation ω² = g k

#: Motion components, in the column order of :meth:`WaveMotion.evaluate`.
COMPONENTS = ("roll", "pitch", "yaw", "heave")


def jonswap(omega, hs: float, tp: float, gamma: float = 3.3):
    """JONSWAP wave-elevation spectrum (DNV-RP-C205 eqs. 3.5.3-3.5.5).

    Parameters
    ----------
    omega : array_like
        Angular frequency, rad/s (> 0).
    hs : float
        Significant wave height H_s = 4√m0, m.
    tp : float
        Peak period, s.
    gamma : float
        Peak enhancement factor; 1 gives the Pierson–Moskowitz spectrum.

    Returns
    -------
    ndarray
        Spectral density S_η(ω), m²·s/rad.
    """
    w = np.asarray(omega, float)
    wp = 2.0 * np.pi / tp
    s_pm = 5.0 / 16.0 * hs ** 2 * wp ** 4 * w ** -5 * np.exp(-1.25 * (w / wp) ** -4)
    sigma = np.where(w <= wp, 0.07, 0.09)
    a_gamma = 1.0 - 0.287 * np.log(gamma)  # normalisation keeping H_s (DNV eq. 3.5.6)
    return a_gamma * s_pm * gamma ** np.exp(-0.5 * ((w - wp) / (sigma * wp)) ** 2)


@dataclass(frozen=True)
class SeaState:
    """Sea state. Defaults: a moderate short-fetch lake sea (Lake Ladoga, seed 004 Lab 2).

    Attributes
    ----------
    hs : float
        Significant wave height, m.
    tp : float
        Peak period, s.
    gamma : float
        JONSWAP peak enhancement (1 = Pierson–Moskowitz).
    """

    hs: float = 1.5
    tp: float = 5.5
    gamma: float = 3.3


@dataclass(frozen=True)
class HullResponse:
    """Second-order response of the hull in roll, pitch, yaw and heave.

    Attributes
    ----------
    periods : tuple of 4 float
        Natural periods (s) in roll, pitch, yaw, heave. A large value makes the response a
        low-pass that passes the long waves only.
    damping : tuple of 4 float
        Damping ratios ζ.
    angle_std : tuple of 3 float
        Standard deviations imposed on roll, pitch, yaw, rad (defaults 3°, 1°, 0.5°: peaks of
        about ±9°, ±3°, ±1.5°).
    """

    periods: tuple = (7.0, 5.0, 20.0, 4.0)
    damping: tuple = (0.08, 0.4, 1.0, 0.75)
    angle_std: tuple = (np.deg2rad(3.0), np.deg2rad(1.0), np.deg2rad(0.5))


@dataclass
class WaveMotion:
    """Sum-of-sinusoids motion in roll, pitch, yaw (rad) and heave (m).

    Attributes
    ----------
    omega, amplitude, phase : ndarray, shape (4, k)
        Frequencies (rad/s), amplitudes (rad or m) and phases (rad) per component.
    """

    omega: np.ndarray
    amplitude: np.ndarray
    phase: np.ndarray

    @property
    def std(self) -> np.ndarray:
        """Standard deviation of each component, shape (4,)."""
        return np.sqrt(0.5 * np.sum(self.amplitude ** 2, axis=1))

    def evaluate(self, t, chunk: int = 65536):
        """Values, rates and accelerations at times t.

        Returns
        -------
        values, rates, accels : ndarray, shape (n, 4)
            Columns roll, pitch, yaw (rad, rad/s, rad/s²) and heave (m, m/s, m/s²; up).
        """
        t = np.asarray(t, float)
        out = np.zeros((3, len(t), 4))
        for s in range(0, len(t), chunk):
            tt = t[s:s + chunk, None, None]
            arg = self.omega * tt + self.phase          # (n, 4, k)
            c, sn = np.cos(arg), np.sin(arg)
            a, w = self.amplitude, self.omega
            out[0, s:s + chunk] = np.sum(a * c, axis=-1)
            out[1, s:s + chunk] = -np.sum(a * w * sn, axis=-1)
            out[2, s:s + chunk] = -np.sum(a * w * w * c, axis=-1)
        return out[0], out[1], out[2]


def response_spectrum(omega, sea: SeaState, hull: HullResponse):
    """Unscaled spectra of roll, pitch, yaw, heave, shape (4, n): the shaped wave spectrum."""
    w = np.asarray(omega, float)
    s_eta = jonswap(w, sea.hs, sea.tp, sea.gamma)
    out = np.empty((4,) + w.shape)
    for j in range(4):
        wn = 2.0 * np.pi / hull.periods[j]
        h2 = 1.0 / ((1.0 - (w / wn) ** 2) ** 2 + (2.0 * hull.damping[j] * w / wn) ** 2)
        slope = (w * w / G0) ** 2 if j < 3 else 1.0
        out[j] = h2 * slope * s_eta
    return out


def wave_motion(sea: SeaState, hull: HullResponse, rng: np.random.Generator,
                n_components: int = 32) -> WaveMotion:
    """Draw a seeded wave-motion realisation.

    Frequencies cover [0.4, 4] ω_p in equal bins, one jittered frequency per bin; phases are
    uniform. Roll, pitch and yaw are scaled to ``hull.angle_std``; heave keeps the level of
    the shaped elevation spectrum.

    Parameters
    ----------
    sea : SeaState
    hull : HullResponse
    rng : numpy.random.Generator
    n_components : int
        Sinusoids per motion component.

    Returns
    -------
    WaveMotion
    """
    wp = 2.0 * np.pi / sea.tp
    edges = np.linspace(0.4 * wp, 4.0 * wp, n_components + 1)
    d_omega = np.diff(edges)
    omega = edges[:-1] + d_omega * rng.uniform(size=(4, n_components))
    spec = np.stack([response_spectrum(omega[j], sea, hull)[j] for j in range(4)])
    amplitude = np.sqrt(2.0 * spec * d_omega)
    std = np.sqrt(0.5 * np.sum(amplitude ** 2, axis=1))
    amplitude[:3] *= (np.asarray(hull.angle_std) / std[:3])[:, None]
    phase = rng.uniform(0.0, 2.0 * np.pi, size=(4, n_components))
    return WaveMotion(omega, amplitude, phase)
