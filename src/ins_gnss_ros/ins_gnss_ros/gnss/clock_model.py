"""Receiver clock: offset, frequency offset and frequency drift rate, in range units.

Seed 004 §2.4 (receiver clock model, steering disabled):

    d(ΔD)/dt = ΔḊ + w1,     d(ΔḊ)/dt = k2 + w2,     dk2/dt = w3  (k2 a Wiener process)

with ΔD the clock offset [m], ΔḊ the frequency offset [m/s] and k2 the oscillator's frequency
drift rate (ageing) [m/s²]. The white noises follow from the oscillator's power-law model of
the fractional-frequency PSD, S_y(f) = h0 + h_-2 / f² (white frequency and random-walk frequency
noise; flicker h_-1 has no finite-state model and is left out). In range units (Brown & Hwang,
"Introduction to Random Signals and Applied Kalman Filtering", 4th ed., ch. 9, the GPS receiver
clock model; Groves, "Principles of GNSS, Inertial and Multisensor Integrated Navigation",
2nd ed., ch. 9, receiver clock states):

    S_w1 = c² h0 / 2            [m²/s]
    S_w2 = 2 π² c² h_-2         [m²/s³]

Discrete model: x = [ΔD, ΔḊ, k2], x_{k+1} = Φ x_k + w_k, with the exact transition

    Φ = [[1, T, T²/2], [0, 1, T], [0, 0, 1]]

and the exact process noise Q = ∫₀ᵀ Φ(s) diag(S_w1, S_w2, S_w3) Φ(s)ᵀ ds:

    Q = S_w1 [[T, 0, 0], [0, 0, 0], [0, 0, 0]]
      + S_w2 [[T³/3, T²/2, 0], [T²/2, T, 0], [0, 0, 0]]
      + S_w3 [[T⁵/20, T⁴/8, T³/6], [T⁴/8, T³/3, T²/2], [T³/6, T²/2, T]],

so that a simulated clock has the Allan variance σ_y²(τ) = h0/(2τ) + (2π²/3) h_-2 τ of its
oscillator whatever the step T.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .constants import C_LIGHT


@dataclass(frozen=True)
class OscillatorSpec:
    """Power-law noise of a receiver oscillator and its initial state.

    Attributes
    ----------
    h0 : float
        White frequency noise coefficient [s] (S_y = h0).
    h_2 : float
        Random-walk frequency noise coefficient h_-2 [1/s] (S_y = h_-2 / f²).
    aging_psd : float
        PSD of the drift-rate random walk w3 [m²/s⁵] (0: constant drift rate).
    offset0 : float
        Initial clock offset [s].
    drift0 : float
        Initial fractional frequency offset [s/s].
    drift_rate0 : float
        Initial frequency drift rate (ageing) [1/s].
    """

    h0: float = 2.0e-19
    h_2: float = 2.0e-20
    aging_psd: float = 0.0
    offset0: float = 1.0e-4
    drift0: float = 5.0e-8
    drift_rate0: float = 0.0


#: Typical oscillators (Brown & Hwang, 4th ed., ch. 9, table of clock Allan-variance
#: parameters): h0 [s], h_-2 [1/s].
TCXO = OscillatorSpec(h0=2.0e-19, h_2=2.0e-20)
OCXO = OscillatorSpec(h0=8.0e-20, h_2=4.0e-23)


def transition(dt: float) -> np.ndarray:
    """Exact 3x3 transition Φ of [offset m, drift m/s, drift rate m/s²] over ``dt`` [s]."""
    return np.array([[1.0, dt, 0.5 * dt * dt], [0.0, 1.0, dt], [0.0, 0.0, 1.0]])


def process_noise(spec: OscillatorSpec, dt: float) -> np.ndarray:
    """Exact 3x3 process noise covariance Q over ``dt`` [s], range units (module docstring)."""
    s1 = 0.5 * C_LIGHT ** 2 * spec.h0
    s2 = 2.0 * np.pi ** 2 * C_LIGHT ** 2 * spec.h_2
    s3 = spec.aging_psd
    t = dt
    q = np.zeros((3, 3))
    q[0, 0] = s1 * t
    q[:2, :2] += s2 * np.array([[t ** 3 / 3, t ** 2 / 2], [t ** 2 / 2, t]])
    q += s3 * np.array([[t ** 5 / 20, t ** 4 / 8, t ** 3 / 6],
                        [t ** 4 / 8, t ** 3 / 3, t ** 2 / 2],
                        [t ** 3 / 6, t ** 2 / 2, t]])
    return q


def allan_variance(spec: OscillatorSpec, tau):
    """Allan variance σ_y²(τ) of the oscillator's h0 and h_-2 terms (Brown & Hwang ch. 9;
    the flicker term 2 ln2 h_-1 is not modelled)."""
    tau = np.asarray(tau, float)
    return spec.h0 / (2.0 * tau) + (2.0 * np.pi ** 2 / 3.0) * spec.h_2 * tau


class ReceiverClock:
    """A running receiver clock: call :meth:`advance` with ascending times.

    Attributes
    ----------
    state : ndarray, shape (3,)
        Offset [m] (> 0: the receiver's time is ahead, pseudoranges are too long), drift [m/s]
        and drift rate [m/s²] at ``t``.
    t : float or None
        Time of ``state`` [s]; None before the first call.
    """

    def __init__(self, spec: OscillatorSpec, rng: np.random.Generator):
        self.spec = spec
        self.rng = rng
        self.state = np.array([spec.offset0, spec.drift0, spec.drift_rate0]) * C_LIGHT
        self.t = None
        self._chol = {}  # dt -> Cholesky factor of Q (constant steps reuse it)

    def advance(self, t: float) -> np.ndarray:
        """Propagate to time ``t`` [s] (the first call only fixes the time axis)."""
        if self.t is not None and t > self.t:
            dt = round(t - self.t, 9)
            chol = self._chol.get(dt)
            if chol is None:
                # A symmetric square root: Q is singular without ageing noise (no Cholesky).
                w, v = np.linalg.eigh(process_noise(self.spec, dt))
                chol = v * np.sqrt(np.clip(w, 0.0, None))
                self._chol[dt] = chol
            self.state = transition(t - self.t) @ self.state + chol @ self.rng.standard_normal(3)
        self.t = t
        return self.state


def simulate_clock(spec: OscillatorSpec, t, rng: np.random.Generator) -> np.ndarray:
    """Clock states at ascending times ``t`` [s]: ndarray (n, 3) of :attr:`ReceiverClock.state`."""
    clock = ReceiverClock(spec, rng)
    return np.array([clock.advance(tk).copy() for tk in np.asarray(t, float)])
