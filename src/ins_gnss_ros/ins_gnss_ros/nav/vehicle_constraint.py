"""The non-holonomic constraint, learned from the aided solution instead of configured.

A wheeled vehicle moves along one axis of its body: its lateral and vertical velocities are zero
but for side slip, suspension travel and the yaw rate times the distance to the rear axle (the
constraint of Sukkarieh, Nebot and Durrant-Whyte, IEEE Trans. Robotics and Automation 15(3),
1999; Shin, "Estimation techniques for low-cost inertial navigation", UCGE report 20219, 2005,
section 5.4). Used as a measurement it bounds the drift of a MEMS INS in a GNSS outage (the real
car drive with config/default.yaml: 6.7 m RMS of the per-outage maximum without it, 3.5 m with
it), but only a profile knows whether the IMU is on wheels and how it is mounted, and a ship's
sway and heave, a walker's or an aircraft's motion break it.

Both can be seen while GNSS aids the solution, in the body-axes velocity ``v_b = C_bn v`` of
the navigating solution. :class:`LearnedConstraint` keeps its second moment ``E[v_b v_b^T]``
and the body's mean up direction over the time moving faster than ``MIN_SPEED`` (forgetting
with ``MEMORY_S`` of moving time, so that a vehicle that starts to slide stops being
constrained). The principal axis of the moment is the direction of travel in the IMU's axes,
whatever the mounting (a car's roof IMU in its own axes, yawed 175 deg and pitched 7 deg, moves
along it as well as one mounted square); the lateral axis is perpendicular to it and to up, the
vertical one to both. After ``LEARN_S`` s of motion, a body whose lateral and vertical RMS both
stay within ``ENABLE_RMS`` is constrained on those axes, with ``SIGMA_FACTOR`` times the measured
RMS as the noise (not below ``SIGMA_FLOOR``): the constraint then says no more than the aided
solution showed. The axes are kept from then on, and the filter estimates how far the vehicle's
lie from them (the "nhc" boresight state, ``BORESIGHT_SIGMA_DEG``): learned from the solution,
they carry its attitude error of the time, which a constraint on them as exact would hold with
confidence (a simulated car: heading 2.2 deg off, attitude NEES 162; with the state 1.1 deg,
4.0). The velocity across the boresight-turned axes beyond ``DISABLE_RMS`` over
``RELEASE_MEMORY_S`` of motion releases it again.

Until the constraint has decided, a heading aligned on the course over ground (a start on the
move without a heading source: alignment.yaw_error_from_course) assumes the body x axis along
the motion, within ``alignment.SIDE_SLIP_SIGMA``. :func:`hold_side_slip` keeps that assumption
for those first seconds as a lateral constraint on the body axes with the slip as the
boresight yaw, a random walk of ``SLIP_RATE``: the gyros' z bias then shows in the yaw's drift
from the course in straight driving. Without it the default profile's gyro-bias uncertainty
(then 3 deg/s) let the yaw sigma of a simulated rolling start grow to 28 deg in 15 s, where the
linearised filter ran the yaw 95 deg off (docs/results/product_path.md, "2026-12-06 (session
34)").
"""
from __future__ import annotations

import math

import numpy as np

from .rotations import quat_to_dcm

