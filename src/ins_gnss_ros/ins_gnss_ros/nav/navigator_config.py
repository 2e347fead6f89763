"""Parameters of the navigator (:class:`~ins_gnss_ros.nav.navigator.Navigator`)."""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from .gating import DEFAULT_GATE_PROB


@dataclass
class NavigatorConfig:
    """Parameters of the offline navigator (all SI).

    Attributes
    ----------
    noise : FilterNoise
        IMU noise model (sensor_errors.filter_noise or hand-made).
    layout : str or tuple
        Error-model layout (error_model.LAYOUTS key or block names).
    extras : dict of str to ExtraState
        Extra filter blocks ("td", "mag").
    lever_arm_b : array_like, shape (3,)
        GNSS antenna relative to the IMU, FLU, m.
    lever_published_var : array_like, shape (3,)
        Variance of lever_arm_b per FLU axis that only the published position covariance
        carries (Navigator._published_var), m^2.
    cov_interval : float
        Covariance propagation interval, s.
    gate_prob : float or None
        Chi-square gate probability (None: no gating).
    max_reject_time : float
        After this long of continuous rejection of one measurement kind, force it in, s.
    floor_tau : float
        Time constant of the noise floor a forced kind keeps (:mod:`.integrity`): it
        decays by exp(-dt / floor_tau) over the time its measurements are accepted, s.
    degraded_ratio : float
        While a forced kind's floor exceeds degraded_ratio^2 times the measurement's own
        variance and the kind has not yet been accepted for confirm_time since it was last
        forced or rejected, the mode is DEAD_RECKONING (degraded: not confirmed by the aiding),
        -.
    confirm_time : float
        Time a forced kind must be accepted without being forced or rejected again to confirm
        the solution, s.
    suspect_time : float
        While an aiding kind has been rejected continuously for this long (and is still
        arriving), the mode is DEAD_RECKONING too: the INS or that aiding is wrong, s.
    gap_accel_sigma, gap_rate_sigma : float
        Over a bridged IMU gap (:meth:`Navigator.add_bridged_gap`): standard deviation of the
        difference between the held and the true specific force (m/s^2) and angular rate
        (rad/s), averaged over it.
    sigma_pos0, sigma_vel0, sigma_tilt0 : float
        Initial standard deviations at the first fix (m, m/s, rad).
    moving_accel_sigma : float
        A start on the move that no two receiver velocities measure: standard deviation of
        the vehicle's mean horizontal acceleration over the levelling, m/s^2
        (:meth:`Navigator._levelling_tilt_sigma`).
    sigma_yaw_align : float
        Floor of the heading standard deviation after motion alignment, rad.
    static_speed : float
        GNSS horizontal speed below which the vehicle counts as at rest while aligning, m/s.
    align_speed : float
        GNSS horizontal speed at which the heading is taken from the motion, m/s.
    level_time : float
        Minimum IMU data before the first fix for levelling, s.
    dr_timeout : float
        Without accepted aiding for this long the mode becomes DEAD_RECKONING, s.
    nhc_sigma : tuple of 2 float or None
        Non-holonomic constraint noise (lateral, vertical), m/s, applied every epoch while
        navigating (wheeled vehicles only); None disables it.
    nhc_learn : bool
        Without nhc_sigma: learn from the aided solution whether the vehicle moves like a
        wheeled one and apply the constraint then, with the noise learned
        (vehicle_constraint.py).
    nhc_interval : float
        Least time between two constraint updates, s.
    nhc_rate_arm : float
        Uncertainty of the distance to the constraint point along x, m: the lateral noise
        becomes hypot(sigma_lateral, nhc_rate_arm * yaw rate).
    nhc_lever_b : array_like, shape (3,)
        Point where the constraint holds (rear-axle centre) relative to the IMU, FLU, m.
    wheel_lever_b : array_like, shape (3,)
        Reference point of the wheel odometry (rear-axle centre) relative to the IMU, FLU, m.
    zaru_sigma : float or None
        Zero-angular-rate update at every GNSS velocity epoch at rest: noise added to the
        averaged gyro white noise, rad/s (vibration, body sway); None disables it.
    frozen_speed : float
        A fix identical to the previous one is rejected as frozen above this INS speed, and a
        velocity identical to the previous one above this speed of its own, m/s.
    history : float
        How far back a delayed measurement can still be applied at its epoch, s.
    checkpoint_interval : float
        Spacing of the snapshots kept for delayed measurements, s.
    store_covariance : bool
        Keep the full P, P_prior and Phi per epoch (needed by the RTS smoother).
    record : bool
        Keep the per-epoch outputs and every update result (:meth:`Navigator.output`). The
        ``ekf`` node runs for hours and turns it off: then only the updates of the last
        `history` seconds are kept (:meth:`Navigator.updates_since`) and memory stays bounded.
    compensated_increments : bool
        The increments given to :meth:`Navigator.add_imu` are already coning/sculling/rotation
        compensated (``imu/delta``, as the imu_preprocessor makes them and the strapdown node
        integrates them): they are mechanised as they are. False: raw sensor increments, whose
        second-order terms the navigator adds (one-sample algorithm).
    """

    noise: object
    layout: object = "15"
    extras: dict = field(default_factory=dict)
    lever_arm_b: np.ndarray = field(default_factory=lambda: np.zeros(3))
    lever_published_var: np.ndarray = field(default_factory=lambda: np.zeros(3))
    cov_interval: float = 0.1
    gate_prob: float | None = DEFAULT_GATE_PROB
    max_reject_time: float = 2.0
    floor_tau: float = 30.0
    confirm_time: float = 10.0
    degraded_ratio: float = 3.0
    suspect_time: float = 1.0
    gap_accel_sigma: float = 1.0
    gap_rate_sigma: float = np.deg2rad(5.0)
    sigma_pos0: float = 1.0
    sigma_vel0: float = 0.1
    sigma_tilt0: float = 0.02
    moving_accel_sigma: float = 1.0
    sigma_yaw_align: float = np.deg2rad(1.0)
    static_speed: float = 0.1
    align_speed: float = 0.5
    level_time: float = 1.0
    dr_timeout: float = 2.0
    nhc_sigma: tuple | None = None
    nhc_learn: bool = False
    nhc_lever_b: np.ndarray = field(default_factory=lambda: np.zeros(3))
    nhc_interval: float = 0.1
    nhc_rate_arm: float = 0.0
    wheel_lever_b: np.ndarray = field(default_factory=lambda: np.zeros(3))
    zaru_sigma: float | None = 1e-4
    frozen_speed: float = 0.5
    history: float = 3.0
    checkpoint_interval: float = 0.5
    store_covariance: bool = True
    record: bool = True
    compensated_increments: bool = False
