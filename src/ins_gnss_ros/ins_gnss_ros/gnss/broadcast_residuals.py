"""How the simulated signal truth differs from the broadcast models a receiver corrects with.

Without these residuals the GNSS simulator's ionosphere, troposphere, orbits and clocks ARE the
models the receiver code subtracts (Klobuchar, Saastamoinen, the broadcast ephemeris), so a
receiver test carries no model error at all. Real receivers see (Misra and Enge, "Global
Positioning System", 2nd ed., sections 5.3-5.4 and table 5.2; Montenbruck et al., "Broadcast
versus precise ephemerides: a multi-GNSS perspective", GPS Solutions 19, 2015):

* ionosphere: the Klobuchar model removes roughly half of the delay (RMS). Here the true delay
  is the Klobuchar delay times ``iono_scale`` (2: the model removes half) times a factor
  1 + ``iono_satellite_sigma`` z per satellite (z standard normal, fixed per satellite: the
  pierce points see different electron contents than the model's single shell);
* troposphere: Saastamoinen with a standard atmosphere leaves a few centimetres to a decimetre
  of zenith (wet) delay; here a zenith residual of ``tropo_zenith_sigma`` per run, mapped with
  the model's own elevation dependence;
* orbit and satellite clock (signal-in-space range error, SISRE, about 1 m for GPS and
  Galileo broadcast): per satellite a range error A + B sin(2 pi t / T + phi), A and B normal
  with ``sisre_sigma`` / sqrt(2) each, T the orbital period (the radial orbit error and the
  clock error are dominated by once-per-revolution terms), phi uniform: smooth, with its exact
  rate in the Doppler.

Drawn once per satellite from the simulator's seed: the same seed gives the same residuals.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from .spp import ModelErrors

__all__ = ["BroadcastResiduals", "ResidualDraw"]

#: Orbital period of GPS (half a sidereal day) and Galileo (14 h 05 min), s.
ORBIT_PERIOD_S = {"G": 43_082.0, "E": 50_680.0}


@dataclass(frozen=True)
class BroadcastResiduals:
    """Sizes of the residuals (module docstring); all zero gives the broadcast models back.

    Attributes
    ----------
    iono_scale : float
        True ionospheric delay / Klobuchar delay, on average (-).
    iono_satellite_sigma : float
        Relative spread of that ratio between satellites (-).
    tropo_zenith_sigma : float
        Zenith troposphere residual, m.
    sisre_sigma : float
        Orbit + clock range error per satellite, RMS, m.
    """

    iono_scale: float = 2.0
    iono_satellite_sigma: float = 0.25
    tropo_zenith_sigma: float = 0.05
    sisre_sigma: float = 1.0

    def model_errors(self) -> ModelErrors:
        """The receiver's error budget for these residuals (its solutions' covariance, as a
        real receiver's accuracy estimate has one): the ionosphere's RMS fraction of the
        Klobuchar delay, sqrt((scale - 1)^2 + (scale sigma)^2), the zenith troposphere and the
        SISRE as drawn."""
        iono = math.hypot(self.iono_scale - 1.0, self.iono_scale * self.iono_satellite_sigma)
        return ModelErrors(iono, self.tropo_zenith_sigma, self.sisre_sigma)


class ResidualDraw:
    """One simulator's residuals: drawn per satellite on first use from ``rng``."""

    def __init__(self, sizes: BroadcastResiduals, rng: np.random.Generator):
        self.sizes, self.rng = sizes, rng
        self.tropo_zenith = float(sizes.tropo_zenith_sigma * rng.standard_normal())
        self._satellites: dict[str, tuple[float, float, float, float]] = {}

    def _draw(self, sat_id: str):
        if sat_id not in self._satellites:
            s, rng = self.sizes, self.rng
            a, b = s.sisre_sigma / math.sqrt(2.0) * rng.standard_normal(2)
            phase = rng.uniform(0.0, 2.0 * math.pi)
            iono = s.iono_scale * (1.0 + s.iono_satellite_sigma * rng.standard_normal())
            self._satellites[sat_id] = (iono, float(a), float(b), phase)
        return self._satellites[sat_id]

    def ionosphere(self, sat_id: str, klobuchar_delay: float) -> float:
        """True ionospheric delay of a satellite whose Klobuchar delay is given, m."""
        return self._draw(sat_id)[0] * klobuchar_delay

    def troposphere(self, model_delay: float, model_zenith: float) -> float:
        """True tropospheric delay, m: the model's plus the zenith residual, mapped as the
        model maps its own zenith delay (``model_delay / model_zenith``)."""
        return model_delay + self.tropo_zenith * model_delay / model_zenith

    def orbit_clock(self, sat_id: str, t_gps: float) -> tuple[float, float]:
        """Range error of the broadcast orbit and clock (true minus broadcast range, m) and its
        rate (m/s) at GPS time ``t_gps``."""
        _, a, b, phase = self._draw(sat_id)
        w = 2.0 * math.pi / ORBIT_PERIOD_S.get(sat_id[0], ORBIT_PERIOD_S["G"])
        return a + b * math.sin(w * t_gps + phase), b * w * math.cos(w * t_gps + phase)