#: Horizontal speed above which the body velocity is learned from, m/s: slower, the velocity's
#: direction is the GNSS velocity noise's.
MIN_SPEED = 1.0
#: Moving time learned from before the first decision, s.
LEARN_S = 30.0
#: Time constant of the forgetting, s of moving time.
MEMORY_S = 300.0
#: Lateral and vertical body-velocity RMS within which the body counts as on wheels, m/s (a car:
#: ~0.1; a ship's sway and heave, a hand-held receiver: beyond).
ENABLE_RMS = 0.3
#: RMS across the kept (and boresight-turned) axes beyond which a constrained body is released
#: again, m/s, and the moving time it is taken over, s.
DISABLE_RMS = 0.45
RELEASE_MEMORY_S = 60.0
#: Constraint noise per measured RMS, and its least value, m/s.
SIGMA_FACTOR = 2.0
SIGMA_FLOOR = 0.1
#: Longest time one solution stands for (the first after an outage or a gap), s.
MAX_STEP_S = 1.0
#: Angle between the direction of travel and the body x axis beyond which /diagnostics says
#: which mounting would align them, deg.
MOUNTING_HINT_DEG = 3.0
#: Initial sigma of the filter's boresight state ("nhc": pitch and yaw of the vehicle's axes
#: from the learned ones), deg: the solution's attitude error when they were learned.
BORESIGHT_SIGMA_DEG = 3.0
#: The held side slip (:func:`hold_side_slip`): its random walk, rad/sqrt(s) (a car's slip
#: changes by a degree or two over a turn); the lateral constraint's noise, m/s, widened by
#: the yaw rate times ``SLIP_RATE_ARM`` m (an IMU up to that far from the rear axle slips
#: sideways in turns). It is applied at the speeds a course aligns at (the navigator's
#: ``align_speed``): a slow robot's yaw has nothing else to hold it (above 3 m/s only, a
#: consumer unit's robot with receiver velocities ran its heading 180 deg off,
#: docs/results/product_path.md "2026-12-07 (session 39)"); a walker's body, turned against
#: its course, rejects it, which ends the hold.
SLIP_RATE = np.radians(1.0)
SLIP_HOLD_SIGMA = 0.5
SLIP_RATE_ARM = 2.0
#: The largest share of the yaw variance the held slip takes: a yaw aligned with a sigma near
#: the slip's keeps a part of its error its own, so that P stays positive definite.
SLIP_SHARE = 0.9
#: The held slip's own uncertainty beyond the yaw's, rad.
SLIP_OWN_SIGMA = np.radians(0.5)


class LearnedConstraint:
    """Learns whether the vehicle moves like a wheeled one, along which body axis, and the
    constraint's noise.

    Attributes
    ----------
    axes : ndarray, shape (3, 3) or None
        Rows: the vehicle's forward, lateral and vertical axes (unit vectors in the body axes)
        once constrained; kept from then on, the filter's boresight state ("nhc",
        ``BORESIGHT_SIGMA_DEG``) estimating how far the true ones lie from them.
    sigma : tuple of 2 float or None
        Their constraint noise, m/s, once constrained.
    """

    def __init__(self):
        self.moment = np.zeros((3, 3))  # E[v_b v_b^T], (m/s)^2
        self.mean_v = np.zeros(3)       # E[v_b]: which way along the axis is forward
        self.up = np.zeros(3)           # E[up in body axes]
        self.moving = 0.0               # moving time learned from, s
        self.last_t = -np.inf
        self.axes = self.sigma = None
        self.across = np.zeros(2)       # mean square across the kept axes, once constrained

    def add(self, t: float, v_enu: np.ndarray, q_nb: np.ndarray,
            boresight: np.ndarray = np.zeros(2)) -> None:
        """Learn from the navigating, aided solution at time t (s), standing for the time since
        the last one it was given (at most ``MAX_STEP_S``); ``boresight`` is the filter's
        estimate of the vehicle axes' pitch and yaw from the kept ones, rad.

        Epochs at or before the last learned one are passed over: a delayed measurement re-runs
        the filter over them, and learning them twice would count them twice.
        """
        if t <= self.last_t:
            return
        # the first one stands for no time: nothing was learned before it
        dt = min(t - self.last_t, MAX_STEP_S) if math.isfinite(self.last_t) else 0.0
        self.last_t = t
        if np.hypot(v_enu[0], v_enu[1]) < MIN_SPEED:
            return
        C = quat_to_dcm(q_nb)
        v_b = C.T @ v_enu
        weight = -np.expm1(-dt / MEMORY_S)
        self.moment += weight * (np.outer(v_b, v_b) - self.moment)
        self.mean_v += weight * (v_b - self.mean_v)
        self.up += weight * (C[2] - self.up)  # C^T e_U: the third row
        self.moving += dt
        if self.moving < LEARN_S:
            return
        # The axes are learned from the solution, whose heading error at the time turns them
        # as a mounting would: once constrained they are kept with their noise, and the
        # boresight state takes that error (learning them on from a solution the constraint
        # itself pulls would chase it); the release is judged across the axes as the filter
        # corrects them.
        if self.axes is None:
            axes = self.learned()
            rms = self.rms(axes)
            if np.all(rms <= ENABLE_RMS):
                self.axes, self.sigma = axes, tuple(np.maximum(SIGMA_FACTOR * rms, SIGMA_FLOOR))
                self.across = rms ** 2
            return
        across = turned(self.axes, boresight)[1:] @ v_b
        self.across += -np.expm1(-dt / RELEASE_MEMORY_S) * (across ** 2 - self.across)
        if np.any(self.across > DISABLE_RMS ** 2):
            self.axes = self.sigma = None

    def learned(self) -> np.ndarray:
        """The vehicle's axes learned so far (3, 3): rows forward (the direction of travel in the
        body axes), lateral (across it and up) and vertical."""
        _, vectors = np.linalg.eigh(self.moment)
        forward = vectors[:, -1] * np.sign(vectors[:, -1] @ self.mean_v or 1.0)
        lateral = np.cross(self.up, forward)
        lateral /= np.linalg.norm(lateral)
        return np.array([forward, lateral, np.cross(forward, lateral)])

    def rms(self, axes) -> np.ndarray:
        """RMS of the body velocity along the lateral and vertical rows of ``axes`` (2,), m/s; the
        exponential means started at zero, their bias divided out."""
        mean_square = np.einsum("ij,jk,ik->i", axes[1:], self.moment, axes[1:])
        return np.sqrt(mean_square / -np.expm1(-self.moving / MEMORY_S))

    def summary(self) -> str:
        """What was learned, for /diagnostics."""
        if self.moving < LEARN_S:
            return (f"learning the body's lateral and vertical velocity: {self.moving:.0f} of "
                    f"{LEARN_S:.0f} s moving above {MIN_SPEED:g} m/s with GNSS")
        if self.axes is None:
            axes = self.learned()
            f, rms = axes[0], self.rms(axes)
        else:
            f, rms = self.axes[0], np.sqrt(self.across)
        seen = (f"travel along body ({f[0]:+.3f}, {f[1]:+.3f}, {f[2]:+.3f}), lateral "
                f"{rms[0]:.2f}, vertical {rms[1]:.2f} m/s RMS")
        if self.sigma is None:
            return f"off: {seen} (a wheeled vehicle stays within {ENABLE_RMS:g})"
        summary = f"on: {seen}, sigma {self.sigma[0]:.2f} / {self.sigma[1]:.2f} m/s"
        if f[0] < np.cos(np.radians(MOUNTING_HINT_DEG)):
            pitch, yaw = np.degrees(mounting_from_travel(f))
            summary += (f"; imu_preprocessor mounting_rpy_deg [0, {pitch:.1f}, {yaw:.1f}] would "
                        "put the travel on base_link's x axis (the roll is not seen in it)")
        return summary


