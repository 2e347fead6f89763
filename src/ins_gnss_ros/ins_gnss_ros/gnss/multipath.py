"""Elevation-dependent multipath on code and carrier phase.

Multipath is the sum of reflected signals; its error on one receiver antenna and satellite varies
with the geometry, so it is correlated in time and grows as the satellite sinks (ground and
vehicle reflections reach the antenna at low elevation, where the antenna gain pattern also
rejects them least). Model, per antenna, satellite and observable (independent of each other):

    m(t) = σ(E(t)) u(t),     σ(E) = σ_0 exp(-E / E_0),

u a unit-variance first-order Gauss-Markov process with correlation time τ (Groves, "Principles
of GNSS, Inertial and Multisensor Integrated Navigation", 2nd ed., ch. 9: code multipath of
metres at low elevation, carrier-phase multipath below a quarter wavelength, correlation times
of seconds to minutes depending on the platform's motion). u is discretised exactly,

    u_{k+1} = a u_k + sqrt(1 - a²) n_k,    a = exp(-Δt / τ),    n_k ~ N(0, 1),

and started from its stationary distribution; scaling the unit process by σ(E) keeps the error
continuous while the elevation changes. Code and phase have separate σ_0 and τ (the phase error
is bounded by λ/4 physically: keep σ_0 well below it).
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class MultipathModel:
    """Parameters of the multipath error of the module's model.

    Attributes
    ----------
    code_sigma0, phase_sigma0 : float
        σ_0, the code and the phase multipath σ at zero elevation [m].
    elevation_scale : float
        E_0 [rad]: σ falls by e every E_0 of elevation.
    code_tau, phase_tau : float
        Correlation times [s].
    """

    code_sigma0: float = 1.0
    phase_sigma0: float = 0.01
    elevation_scale: float = math.radians(20.0)
    code_tau: float = 30.0
    phase_tau: float = 30.0

    def sigma(self, elevation):
        """(code σ [m], phase σ [m]) at ``elevation`` [rad] (negative elevations clipped to 0)."""
        scale = np.exp(-np.maximum(elevation, 0.0) / self.elevation_scale)
        return self.code_sigma0 * scale, self.phase_sigma0 * scale


class MultipathProcess:
    """Running multipath errors of many (antenna, satellite) channels, all with one model.

    A channel starts (from the stationary distribution) the first time it is asked for and
    continues from its last value; :meth:`reset` forgets a channel (e.g. after loss of signal).
    """

    def __init__(self, model: MultipathModel, rng: np.random.Generator):
        self.model = model
        self.rng = rng
        self._state = {}  # key -> (t, u_code, u_phase)

    def reset(self, key) -> None:
        self._state.pop(key, None)

    def step(self, key, t: float, elevation: float):
        """Code and phase multipath [m] of channel ``key`` at time ``t`` [s]."""
        previous = self._state.get(key)
        n = self.rng.standard_normal(2)
        if previous is None:
            u = n
        else:
            t0, u0 = previous
            a = np.exp(-(t - t0) / np.array([self.model.code_tau, self.model.phase_tau]))
            u = a * u0 + np.sqrt(1.0 - a * a) * n
        self._state[key] = (t, u)
        code_sigma, phase_sigma = self.model.sigma(elevation)
        return float(code_sigma * u[0]), float(phase_sigma * u[1])
