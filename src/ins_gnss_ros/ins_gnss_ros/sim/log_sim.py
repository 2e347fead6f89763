"""Ship's speed log: velocity through the water in body axes.

Seed 004 §2.8: the log reads V_L, the longitudinal component of the velocity relative to the
water; its error δV^L contains the sea current, the unmeasured transverse drift and instrument
errors. Model:

    v_w^b = C_bn (v^n − c^n(t)) + ω_eb^b × l^b              transducer velocity through water
    V_L   = (1 + k) v_w,x^b + b + η                            (longitudinal)
    V_T   = (1 + k) v_w,y^b + b + η                            (transverse, Doppler logs only)

with the current c^n(t) = c̄^n + a first-order Gauss–Markov deviation per horizontal axis
(slowly varying tidal/wind-driven drift), l^b the transducer lever arm in base_link, k the
scale-factor error, b a zero offset and η white noise. Body FLU: +y is to port.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from scipy.signal import lfilter

from ins_gnss_ros.nav import earth
from ins_gnss_ros.nav.rotations import quat_to_dcm
from ins_gnss_ros.sim.trajectory import Trajectory


@dataclass(frozen=True)
class CurrentModel:
    """Water current over ground.

    Attributes
    ----------
    mean_enu : ndarray, shape (3,)
        Mean current (velocity of the water), ENU, m/s.
    gm_sigma : float
        Standard deviation of the slowly varying part, per horizontal axis, m/s.
    gm_tau : float
        Its correlation time, s.
    """

    mean_enu: np.ndarray = field(default_factory=lambda: np.zeros(3))
    gm_sigma: float = 0.0
    gm_tau: float = 600.0


@dataclass(frozen=True)
class LogSpec:
    """Speed-log instrument.

    Attributes
    ----------
    rate : float
        Output rate, Hz (seed 004: 1–15 Hz over RS422).
    scale_error : float
        Scale-factor error k, dimensionless.
    offset : float
        Zero offset b, m/s.
    noise_std : float
        White noise per sample, m/s.
    lever_arm_b : ndarray, shape (3,)
        Transducer position relative to the IMU, base_link FLU, m.
    dual_axis : bool
        True for a two-axis (Doppler/correlation) log that also measures the transverse speed.
    """

    rate: float = 2.0
    scale_error: float = 0.0
    offset: float = 0.0
    noise_std: float = 0.0
    lever_arm_b: np.ndarray = field(default_factory=lambda: np.zeros(3))
    dual_axis: bool = False


@dataclass
class LogMeasurements:
    """Simulated speed-log output.

    Attributes
    ----------
    t : ndarray, shape (n,)
        Sample time, s.
    speed : ndarray, shape (n,)
        Longitudinal speed through water V_L, m/s.
    transverse : ndarray, shape (n,)
        Transverse speed through water (to port), m/s; NaN for a single-axis log.
    current_enu : ndarray, shape (n, 3)
        True current, m/s.
    water_velocity_b : ndarray, shape (n, 3)
        True velocity of the transducer through the water, body FLU, m/s.
    """

    t: np.ndarray
    speed: np.ndarray
    transverse: np.ndarray
    current_enu: np.ndarray
    water_velocity_b: np.ndarray


def simulate_current(t, model: CurrentModel, rng: np.random.Generator):
    """Current at uniformly spaced times t: the mean plus an exactly discretised first-order
    Gauss–Markov process per horizontal axis, x_k+1 = a x_k + w_k, a = exp(−Δt/τ),
    var w = σ²(1 − a²), started from its stationary distribution. Shape (n, 3), m/s."""
    dev = np.zeros((len(t), 3))
    if model.gm_sigma > 0.0 and len(t) > 1:
        a = np.exp(-(t[1] - t[0]) / model.gm_tau)
        w = model.gm_sigma * rng.standard_normal((len(t), 2))
        w[1:] *= np.sqrt(1.0 - a * a)
        dev[:, :2] = lfilter([1.0], [1.0, -a], w, axis=0)
    return np.asarray(model.mean_enu, float) + dev


def simulate_log(traj: Trajectory, current: CurrentModel = CurrentModel(),
                 spec: LogSpec = LogSpec(), seed: int = 0) -> LogMeasurements:
    """Speed-log output along a trajectory.

    Parameters
    ----------
    traj : Trajectory
        Truth; its rate must be an integer multiple of ``spec.rate``.
    current : CurrentModel
    spec : LogSpec
    seed : int
        Seed of the current variation and the noise.

    Returns
    -------
    LogMeasurements
    """
    idx = np.arange(0, len(traj), traj.decimation(spec.rate))
    rng = np.random.default_rng(seed)
    t = traj.t[idx]
    c_n = simulate_current(t, current, rng)
    c_nb = quat_to_dcm(traj.q_nb[idx])
    # Rotation of the hull relative to the Earth moves the transducer: ω_eb = ω_ib − C_bn ω_ie.
    w_ie_b = np.einsum("kji,kj->ki", c_nb, earth.earth_rate_enu(traj.lat[idx]))
    w_eb_b = traj.omega_ib_b[idx] - w_ie_b
    v_b = np.einsum("kji,kj->ki", c_nb, traj.v_enu[idx] - c_n) + np.cross(w_eb_b,
                                                                          spec.lever_arm_b)
    noise = spec.noise_std * rng.standard_normal((len(t), 2))
    meas = (1.0 + spec.scale_error) * v_b[:, :2] + spec.offset + noise
    transverse = meas[:, 1] if spec.dual_axis else np.full(len(t), np.nan)
    return LogMeasurements(t, meas[:, 0], transverse, c_n, v_b)