def turned(axes: np.ndarray, boresight) -> np.ndarray:
    """The vehicle axes (rows forward, lateral, vertical) turned by the small boresight angles
    (pitch, yaw), as the non-holonomic measurement model turns them
    (:func:`ins_gnss_ros.nav.measurements.nonholonomic`)."""
    theta, psi = boresight
    forward, lateral, vertical = axes
    return np.array([forward, lateral - psi * forward, vertical + theta * forward])


def mounting_from_travel(forward: np.ndarray):
    """Pitch and yaw (rad) of the mounting C_bs = Rz(yaw) Ry(pitch) (the imu_preprocessor's
    ``mounting_rpy_deg`` with roll 0, which the direction of travel cannot show) that puts the
    direction of travel ``forward`` (unit, the IMU's axes) on base_link's x axis:
    C_bs^T e_x = (cos p cos y, -sin y, sin p cos y), with |pitch| <= 90 deg."""
    cos_yaw = np.copysign(np.hypot(forward[0], forward[2]), forward[0])
    pitch = np.arctan2(forward[2] / cos_yaw, forward[0] / cos_yaw)
    return pitch, np.arctan2(-forward[1], cos_yaw)


def hold_side_slip(P, yaw, slip, slip_var):
    """The covariance P with the boresight-yaw state (index ``slip``) made the side slip a
    course alignment took into the yaw error (index ``yaw``) with variance ``slip_var``
    (alignment.SIDE_SLIP_SIGMA^2, rad^2): the yaw error then holds minus the slip (the body x
    axis was put on the course), so the slip is regressed on the yaw error,
    cov(slip, x) = -c P[yaw, x] / P[yaw, yaw] with c = slip_var (at most ``SLIP_SHARE`` of the
    yaw's variance), plus its own ``SLIP_OWN_SIGMA``. A lateral constraint on the body axes
    turned by that boresight then tells nothing of the yaw at first (the two errors cancel in
    it), and the yaw's drift against the course thereafter."""
    P = P.copy()
    var_yaw = P[yaw, yaw]
    c = min(slip_var, SLIP_SHARE * var_yaw)
    P[slip, :] = -c / var_yaw * P[yaw, :]
    P[:, slip] = P[slip, :]
    P[slip, slip] = slip_var + SLIP_OWN_SIGMA ** 2
    return P

