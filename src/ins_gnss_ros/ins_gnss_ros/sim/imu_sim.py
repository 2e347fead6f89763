"""Noisy IMU from a truth trajectory.

The ideal increments of :class:`~ins_gnss_ros.sim.trajectory.Trajectory` pass through, in the
order a real sensor applies them:

1. the error processes of :mod:`ins_gnss_ros.nav.sensor_errors` (turn-on bias, Gauss–Markov
   and random-walk in-run bias, scale factor and axis non-orthogonality, gyro g-sensitivity,
   white noise; seed 001 B2.5 model ω* = (E + K_g) ω + b_g + η_g, a* = (E + K_a) a + b_a + η_a);
2. saturation at the measurement range, applied to the interval-mean rate (the increments do not
   resolve what happens inside one interval);
3. quantisation of the increments with the remainder carried to the next sample, as an
   integrating sensor (pulse-counting FOG/RLG, or a MEMS part's accumulating decimation
   filter) does: the quantisation error does not accumulate in the summed angle and velocity.

Outputs are increments (Δθ, Δv per interval, for ``imu/delta``) and the matching raw rates
ω = Δθ/Δt, f = Δv/Δt (interval means, for ``imu/data_raw`` sensor_msgs/Imu), stamped at the end
of each interval. The same seed gives the identical output.
"""
from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from ins_gnss_ros.nav.sensor_errors import ImuErrorSimulator, ImuGrade
from ins_gnss_ros.sim.trajectory import Trajectory


@dataclass(frozen=True)
class ImuSpec:
    """An IMU: its error budget plus range and resolution.

    Attributes
    ----------
    grade : ImuGrade
        Error processes (nav.sensor_errors presets or custom).
    rate : float
        Output rate, Hz; the trajectory rate must be an integer multiple of it.
    gyro_range : float
        Gyro measurement range ±, rad/s (ADIS16405: ±300 °/s; seed 004 ISON-2: ±150 °/s).
    accel_range : float
        Accelerometer range ±, m/s² (ADIS16405: ±18 g; ISON-2: ±30 m/s²).
    gyro_quantum : float
        Angle increment resolution, rad (0: none).
    accel_quantum : float
        Velocity increment resolution, m/s (0: none).
    """

    grade: ImuGrade
    rate: float = 200.0
    gyro_range: float = np.deg2rad(300.0)
    accel_range: float = 18.0 * 9.80665
    gyro_quantum: float = 0.0
    accel_quantum: float = 0.0


@dataclass
class ImuMeasurements:
    """Simulated IMU output and the true sensor errors behind it.

    Sample k covers [t[k] − dt, t[k]] of the trajectory.

    Attributes
    ----------
    t : ndarray, shape (n,)
        Stamp (end of the interval), s.
    dt : float
        Interval, s.
    dtheta, dv : ndarray, shape (n, 3)
        Measured angle (rad) and velocity (m/s) increments, body FLU.
    gyro, accel : ndarray, shape (n, 3)
        Interval-mean angular rate (rad/s) and specific force (m/s²), body FLU.
    gyro_bias, accel_bias : ndarray, shape (n, 3)
        True total bias (turn-on + Gauss–Markov + random walk) during each interval,
        rad/s and m/s², for judging a filter's bias estimates.
    gyro_matrix, accel_matrix : ndarray, shape (3, 3)
        True scale-factor + non-orthogonality error matrices (measured = (I + M) true + ...).
    g_sensitivity : ndarray, shape (3, 3)
        True gyro g-sensitivity, rad/s per m/s².
    """

    t: np.ndarray
    dt: float
    dtheta: np.ndarray
    dv: np.ndarray
    gyro: np.ndarray
    accel: np.ndarray
    gyro_bias: np.ndarray
    accel_bias: np.ndarray
    gyro_matrix: np.ndarray
    accel_matrix: np.ndarray
    g_sensitivity: np.ndarray


def decimate_increments(x, factor: int):
    """Sum consecutive blocks of ``factor`` increments (exact: the integrals add), (n, 3)."""
    n = len(x) // factor
    return x[:n * factor].reshape(n, factor, -1).sum(axis=1)


def quantize(x, quantum: float):
    """Quantise a sequence of increments, carrying each remainder into the next sample.

    Parameters
    ----------
    x : ndarray, shape (n, 3)
    quantum : float
        Resolution; 0 returns x unchanged.

    Returns
    -------
    ndarray, shape (n, 3)
        Multiples of ``quantum`` whose running sum stays within quantum/2 of that of x.
    """
    if quantum <= 0.0:
        return x.copy()
    # Quantising the running sum and differencing is the same as carrying the remainder.
    counts = np.round(np.cumsum(x, axis=0) / quantum)
    return np.diff(counts, axis=0, prepend=0.0) * quantum


def simulate_imu(traj: Trajectory, spec: ImuSpec, seed: int) -> ImuMeasurements:
    """Measured IMU output along a trajectory.

    Parameters
    ----------
    traj : Trajectory
        Truth with ideal increments; its rate must be an integer multiple of ``spec.rate``.
    spec : ImuSpec
    seed : int
        Seed of all random draws (turn-on errors, in-run processes, noise).

    Returns
    -------
    ImuMeasurements
    """
    factor = traj.decimation(spec.rate)
    dt = traj.dt * factor
    dtheta = decimate_increments(traj.dtheta, factor)
    dv = decimate_increments(traj.dv, factor)

    errors = ImuErrorSimulator(spec.grade, dt, np.random.default_rng(seed))
    dtheta_m, dv_m = (x[0] for x in errors.corrupt(dtheta, dv))
    # True bias sequence: an identically seeded simulator without white noise makes the same
    # draws in the same order, and on zero input it outputs exactly bias·dt.
    quiet = replace(spec.grade, gyro=replace(spec.grade.gyro, white_density=0.0),
                    accel=replace(spec.grade.accel, white_density=0.0))
    zero = np.zeros_like(dtheta)
    bias_g, bias_a = (x[0] / dt for x in ImuErrorSimulator(
        quiet, dt, np.random.default_rng(seed)).corrupt(zero, zero))

    dtheta_m = quantize(np.clip(dtheta_m, -spec.gyro_range * dt, spec.gyro_range * dt),
                        spec.gyro_quantum)
    dv_m = quantize(np.clip(dv_m, -spec.accel_range * dt, spec.accel_range * dt),
                    spec.accel_quantum)
    t = traj.t[0] + dt * np.arange(1, len(dtheta) + 1)
    return ImuMeasurements(t, dt, dtheta_m, dv_m, dtheta_m / dt, dv_m / dt, bias_g, bias_a,
                           errors.gyro.matrix[0], errors.accel.matrix[0],
                           errors.g_sensitivity[0])
