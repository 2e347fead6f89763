"""The navigator's run state and the checkpoints of it that delayed measurements rewind to.

A measurement older than the state is applied at its epoch, never at arrival: the navigator
restores the newest checkpoint before the epoch and re-runs the buffered IMU data and the
measurements applied since, with the late one in its place (exactly what the filter would have
done had it arrived on time; seed 000 section A2.6 and seed 003 section B4 use the delayed
measurement against the stored state of its epoch for the same purpose).

Everything the filter changes as it runs is one :class:`RunState`; a checkpoint holds a copy of
all of it, so no part of the state can be left out of a rewind. What a rewind deliberately
keeps lies outside it: the noise floors of forced measurement kinds and the times of their
rejections (:class:`~ins_gnss_ros.nav.integrity.Integrity`: a floor is only ever
conservative), the IMU samples and the bridged gaps (facts of the input), and the record,
which is cut back to the checkpoint's length.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from .alignment import Levelling
from .ekf import ErrorStateEKF
from .modes import ALIGNING
from .recording import estimate_sizes
from .strapdown import NavState


@dataclass
class RunState:
    """Everything the filter changes as it runs (all times in s on the navigation scale).

    Attributes
    ----------
    next_sample : int
        Number of the next IMU sample to process (:class:`~ins_gnss_ros.nav.imu_buffer.ImuBuffer`).
    levelling : Levelling
        Specific force summed before the first fix.
    gnss_speed : float
        Horizontal speed of the last GNSS velocity, m/s (NaN before the first).
    t_rest : float
        Epoch of the last zero-velocity update.
    t_still : float
        Epoch of the last StillImu before the start.
    nav : NavState or None
        The solution (None until the first fix).
    ekf : ErrorStateEKF or None
        Covariance, error state and model of the filter (None until the first fix).
    estimates : dict of str to ndarray
        Running sensor, clock and extra-block estimates (error_model.py units).
    mode : str
        modes.py.
    heading_known : bool
        The yaw has been aligned; until then its variance is kept out of the filter.
    heading_by : str or None
        The bias block of the heading source that aligned the yaw ("ahrs", "mag"), until the
        motion confirms it (Navigator._check_heading_on_course); None otherwise.
    heading_steered_by : frozenset of str
        The bias blocks of the heading sources that aligned the yaw or updated it since its
        last alignment: a refuted source's verdict forgets the heading only where it is one.
    t_epoch, t_model, t_nhc, t_last_aid : float
        The last filter epoch, model (F) refresh, non-holonomic update and accepted aiding.
    reject_since : dict of str to (float, float)
        Measurement kind -> first and last epoch of its current continuous rejection (decides
        forcing, :func:`~ins_gnss_ros.nav.integrity.rejection_start`).
    a_enu : (3,) ndarray
        Mean acceleration of the last segment, ENU, m/s^2.
    omega : (3,) ndarray
        Mean compensated angular rate of the last segment, body FLU, rad/s.
    omega_time : float
        Length of that segment.
    omega_smooth, omega_smooth2 : (3,) ndarray
        That rate smoothed over ``LEVER_RATE_TAU`` s of segments (navigator.py), and that
        smoothed again, rad/s: 2 omega_smooth - omega_smooth2 follows the rate without the
        smoothing's lag (Brown's double exponential smoothing).
    rest_dtheta, rest_time : (3,) ndarray, float
        The gyros' angle increments (as measured, before the running estimates' compensation)
        summed over the segments at rest since the last ZARU, rad, and their length, s.
    turn : (3,) ndarray
        The rotation of the current manoeuvre, body FLU, rad (propagation.turn_noise).
    pinned_antenna : tuple of 3 float or None
        (lat, lon, h) of the antenna at the last fix the filter took while the heading was
        unknown (the first fix included): the solution, run with a yaw that may be anything,
        meets the truth there, and the heading alignment turns it about that point.
    last_fix : tuple of 3 float or None
        (lat, lon, h) of the last GNSS fix (a frozen receiver repeats it).
    last_velocity : tuple of 3 float or None
        ENU of the last GNSS velocity (a driver republishing a solution repeats it).
    t_fix_accepted : float
        GNSS time of the last fix the filter took.
    t_fixes_aligned : float
        GNSS time of the last fix of the course the heading was aligned on: the fixes up to it
        are in the alignment (alignment.fixes_with_course), not applied again.
    levelling_velocities : tuple or None
        The first and the last receiver velocity while levelling before the start: (epoch s,
        (east, north, up) m/s) each.
    started_on_x : bool
        The filter started on the move, its velocity along the body x axis
        (alignment.levelled_state): the heading aligned against it takes that axis for the
        direction of motion.
    turn_in_bias : bool
        The gyros' bias about the vertical was taken from the mean of an IMU still while the
        vehicle was not known to stand: a steady turn's rate may be in it, until a rest
        measures the bias or a course of fixes refutes it (Navigator._check_turn_on_course).
    course_check : tuple or None
        After a start on the move aligned the body x axis on a receiver velocity's course, until
        the motion tells which way that axis points (Navigator._check_course_direction): the
        last seconds' (epoch s, the receiver's and the INS's own horizontal velocity, m/s), and
        the velocity corrections the updates have applied since the alignment (ENU, m/s), by
        which the INS's velocity less them is its own; replaced, never changed in place.
    slip_held, t_slip : bool, float
        The side slip of a heading aligned on the course is held (Navigator._slip_update), and
        the epoch of its last update (NaN until the first epoch after the alignment).
    t_levelled : float
        The epoch of the last levelling of an INS aligning on the move
        (Navigator._level_on_the_move).
    """

    next_sample: int = 0
    levelling: Levelling = field(default_factory=Levelling)
    gnss_speed: float = np.nan
    t_rest: float = -np.inf
    t_still: float = -np.inf
    nav: NavState | None = None
    ekf: ErrorStateEKF | None = None
    estimates: dict = field(default_factory=dict)
    mode: str = ALIGNING
    heading_known: bool = False
    heading_by: str | None = None
    heading_steered_by: frozenset = frozenset()
    t_epoch: float = -np.inf
    t_model: float = -np.inf
    t_nhc: float = -np.inf
    t_last_aid: float = -np.inf
    reject_since: dict = field(default_factory=dict)
    a_enu: np.ndarray = field(default_factory=lambda: np.zeros(3))
    omega: np.ndarray = field(default_factory=lambda: np.zeros(3))
    omega_time: float = 1.0
    omega_smooth: np.ndarray = field(default_factory=lambda: np.zeros(3))
    omega_smooth2: np.ndarray = field(default_factory=lambda: np.zeros(3))
    rest_dtheta: np.ndarray = field(default_factory=lambda: np.zeros(3))
    rest_time: float = 0.0
    turn: np.ndarray = field(default_factory=lambda: np.zeros(3))
    pinned_antenna: tuple | None = None
    last_fix: tuple | None = None
    last_velocity: tuple | None = None
    t_fix_accepted: float = -np.inf
    t_fixes_aligned: float = -np.inf
    levelling_velocities: tuple | None = None
    started_on_x: bool = False
    turn_in_bias: bool = False
    course_check: tuple | None = None
    slip_held: bool = False
    t_slip: float = -np.inf
    t_levelled: float = -np.inf

    @classmethod
    def initial(cls, space):
        """The state of a navigator with no data, for the filter state `space`."""
        return cls(estimates={name: np.zeros(size) for name, size in estimate_sizes(space)})

    def copy(self):
        """A copy that shares nothing mutable with this state (every field, by construction:
        every attribute; taken without the constructor, which costs more than the copy)."""
        state = object.__new__(RunState)
        state.__dict__.update({name: _independent(value)
                               for name, value in self.__dict__.items()})
        return state


def _independent(value):
    """`value`, or a copy of it where it can be changed in place."""
    if isinstance(value, np.ndarray):
        return value.copy()
    if isinstance(value, dict):
        return {k: _independent(v) for k, v in value.items()}
    if isinstance(value, ErrorStateEKF):
        # Its model and noise are replaced, never changed in place: only P and x are copied
        # (its attributes taken as they are: copy.copy costs three times more).
        ekf = object.__new__(type(value))
        ekf.__dict__.update(value.__dict__)
        ekf.P, ekf.x = value.P.copy(), value.x.copy()
        return ekf
    return value  # immutable: numbers, strings, tuples, None, frozen dataclasses


@dataclass(frozen=True)
class Checkpoint:
    """A copy of the run state, and how far the run had got when it was taken."""

    state: RunState
    epochs: int         # epochs recorded (Recorder.epochs)
    update_count: int   # update results produced (Recorder.update_count)
    applied: int        # measurements applied (Rewind.applied_count)
    # The record of the checkpoint's epoch as it was (Recorder.last_epoch): the updates applied
    # at that epoch after the checkpoint change it, and the re-run applies them again.
    last_epoch: dict | None = None


class Rewind:
    """Checkpoints of the last `history` seconds, every `interval` seconds, and the
    measurements applied since the oldest one."""

    def __init__(self, history, interval):
        self.history, self.interval = history, interval
        self.checkpoints = []
        self._applied = []
        self._applied_dropped = 0
        self._t_last = -np.inf

    @property
    def applied_count(self):
        """Number of measurements applied so far."""
        return self._applied_dropped + len(self._applied)

    def applied(self, m):
        """Measurement m has been applied."""
        self._applied.append(m)

    def keep(self, state, epochs, update_count, last_epoch=lambda: None):
        """Take a checkpoint of `state` if `interval` has passed since the last one; drop those
        no measurement within `history` can need. Returns the oldest checkpoint when older ones
        were dropped (the update results before it are no longer needed either), else None.
        `last_epoch()` gives the record of the current epoch to keep with a checkpoint."""
        if state.nav.t - self._t_last >= self.interval:
            self.checkpoints.append(Checkpoint(state.copy(), epochs, update_count,
                                               self.applied_count, last_epoch()))
            self._t_last = state.nav.t
            horizon = state.nav.t - self.history
            cps, drop = self.checkpoints, 0
            while drop < len(cps) - 1 and cps[drop + 1].state.nav.t < horizon:
                drop += 1
            if drop:
                del cps[:drop]
                del self._applied[:cps[0].applied - self._applied_dropped]
                self._applied_dropped = cps[0].applied
                return cps[0]
        return None

    def before(self, epoch):
        """The newest checkpoint older than `epoch`, or None."""
        return next((c for c in reversed(self.checkpoints) if c.state.nav.t < epoch), None)

    def back_to(self, checkpoint):
        """Forget what came after `checkpoint`; returns the measurements applied since, in
        order, to be applied again."""
        start = checkpoint.applied - self._applied_dropped
        again = self._applied[start:]
        del self._applied[start:]
        t = checkpoint.state.nav.t
        self.checkpoints = [c for c in self.checkpoints if c.state.nav.t <= t]
        self._t_last = t
        return again

    def needed_sample(self, state):
        """Number of the oldest IMU sample a rewind (or `state`) can still need."""
        # The checkpoints are in the order of the run: the first one's is the smallest.
        cps = self.checkpoints
        return min(cps[0].state.next_sample, state.next_sample) if cps else state.next_sample
