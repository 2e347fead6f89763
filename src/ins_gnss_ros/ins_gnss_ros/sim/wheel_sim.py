"""Wheel odometry of a car: the forward speed of the rear-axle centre from wheel-speed sensors.

Model, for output samples t_k = k T (T = 1 / rate):

    v_x(t) = (C_bn v^n + ω_eb^b × l^b)_x                  true forward speed of the point l^b
    d(t)   = ∫ (1 + k) (1 + σ(t)) v_x dt                   distance the wheels roll
    n_k    = floor(d(t_k) / tick)                          encoder counts of ``tick`` m each
    V_k    = (n_k − n_(k−1)) tick / T                      speed over [t_k − T, t_k]
    stamp_k = t_k + latency                                stamped on arrival over the bus

with k the scale-factor error (tyre radius), σ(t) the slip ratio (0 on a dry road; positive
while the driven wheels spin, negative while they lock under braking, −1 fully locked) and l^b
the axle centre relative to the IMU in base_link FLU. The counts quantise the distance, not the
speed: the quantisation errors of successive speeds cancel in their sum, as on a real
odometer. A speed is the mean over its interval, so it refers to t_k − T/2: a filter applies a
reading stamped t at t − (latency + T/2). A wheel odometry has no lateral or vertical sensor:
the constraint that they are zero holds at the axle (the car of
:class:`~ins_gnss_ros.sim.trajectory.CarMotion` slips nowhere, so a point straight below the
IMU keeps it up to the roll rate times the height).
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ins_gnss_ros.nav import earth
from ins_gnss_ros.nav.rotations import quat_to_dcm
from ins_gnss_ros.sim.trajectory import Trajectory


@dataclass(frozen=True)
class WheelSpec:
    """Wheel odometry of a car.

    Attributes
    ----------
    rate : float
        Output rate, Hz.
    scale_error : float
        Scale-factor error k of the distance (tyre radius), -.
    tick : float
        Distance per encoder count, m (0: no quantisation).
    latency : float
        Stamp minus the end of the speed's interval, s.
    slip_interval : float
        Mean time between slip events (Poisson), s (inf: none).
    slip_duration : tuple of 2 float
        Range of a slip event's duration, s (uniform).
    slip_ratio : tuple of 2 float
        Range of the magnitude of the slip ratio, - (uniform; spin or lock with equal chance).
    slip_min_speed : float
        Slip events happen only above this speed, m/s.
    lever_arm_b : ndarray, shape (3,)
        Odometry reference point (rear-axle centre) relative to the IMU, base_link FLU, m.
    """

    rate: float = 20.0
    scale_error: float = 0.0
    tick: float = 0.0
    latency: float = 0.0
    slip_interval: float = np.inf
    slip_duration: tuple = (0.3, 1.5)
    slip_ratio: tuple = (0.1, 0.3)
    slip_min_speed: float = 2.0
    lever_arm_b: np.ndarray = field(default_factory=lambda: np.zeros(3))


@dataclass
class WheelMeasurements:
    """Simulated wheel odometry.

    Attributes
    ----------
    t : ndarray, shape (n,)
        End of each speed's interval, s.
    stamp : ndarray, shape (n,)
        Message stamps, s (t + latency).
    speed : ndarray, shape (n,)
        Measured forward speed, m/s.
    true_speed : ndarray, shape (n,)
        True forward speed of the point at t, m/s.
    slipping : ndarray of bool, shape (n,)
        A slip event overlaps the speed's interval.
    """

    t: np.ndarray
    stamp: np.ndarray
    speed: np.ndarray
    true_speed: np.ndarray
    slipping: np.ndarray


def point_forward_speed(traj: Trajectory, lever_b) -> np.ndarray:
    """True forward speed (m/s) of a point fixed to the body at lever_b (FLU, m), per sample;
    the rotation relative to the Earth moves it (ω_eb = ω_ib − C_bn ω_ie)."""
    c_nb = quat_to_dcm(traj.q_nb)
    w_eb_b = traj.omega_ib_b - np.einsum("kji,kj->ki", c_nb, earth.earth_rate_enu(traj.lat))
    v_b = np.einsum("kji,kj->ki", c_nb, traj.v_enu) + np.cross(w_eb_b, lever_b)
    return v_b[:, 0]


def slip_ratio(t: np.ndarray, speed: np.ndarray, spec: WheelSpec,
               rng: np.random.Generator) -> np.ndarray:
    """Slip ratio σ at the samples t (s) of the trajectory: Poisson events of random length and
    ratio (sign: spin or lock) wherever the speed exceeds ``slip_min_speed`` at the start."""
    ratio = np.zeros(len(t))
    if not np.isfinite(spec.slip_interval):
        return ratio
    start = t[0] + rng.exponential(spec.slip_interval)
    while start < t[-1]:
        length = rng.uniform(*spec.slip_duration)
        value = rng.uniform(*spec.slip_ratio) * rng.choice([-1.0, 1.0])
        i = np.searchsorted(t, start)
        if i < len(t) and abs(speed[i]) > spec.slip_min_speed:
            ratio[(t >= start) & (t < start + length)] = value
        start += length + rng.exponential(spec.slip_interval)
    return ratio


def simulate_wheel(traj: Trajectory, spec: WheelSpec = WheelSpec(), seed: int = 0
                   ) -> WheelMeasurements:
    """Wheel odometry along a trajectory (module docstring).

    Parameters
    ----------
    traj : Trajectory
        Truth; its rate must be an integer multiple of ``spec.rate``.
    spec : WheelSpec
    seed : int
        Seed of the slip events.

    Returns
    -------
    WheelMeasurements
    """
    step = traj.decimation(spec.rate)
    rng = np.random.default_rng(seed)
    v_x = point_forward_speed(traj, np.asarray(spec.lever_arm_b, float))
    ratio = slip_ratio(traj.t, v_x, spec, rng)
    rolled = (1.0 + spec.scale_error) * (1.0 + ratio) * v_x
    # Trapezoid rule on the trajectory grid: exact enough at its rate (>= 200 Hz).
    d = np.concatenate([[0.0], np.cumsum(0.5 * (rolled[1:] + rolled[:-1]) * np.diff(traj.t))])
    idx = np.arange(step, len(traj), step)
    counted = np.floor(d[idx] / spec.tick) * spec.tick if spec.tick > 0.0 else d[idx]
    period = traj.t[idx[0]] - traj.t[0]
    speed = np.diff(np.concatenate([[0.0], counted])) / period
    slipping = np.array([ratio[i - step:i + 1].any() for i in idx])
    t = traj.t[idx]
    return WheelMeasurements(t, t + spec.latency, speed, v_x[idx], slipping)
