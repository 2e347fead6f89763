"""The non-holonomic constraint, learned from the aided solution instead of configured.

A wheeled vehicle moves along its body x axis: the lateral and vertical velocities of its body
are zero but for side slip, suspension travel and the yaw rate times the distance to the rear
axle (the constraint of Sukkarieh, Nebot and Durrant-Whyte, IEEE Trans. Robotics and
Automation 15(3), 1999; Shin, "Estimation techniques for low-cost inertial navigation", UCGE
report 20219, 2005, section 5.4). Used as a measurement, it bounds the drift of a MEMS INS in a
GNSS outage (the real car drive with config/default.yaml: 6.7 m RMS of the per-outage maximum
without it, 2.9 m with it), but only a profile knows whether the IMU is on wheels, and a ship's
sway and heave, a walker's or an aircraft's motion break it.

What the vehicle is can be seen while GNSS aids the solution: the body-frame velocity
``C_bn v`` of the navigating solution. :class:`LearnedConstraint` keeps its mean squares over
the time moving faster than ``MIN_SPEED`` (forgetting with ``MEMORY_S`` of moving time, so that
a vehicle that starts to slide stops being constrained); after ``LEARN_S`` s of it, a body whose
lateral and vertical RMS both stay within ``ENABLE_RMS`` is constrained, with the noise of
``SIGMA_FACTOR`` times the measured RMS (not below ``SIGMA_FLOOR``): the constraint then says no
more than the aided solution showed. The same test with ``DISABLE_RMS`` turns it off again.
"""
from __future__ import annotations

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
#: RMS beyond which a constrained body is released again, m/s.
DISABLE_RMS = 0.45
#: Constraint noise per measured RMS, and its least value, m/s.
SIGMA_FACTOR = 2.0
SIGMA_FLOOR = 0.1
#: Longest time one solution stands for (the first after an outage or a gap), s.
MAX_STEP_S = 1.0


class LearnedConstraint:
    """Learns whether the vehicle moves like a wheeled one and the constraint's noise."""

    def __init__(self):
        self.mean_square = np.zeros(2)  # lateral, vertical body velocity, (m/s)^2
        self.moving = 0.0               # moving time learned from, s
        self.last_t = -np.inf
        self.sigma = None               # (lateral, vertical) m/s once enabled, else None

    def add(self, t: float, v_enu: np.ndarray, q_nb: np.ndarray) -> None:
        """Learn from the navigating, aided solution at time t (s), standing for the time since
        the last one it was given (at most ``MAX_STEP_S``).

        Epochs at or before the last learned one are passed over: a delayed measurement re-runs
        the filter over them, and learning them twice would count them twice.
        """
        if t <= self.last_t:
            return
        # the first one stands for no time: nothing was learned before it
        dt = min(t - self.last_t, MAX_STEP_S) if np.isfinite(self.last_t) else 0.0
        self.last_t = t
        if np.hypot(v_enu[0], v_enu[1]) < MIN_SPEED:
            return
        v_b = quat_to_dcm(q_nb).T @ v_enu
        self.mean_square += -np.expm1(-dt / MEMORY_S) * (v_b[1:] ** 2 - self.mean_square)
        self.moving += dt
        if self.moving < LEARN_S:
            return
        rms = self.rms()
        limit = DISABLE_RMS if self.sigma is not None else ENABLE_RMS
        self.sigma = tuple(np.maximum(SIGMA_FACTOR * rms, SIGMA_FLOOR)) \
            if np.all(rms <= limit) else None

    def rms(self) -> np.ndarray:
        """Lateral and vertical RMS of the body velocity learned so far, m/s (the exponential
        mean started at zero, its bias divided out)."""
        return np.sqrt(self.mean_square / -np.expm1(-self.moving / MEMORY_S))

    def summary(self) -> str:
        """What was learned, for /diagnostics."""
        if self.moving < LEARN_S:
            return (f"learning the body's lateral and vertical velocity: {self.moving:.0f} of "
                    f"{LEARN_S:.0f} s moving above {MIN_SPEED:g} m/s with GNSS")
        rms = self.rms()
        seen = f"lateral {rms[0]:.2f}, vertical {rms[1]:.2f} m/s RMS"
        if self.sigma is None:
            return f"off: {seen} (a wheeled vehicle stays within {ENABLE_RMS:g})"
        return f"on: {seen}, sigma {self.sigma[0]:.2f} / {self.sigma[1]:.2f} m/s"
