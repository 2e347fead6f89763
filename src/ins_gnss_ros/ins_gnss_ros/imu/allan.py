"""Allan-variance characterisation of inertial-sensor noise from a static recording.

IEEE Std 952-1997 (Annex C) and Groves §4.4.3/§14.2.5: for rate-type data (gyro rate, specific
force) the Allan variance of the independent noise processes adds up as

    σ²(τ) = N²/τ  +  (2 ln2 / π) B²  +  K² τ / 3

with N the white-noise density (angle/velocity random walk, unit·√s = unit/√Hz; σ = N at
τ = 1 s on the slope −1/2), B the bias instability (flicker floor, σ_min = 0.664 B), K the rate
(or acceleration) random walk (slope +1/2, σ = K at τ = 3 s). Because the model is linear in
(N², B², K²), the three coefficients are fitted together by non-negative least squares on the
overlapping Allan deviation (computed with allantools), each point weighted by its relative
accuracy; this uses the whole curve instead of reading single points off the slopes.
"""
from __future__ import annotations

from dataclasses import dataclass

import allantools
import numpy as np
from scipy.optimize import nnls

#: σ² of flicker noise per B² (IEEE 952 Table C.1): σ_floor = sqrt(2 ln2 / π) B = 0.664 B.
FLICKER_FACTOR = 2.0 * np.log(2.0) / np.pi


@dataclass(frozen=True)
class NoiseCoefficients:
    """Noise coefficients of one sensor axis (units for a gyro in rad/s; accelerometer m/s²).

    Attributes
    ----------
    white : float
        N, white-noise density: ARW (rad/s/√Hz = rad/√s) or VRW (m/s²/√Hz = m/s/√s).
    bias_instability : float
        B, rad/s or m/s².
    random_walk : float
        K, rate random walk (rad/s/√s) or acceleration random walk (m/s²/√s).
    tau_min : float
        τ at the minimum of the measured deviation, s: a correlation-time hint for a Gauss-Markov
        bias model.
    """

    white: float
    bias_instability: float
    random_walk: float
    tau_min: float


def allan_deviation(y, rate_hz: float):
    """Overlapping Allan deviation of rate-type samples at octave-spaced τ.

    Parameters
    ----------
    y : array_like, shape (n,)
        Samples of one axis (rate, not increments), any unit.
    rate_hz : float
        Sample rate, Hz.

    Returns
    -------
    tau, adev, adev_err, n_clusters : ndarray
        Averaging times (s), deviations (unit), 1-σ errors and the number of terms per τ.
    """
    tau, adev, err, n = allantools.oadev(np.asarray(y, float), rate=rate_hz,
                                         data_type="freq", taus="octave")
    return tau, adev, err, n


def fit_noise(tau, adev, duration: float) -> NoiseCoefficients:
    """Fit white, flicker and random-walk coefficients to an Allan-deviation curve.

    Parameters
    ----------
    tau, adev : array_like
        As returned by :func:`allan_deviation`.
    duration : float
        Length of the recording, s.
    """
    tau, adev = np.asarray(tau, float), np.asarray(adev, float)
    # Above T/10 fewer than ten independent clusters remain and the deviation is unreliable
    # (and biased low for band-limited noise).
    keep = (tau <= duration / 10.0) & (adev > 0)
    tau, adev = tau[keep], adev[keep]
    design = np.column_stack([1.0 / tau, np.full_like(tau, FLICKER_FACTOR), tau / 3.0])
    # Relative residuals of σ², each weighted by its relative accuracy, which goes as
    # sqrt(number of independent clusters T/τ) (IEEE 952 Annex C.2).
    w = np.sqrt(duration / tau) / adev ** 2
    coef, _ = nnls(design * w[:, None], adev ** 2 * w)
    return NoiseCoefficients(white=float(np.sqrt(coef[0])),
                             bias_instability=float(np.sqrt(coef[1])),
                             random_walk=float(np.sqrt(coef[2])),
                             tau_min=float(tau[np.argmin(adev)]))


def characterise(samples, rate_hz: float) -> list[NoiseCoefficients]:
    """Noise coefficients of every column of a static recording, shape (n, axes)."""
    samples = np.atleast_2d(np.asarray(samples, float).T).T
    out = []
    for axis in samples.T:
        tau, adev, _, _ = allan_deviation(axis - axis.mean(), rate_hz)
        out.append(fit_noise(tau, adev, len(axis) / rate_hz))
    return out


def noise_section(gyro: list[NoiseCoefficients], accel: list[NoiseCoefficients]) -> dict:
    """The ``imu_noise`` section of a parameter file: per-axis values and their RMS (SI units).

    Keys: gyro_noise_density (rad/s/√Hz), gyro_bias_instability (rad/s), gyro_random_walk
    (rad/s/√s), gyro_correlation_time (s), and the accel_* equivalents in m/s² units.
    """
    out = {}
    for name, coeffs in (("gyro", gyro), ("accel", accel)):
        for key, attr in (("noise_density", "white"), ("bias_instability", "bias_instability"),
                          ("random_walk", "random_walk"), ("correlation_time", "tau_min")):
            out[f"{name}_{key}"] = [float(getattr(c, attr)) for c in coeffs]
    return {"imu_noise": out}
