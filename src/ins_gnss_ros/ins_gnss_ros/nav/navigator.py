"""Offline navigator: the strapdown and the closed-loop error-state filter over a whole trial.

The same filter code as the ``ekf`` node, without ROS. Feed IMU increments (:meth:`add_imu`, at
the IMU rate, any batch size) and time-stamped measurements (:meth:`add_measurement`,
measurement_types.py) in any interleaving; :meth:`flush` at the end. The navigator

* compensates the increments with the running sensor-error estimates, applies the one-sample
  coning/sculling terms to raw ones (imu_buffer.py) and mechanises them in compiled batches,
  propagating the covariance every `cov_interval` s and at each measurement (propagation.py);
* applies each measurement at ITS epoch, never at arrival: a late one by rewinding to a
  checkpoint before its epoch (rewind.py). With a "td" extra state the epoch of a GNSS
  measurement stamped t is t - td;
* closes the loop after every update (ekf.py), gates every measurement (gating.py), rejects a
  frozen receiver that repeats a fix while the INS moves, and forces a measurement kind through
  after `max_reject_time` seconds of continuous rejection (integrity.py);
* adds the process noise of IMU gaps the caller bridged with held rates (imu_gaps.py);
* runs the modes (modes.py) ALIGNING (levelling at the first fix, the gyro bias of a static
  start, heading from the first motion or a heading fix: alignment.py; GNSS used only while at
  rest), NAVIGATING, DEAD_RECKONING;
* starts again from ALIGNING when the IMU time jumps backwards.

Per-epoch outputs (recording.py) keep what the RTS smoother (smoother.py) needs.
"""
from __future__ import annotations

import bisect
from dataclasses import replace

import numpy as np

from . import _kernels
from . import measurements as meas
from . import modes
from .alignment import MIN_INS_SPEED_SHARE, SIDE_SLIP_SIGMA, Levelling, \
    couple_start_to_lever_arm, couple_tilt_to_accelerometers, course_error_gain, \
    course_gradient, fixes_with_course, initial_covariance, levelled_state, restart_velocity, \
    rotate_yaw, take_static_gyro_bias, without_cross_track, yaw_error_from_course, \
    yaw_error_from_heading, yaw_error_from_motion, yaw_of_x
from .conventions import wrap_pi
from .earth import WGS84, normal_gravity
from .ekf import ErrorStateEKF, StateSpace, at_prior
from .error_model import make_layout
from .gating import rejected
from .imu_buffer import ImuBuffer
from .imu_gaps import BridgedGaps
from .increments import SensorErrors
from .integrity import Integrity, rejection_start
from .lever_arm import lever_arm_position, point_velocity
from .measurement_types import GNSS_TYPES, GnssFix, GnssVelocity, HeadingFix, HeadingRefuted, \
    PhaseDifferences, Rest, SatelliteRanges, SpeedLog, StillImu, WheelOdometry, ZeroVelocity
from .modes import ALIGNING, DEAD_RECKONING, NAVIGATING
from .propagation import extrapolate, propagate
from .recording import Recorder, published_covariance
from .rest_noise import RestNoise
from .rotations import quat_from_rotvec, quat_rotate, quat_to_dcm
from .rewind import Rewind, RunState
from .strapdown import apply_error_state
from .vehicle_constraint import LEARN_S, SLIP_HOLD_SIGMA, SLIP_RATE, SLIP_RATE_ARM, \
    LearnedConstraint, hold_side_slip

#: A zero-velocity update tells the vehicle at rest for this long after its epoch, s (the
#: front end sends one per still IMU block, nav/rest_detector.py).
REST_HOLD = 0.5
#: An INS velocity sigma beyond this fraction of the GNSS speed keeps no direction to align on.
UNINFORMED_VELOCITY = 0.3
#: Shortest interval, s, between two levellings of an INS aligning on the move
#: (Navigator._level_on_the_move).
LEVEL_INTERVAL = 1.0
#: Standard deviations by which a heading source's alignment may miss the first course before
#: the source is refuted (Navigator._check_heading_on_course): once per source and run, so a
#: true heading is refuted with a probability of 6e-5.
HEADING_CONFIRM_SIGMAS = 4.0
#: Largest sigma of a course that checks a heading source's alignment, rad: with the heading's
#: few degrees, misses beyond about 25 deg are told.
CONFIRM_COURSE_SIGMA = np.radians(5.0)
#: Standard deviations of its covariance and the side slip by which the INS velocity's course
#: must miss the body x axis for the heading to align on the axis (Navigator._velocity_off_x).
DRIFT_SIGMAS = 3.0
#: Velocity sigma of a start with neither a GNSS speed nor rest known, m/s per axis.
UNKNOWN_SPEED_SIGMA = 30.0
#: The receiver's velocity change, m/s, from which the INS's own one tells which way the body x
#: axis aligned on a course points (Navigator._check_course_direction), over at most the last
#: COURSE_WINDOW s: the first seconds of a manoeuvre, before a wrong direction's error grows
#: (a car accelerating at about 1 m/s^2 was 8 m off 2 s into it), over which the
#: accelerometers' drift stays small.
COURSE_CHECK_DV, COURSE_WINDOW = 3.0, 3.0
#: Yaw variance published while the heading is not aligned, rad^2: that of a yaw spread evenly
#: over the circle (pi^2 / 3). The filter keeps the yaw out of P until then (alignment.
#: initial_covariance), so P's yaw variance is only the gyro noise since the start: published
#: as such, nav/odom said 0.2-1 deg for a yaw 149 deg off (simulated car, seed 3).
UNKNOWN_YAW_VAR = np.pi ** 2 / 3.0


def unknown_direction_var(length: float) -> float:
    """Variance per horizontal axis that covers the error of a horizontal vector d of that
    length (a velocity, a path run, a lever arm) whose direction is known only up to a yaw
    spread evenly over the circle: the error (R - I) d has the covariance |d|^2 / 2 I + d d^T
    (E[R] = 0), at most 1.5 |d|^2 along any axis. While the heading is unknown the filter
    refuses GNSS in motion (aligning): a start from rest without a heading source ran 31 m
    from the truth with a published position sigma of 0.4 m (simulated car, fixes only at
    1 Hz, seed 5)."""
    return 1.5 * length * length


def _view(part, name, doc):
    """A read-only property showing attribute `name` of the navigator's attribute `part`, once
    the navigator has caught up with its input (:meth:`Navigator._catch_up`)."""
    def get(self):
        self._catch_up()
        return getattr(getattr(self, part), name)
    return property(get, doc=doc)


#: Time constant of the rate in the GNSS velocity's lever-arm consider columns, s: the
#: segments' gyro noise averaged down (at rest it would pass for rotation that tells the lever
#: arm: a simulated car grew sure of its IMU's height, 0.2 m sigma for a 1.6 m error), a ship's
#: roll of several seconds kept. Smoothed twice with the lag taken out (Brown's double
#: exponential smoothing): smoothed once, the rate lagged a hull's roll by about this, 20 deg of
#: an 8 s wave, and the antenna's unknown height pulled a simulated vessel's tilt (attitude NEES
#: 27 -> 9; docs/results/product_path.md, "2026-12-07 (session 47)").
LEVER_RATE_TAU = 0.5


class Navigator:
    """Strapdown + closed-loop EKF over time-ordered IMU data and measurements.

    Parameters
    ----------
    config : NavigatorConfig
    """

    def __init__(self, config):
        self.config = config
        self._use_space()
        self._lever = np.asarray(config.lever_arm_b, float)
        # Corrections of the solution so far, pseudo-measurements (NHC, ZARU) included: what a
        # follower of the solution (the strapdown node) must hear of. Monotonic, neither reset
        # nor rewound: a re-run after a delayed measurement changes the solution again.
        self._revision = 0
        # Heading sources (their bias blocks) found none of the body's, with why: a property
        # of the installation, neither reset nor rewound
        self.refuted_headings: dict[str, str] = {}
        # Physical ranges of extra blocks' estimates, projected onto after every correction
        self._ranges = {"vd": meas.VELOCITY_LATENCY_RANGE}
        self.reset()

    # -- input -----------------------------------------------------------------------------
    def reset(self):
        """Forget everything: back to ALIGNING with no data."""
        cfg = self.config
        self._imu = ImuBuffer()
        # A measurement is queued at once but processed on the next IMU data or the next look
        # at the results (_catch_up): measurements that arrive together late (a receiver's fix
        # and velocity of one epoch) then rewind and re-run the IMU data once, not once each.
        self._behind = False
        self._pending = []          # sorted list of (epoch, sequence, measurement)
        self._seq = 0
        self._state = RunState.initial(self._space)     # rewound by delayed measurements
        self._rewind = Rewind(cfg.history, cfg.checkpoint_interval)
        self._integrity = Integrity(cfg)                # not rewound (integrity.py)
        self._rest_noise = RestNoise(cfg.noise)         # a property of the IMU: not rewound
        # a property of the vehicle: not rewound (it passes over re-run epochs)
        self._learned_nhc = LearnedConstraint() \
            if cfg.nhc_learn and cfg.nhc_sigma is None else None
        self._recorder = Recorder(self._space, cfg.record, cfg.store_covariance)
        self._gaps = BridgedGaps(cfg.gap_accel_sigma, cfg.gap_rate_sigma)
        # The fixes' common error (GnssFix.common_var) of the latest fix used, m^2: a property
        # of the receiver, not of the run state, so a rewind keeps it.
        self._fix_common_var = (0.0, 0.0)

    def _use_space(self):
        """The filter's states as the configuration gives them, and what is derived from them."""
        cfg = self.config
        self._space = StateSpace(make_layout(cfg.layout, cfg.noise), dict(cfg.extras))
        if "gs" in self._space or "ng" in self._space or "na" in self._space:
            raise ValueError("the navigator compensates bias, scale-factor and vertical "
                             "cross-axis (nz) blocks only")
        self._nav_blocks = tuple(self._space[name].start for name in ("pos", "vel", "att"))
        self._no_var = np.zeros(self._space.size)  # (_published_var: read, never written)
        self._no_var.flags.writeable = False

    def add_extra_state(self, name, block, valid_range=(-np.inf, np.inf)):
        """Estimate one more extra block (``NavigatorConfig.extras``; an ExtraState) from the
        start: what the first inputs tell of the sensors before the filter runs (a receiver
        whose stamps are its messages' arrival: the time offset "td"), its estimate kept within
        ``valid_range`` (low, high). Nothing changes if the filter has the block already.

        Raises
        ------
        RuntimeError
            Once the filter has started: its states are fixed from then on.
        """
        if name in self._space:
            return
        if self.started:
            raise RuntimeError(f"the filter has started: the extra state {name!r} cannot be "
                               "added")
        self.config = replace(self.config, extras={**self.config.extras, name: block})
        self._ranges[name] = valid_range
        self._use_space()
        self._state.estimates[name] = np.zeros(block.size)
        self._recorder = Recorder(self._space, self.config.record,
                                  self.config.store_covariance)  # (nothing recorded before)

    def set_lever_arm(self, lever_arm_b):
        """Place the GNSS antenna (relative to the IMU, base_link FLU, m) before the filter
        starts: the ekf node's from a URDF's /tf_static, which may come after the node.

        Raises
        ------
        RuntimeError
            Once the filter has started: it has taken fixes of the antenna where it was.
        """
        if self.started:
            raise RuntimeError("the filter has started: the lever arm cannot change")
        self.config = replace(self.config, lever_arm_b=np.array(lever_arm_b, float))
        self._lever = self.config.lever_arm_b

    def note_imu_rates_wrong(self, wrong):
        """Whether the turns show the IMU's rates in other units or of the wrong sign (the
        front end's imu_timing.ImuTimingCheck): while they do the solution is degraded
        (DEAD_RECKONING, integrity.py), the measurements still taken."""
        self._integrity.imu_rates_wrong = bool(wrong)

    def add_imu(self, t, dtheta, dv):
        """Add IMU samples.

        Parameters
        ----------
        t : float or array_like, shape (N,)
            End time of each sample's interval (navigation time scale), s, increasing.
        dtheta, dv : array_like, shape (3,) or (N, 3)
            Gyro (rad) and accelerometer (m/s) increments over each interval, body FLU: raw,
            or compensated (``NavigatorConfig.compensated_increments``).
        """
        # (reshape rather than atleast_1d/2d: the same arrays at a third of the cost per sample)
        t = np.asarray(t, float).reshape(-1)
        dtheta = np.asarray(dtheta, float).reshape(-1, 3)
        dv = np.asarray(dv, float).reshape(-1, 3)
        if len(self._imu) and t[0] <= self._imu.last_time:
            self.reset()
        self._behind = False  # caught up by the _advance below
        self._imu.add(t, dtheta, dv, self._rewind.needed_sample(self._state),
                      self.config.compensated_increments)
        self._advance()

    def add_bridged_gap(self, t_start, t_end, angle_var=None, velocity_var=None):
        """The IMU samples between t_start and t_end (s) were lost and bridged: by the caller,
        holding the rates of the sample after it (in samples of the usual length, added with
        :meth:`add_imu` after this call), or by the IMU preprocessor, which gives the variances
        per axis (rad^2, (m/s)^2) its bridge may miss by over the interval. The covariance
        propagated over the gap gets that process noise (imu_gaps.py). Measurements with epochs
        inside the gap are applied there as usual."""
        horizon = t_start - self.config.history - self.config.checkpoint_interval
        # older gaps lie before every checkpoint
        self._gaps.add(t_start, t_end, horizon, angle_var, velocity_var)

    def add_measurement(self, m):
        """Add a time-stamped measurement (measurement_types.py); one older than the current
        state is applied at its epoch by re-running the stored IMU data (within `history` s)."""
        if self._state.nav is None or "td" in self._space or \
                m.t <= self._imu.last_time - self.config.history + self.config.cov_interval:
            # Before the start, the measurements before m may start the filter (after which m
            # can be too old); the epoch depends on the time-offset estimate of the caught-up
            # state; near the history's end the checkpoints it still keeps decide "too old".
            self._catch_up()
        epoch = self._epoch_of(m)
        if self._state.nav is not None and epoch < self._state.nav.t:
            checkpoint = self._rewind.before(epoch)
            if checkpoint is None:
                if self._behind:  # decided, and reported in its place, on the caught-up run
                    self._catch_up()
                    self.add_measurement(m)
                    return
                self._refuse(m, epoch, "too old")
                return
            self._state = checkpoint.state.copy()
            self._recorder.truncate(checkpoint.epochs, checkpoint.update_count,
                                    checkpoint.last_epoch)
            for again in self._rewind.back_to(checkpoint):
                self._queue(again)
        self._queue(m)
        # Processed by the next _advance: a re-run from a checkpoint (or the segments up to
        # m's epoch) gives the same states as if each measurement had been processed on
        # arrival, since the checkpoints a re-run would take are those it rewinds to.
        self._behind = True

    def flush(self):
        """Process every buffered IMU sample (end of the data)."""
        self._behind = False
        self._advance(final=True)

    def _catch_up(self):
        """Process the measurements added since the last IMU data (add_measurement)."""
        if self._behind:
            self._behind = False  # first: a subclass's _measure may look at the results
            self._advance()

    def start_from(self, state, estimates, P):
        """Start NAVIGATING from a solution (NavState), running estimates (dict by block name)
        and covariance P (n, n) instead of levelling and aligning on the data (a restart at a
        stored epoch), before any data. The start counts as aided (see `dr_timeout`)."""
        s = self._state
        s.estimates = {name: np.array(v, float) for name, v in estimates.items()}
        s.mode, s.heading_known, s.t_last_aid = NAVIGATING, True, state.t
        self._start(state, np.array(P, float))

    # -- results (read-only) ---------------------------------------------------------------
    @property
    def started(self):
        """The filter runs: levelled at a first fix (or :meth:`start_from`)."""
        self._catch_up()
        return self._state.ekf is not None

    @property
    def revision(self):
        """Corrections of the solution so far (``_revision``)."""
        self._catch_up()
        return self._revision

    @revision.setter
    def revision(self, value):
        self._revision = value

    solution = _view("_state", "nav", "The solution (NavState) at the last filter epoch; None "
                     "before the first fix.")
    mode = _view("_state", "mode", "ALIGNING, NAVIGATING or DEAD_RECKONING (modes.py).")
    heading_known = _view("_state", "heading_known", "The heading has been aligned (until then "
                          "only roll and pitch are known).")
    heading_by = _view("_state", "heading_by", "The bias block of the heading source the "
                       "heading was aligned on until the motion confirms it, else None.")

    @property
    def heading_unconfirmed(self):
        """The heading is known but rests on what the motion has still to confirm: a heading
        source's alignment (heading_by), or gyros whose bias about the vertical may hold a
        steady turn (the still IMU's mean on the move); courses of fixes check it."""
        self._catch_up()
        s = self._state
        return s.heading_known and (s.heading_by is not None or s.turn_in_bias)

    @property
    def course_direction_unconfirmed(self):
        """The heading was aligned on the course at a start on the move and the motion has not
        yet shown the body x axis along it (_check_course_direction)."""
        self._catch_up()
        return self._state.course_check is not None

    estimates = _view("_state", "estimates", "Running sensor, clock and extra-block estimates "
                      "by block name (not to be changed).")
    updates = _view("_recorder", "updates", "UpdateResult of every measurement kept, in "
                    "processing order (not to be changed).")
    update_count = _view("_recorder", "update_count", "Number of update results produced so "
                         "far, including forgotten ones. A delayed measurement that re-runs "
                         "the filter can make it go back.")

    imu_noise_at_rest = _view("_rest_noise", "summary", "The IMU's white noise measured at "
                              "rest against the grade's (rest_noise.py), or None.")

    @property
    def learned_constraint(self):
        """What the learned non-holonomic constraint has seen (vehicle_constraint.py), or None
        where it is configured or off."""
        self._catch_up()
        if self._learned_nhc is None:
            return None
        summary = self._learned_nhc.summary()
        if self._state.slip_held:
            summary += "; meanwhile the side slip of the heading aligned on the course is held"
        return summary

    def velocity_latency(self):
        """The GNSS velocity's latency estimate and its sigma (s, "vd" state), or None."""
        self._catch_up()
        s = self._state
        if "vd" not in self._space or s.ekf is None:
            return None
        i = self._space["vd"].start
        return float(s.estimates["vd"][0]), float(np.sqrt(s.ekf.P[i, i]))

    def yaw_rate_sigma(self):
        """1 sigma of the error of the compensated gyros' rate about the body z axis (its bias
        states'), rad/s, once :attr:`started`: what a yaw carried by the gyros errs by per
        second (a course over a run of fixes, nav/course.py)."""
        self._catch_up()
        P = self._state.ekf.P
        return float(np.sqrt(sum(P[self._space[name].start + 2, self._space[name].start + 2]
                                 for name in ("bg", "gmg") if name in self._space)))

    def yaw_scale_sigma(self):
        """1 sigma of the gyros' scale-factor error about the body z axis (its state's, else
        the one :func:`~ins_gnss_ros.nav.propagation.turn_noise` takes), -: what a yaw carried
        by the gyros errs by per radian turned (nav/course.py)."""
        self._catch_up()
        if "sg" in self._space:
            i = self._space["sg"].start + 2
            return float(np.sqrt(self._state.ekf.P[i, i]))
        return float(self.config.noise.blocks["sg"].sigma0)

    def tilt_sigma(self):
        """1 sigma of the INS's tilt (the larger of its two horizontal attitude errors' sigmas),
        rad, once :attr:`started`: a yaw is a heading only to within what it does
        (nav/course.py)."""
        self._catch_up()
        return self._tilt_sigma()

    def _tilt_sigma(self):
        att, P = self._space["att"].start, self._state.ekf.P
        return float(np.sqrt(max(P[att, att], P[att + 1, att + 1])))

    space = property(lambda self: self._space, doc="The filter's StateSpace.")
    lever_arm_b = property(lambda self: self._lever, doc="GNSS antenna relative to the IMU, FLU, m.")

    def covariance(self):
        """The covariance to publish (n, n), once :attr:`started`: the filter's P plus
        :meth:`_published_var` on its diagonal (recorded per epoch, so that the offline path
        publishes the same)."""
        self._catch_up()
        return published_covariance(self._state.ekf.P, self._published_var())

    def _published_var(self):
        """What the published covariance adds to the diagonal of P, (n,): the noise floors of
        forced measurement kinds (integrity.py) and, on the position, the error common to the
        fixes the filter follows (GnssFix.common_var: the filter's position is relative to
        them), the part of an uncertain lever arm's offset P does not carry
        (:meth:`_lever_offset_var`) and an unmeasured one's (NavigatorConfig.
        lever_published_var) and, until the heading is aligned, UNKNOWN_YAW_VAR on the
        yaw and what that unknown yaw does to the horizontal velocity and position (the IMU's
        offset from the antenna the fixes pinned: :func:`unknown_direction_var`); the latter
        also while a heading source's alignment waits for the motion to confirm it (its
        heading may be none of the body's: _check_heading_on_course)."""
        aligned = self._state.heading_known
        confirmed = aligned and self._state.heading_by is None
        unmeasured = self.config.lever_published_var
        if not self._integrity.floors and not any(self._fix_common_var) and confirmed and \
                not self._space.lever_arm and not unmeasured.any():
            return self._no_var  # the usual case, asked at every epoch and update
        var = self._integrity.variances(self._space)
        east = self._space["pos"].start
        if self._space.lever_arm:
            var[east:east + 3] += self._lever_offset_var()
        if unmeasured.any():
            # The fixes place the antenna, and the IMU lies C l from it: an offset nobody
            # measured is the published position's whole error there, however many fixes
            # came. Left out of the filter's gains: as consider states (lever_arm_sigma_m)
            # 0.5 m per horizontal axis doubled the horizontal error of the robustness
            # matrix's cars, whose antenna is above the IMU (docs/results/product_path.md,
            # "2026-12-08 (session 48)").
            C = quat_to_dcm(self._state.nav.q_nb)
            var[east:east + 3] += (C * C) @ unmeasured
        horizontal, vertical = self._fix_common_var
        var[east:east + 2] += horizontal
        var[east + 2] += vertical
        if not aligned:
            var[self._space["att"].start + 2] += UNKNOWN_YAW_VAR
        if not confirmed:
            var += self._unknown_direction_var()
        return var

    def _lever_offset_var(self):
        """The IMU's offset from the antenna that P leaves out, ENU m^2 (3,): the fixes place
        the antenna and the IMU lies C l from it, so where the lever arm is uncertain (its
        consider blocks "lever_*") the IMU's position errs by C dl however many fixes came,
        of variance C_i^2 P_ll on each axis i. P carries it as far as its correlation with
        dl does (P_il^2 / P_ll); that correlation leaks away as the fixes come, as the
        columns -C of each fix move with every attitude correction while P holds those of
        the epochs before (the inconsistency of the linearised filter along what the data
        cannot tell: Navigator._held). Published whole, less what P carries: a simulated RTK
        drive, antenna 1.5 m above the IMU, the default's 1 m sigma, published its height
        1.2 m off with a sigma of 0.33 m and on a 2.2 deg slope 26 valid fixes beyond
        5 sigma, 6 cm along the track against 2 cm (docs/results/product_path.md,
        "2026-12-06 (session 31)"). On the diagonal, as published: over the direction across
        C's, a little wide."""
        P, pos = self._state.ekf.P, self._space["pos"]
        C = quat_to_dcm(self._state.nav.q_nb)
        var = np.zeros(3)
        for axis, j in self._space.lever_arm:
            var += np.maximum(C[:, axis] ** 2 * P[j, j] - P[pos, j] ** 2 / P[j, j], 0.0)
        return var

    def _unknown_direction_var(self):
        """What a heading that may be none of the body's does to the horizontal velocity and
        position, (n,): the velocity's direction unknown, and the IMU's offset from the antenna
        the fixes pinned (the lever arm and, once moving, the path run since) turned by it."""
        nav = self._state.nav
        var = np.zeros(self._space.size)
        velocity, east = self._space["vel"].start, self._space["pos"].start
        var[velocity:velocity + 2] = unknown_direction_var(np.hypot(*nav.v_enu[:2]))
        offset = meas.position_residual_enu(nav.lat, nav.lon, nav.h, *self._state.pinned_antenna)
        var[east:east + 2] = unknown_direction_var(np.hypot(*offset[:2]))
        return var

    def updates_since(self, count):
        """The update results after the first `count` (as counted by :attr:`update_count`)."""
        self._catch_up()
        return self._recorder.updates_since(count)

    def state_at(self, t):
        """The navigation solution moved to time t (s) at the current acceleration, or None
        before the first fix. Meant for t within a sample or two of the solution's time."""
        self._catch_up()
        s = self._state
        return None if s.nav is None else extrapolate(s.nav, t - s.nav.t, s.a_enu)

    def attitude_at(self, t):
        """The attitude q_nb at time t (s), or None before the first fix: the solution's,
        turned by the IMU samples after it up to t as the time update turns it (compensated
        with the running estimates, coning terms added; the earth's and transport rate left
        out, 1e-6 rad over a segment) and on to t at the last segment's rate. What a follower
        of the solution between filter epochs levels with, as the strapdown node's state
        serves the graph's compass."""
        self._catch_up()
        s, buf = self._state, self._imu
        if s.nav is None:
            return None
        times, th, _, cth, _ = buf.rows(s.next_sample, buf.search(t))
        last = times[-1] if len(times) else s.nav.t
        errors = SensorErrors.of_estimates(s.estimates)
        q = np.empty(4)
        # One compiled call: per sample, numpy's quaternion products cost 30 us a sample.
        _kernels.turn_attitude(s.nav.q_nb, th, cth, np.diff(times, prepend=s.nav.t),
                               errors.gyro_bias, errors.gyro_scale, s.omega, float(t - last), q)
        return q

    def output(self):
        """The forward pass so far, as a :class:`~ins_gnss_ros.nav.recording.NavigatorOutput`."""
        self._catch_up()
        return self._recorder.output()

    # -- main loop -------------------------------------------------------------------------
    def _epoch_of(self, m):
        est = self._state.estimates
        if "td" not in est:
            return m.t
        return m.t - est["td"][0] if isinstance(m, GNSS_TYPES) else m.t

    def _queue(self, m):
        bisect.insort(self._pending, (self._epoch_of(m), self._seq, m))
        self._seq += 1

    def _advance(self, final=False):
        s, buf, cfg = self._state, self._imu, self.config
        if s.nav is None and not self._initialise():
            return
        n = buf.end
        while s.next_sample < n:
            i = s.next_sample
            t_cov = s.t_epoch + cfg.cov_interval
            t_meas = self._pending[0][0] if self._pending else np.inf
            t_stop = min(t_cov, t_meas)
            if not final and buf.last_time <= t_stop:
                return  # the segment's end is not yet known (no search: the ekf node's usual case)
            j = buf.search(t_stop)
            if j > i:
                self._segment(i, j)
            elif t_meas <= t_cov:
                self._apply_pending(buf.time(i))
            else:
                self._segment(i, i + 1)
        if final:
            self._apply_pending(np.inf)

    def _initialise(self):
        """Level on the IMU data before the first fix, then start the filter there."""
        s, buf, cfg = self._state, self._imu, self.config
        while self._pending and s.nav is None:
            epoch, _, m = self._pending[0]
            if epoch > buf.last_time:
                return False
            self._pending.pop(0)
            k = buf.search(epoch)
            if k > s.next_sample:
                dt = float(np.median(np.diff(buf.times(buf.first, k)))) \
                    if k - buf.first > 1 else 0.0
                _, dtheta, dv = buf.rows(s.next_sample, k)[:3]
                s.levelling = s.levelling.add(dtheta, dv, dt)
                s.next_sample = k
            if isinstance(m, GnssVelocity):
                s.gnss_speed = float(np.hypot(*m.v_enu[:2]))
                v = (epoch, tuple(np.asarray(m.v_enu, float).tolist()))
                s.levelling_velocities = (s.levelling_velocities or (v,))[:1] + (v,)
            elif isinstance(m, (ZeroVelocity, Rest)):
                s.t_rest = epoch
            elif isinstance(m, StillImu):
                s.t_still = epoch
            if not isinstance(m, GnssFix) or s.levelling.time < cfg.level_time or k == buf.first:
                continue
            # At rest by the last GNSS speed, or by the velocity of the fix's own epoch.
            speed = s.gnss_speed if np.isfinite(s.gnss_speed) else next((np.hypot(*p.v_enu[:2])
                for e, _, p in self._pending if isinstance(p, GnssVelocity) and e - epoch < 0.5),
                np.nan)
            at_rest = speed <= cfg.static_speed or epoch - s.t_rest <= REST_HOLD
            # Neither a speed nor rest known (a receiver without velocity, started on the
            # move): the INS starts at zero velocity with the uncertainty of a moving vehicle.
            sigma_vel = cfg.sigma_vel0 if at_rest or np.isfinite(speed) else UNKNOWN_SPEED_SIGMA
            # At rest or with the IMU still, nothing accelerated over the levelling.
            still = at_rest or epoch - s.t_still <= REST_HOLD
            sigma_tilt = cfg.sigma_tilt0 if still else \
                self._levelling_tilt_sigma(normal_gravity(m.lat, m.h))
            P0 = initial_covariance(self._space, cfg.noise, cfg.sigma_pos0, sigma_vel,
                                    sigma_tilt)
            if not m.height_known:  # a 2-D fix: the height is a guess
                up = self._space["pos"].start + 2
                P0[up, up] = m.cov_enu[2, 2]
            if still:
                taken = take_static_gyro_bias(s.levelling, self._space, cfg.noise, P0,
                                              s.estimates)
                # Not known to stand, the vehicle may be turning steadily: its rate is in the
                # mean about the vertical, as bias.
                s.turn_in_bias = taken and not at_rest
            s.pinned_antenna = (m.lat, m.lon, m.h)
            climb = s.levelling_velocities[-1][1][2] if s.levelling_velocities and not at_rest \
                else 0.0
            nav = levelled_state(s.levelling, m.lat, m.lon, m.h, self._lever,
                                 0.0 if at_rest else s.gnss_speed, float(buf.time(k - 1)), climb)
            s.started_on_x = bool(np.any(nav.v_enu))
            couple_tilt_to_accelerometers(P0, self._space, nav, s.levelling.mean_specific_force(),
                                          sigma_tilt)
            couple_start_to_lever_arm(P0, self._space, nav.q_nb)
            self._start(nav, P0)
        if s.nav is None and not self._pending and len(buf):
            # Without a measurement to start on, keep only the samples of the last `history`
            # (at least `level_time`) seconds: the first fix is levelled on the samples before
            # it, and a receiver without a fix for hours (a ship at the pier) must not fill the
            # memory with IMU data. Older samples are passed over and the levelling starts
            # afresh after them; the buffer's trim then drops them.
            k = buf.search(buf.last_time - max(cfg.history, cfg.level_time))
            if k > s.next_sample:
                s.next_sample = k
                s.levelling = Levelling()
        return s.nav is not None

    def _start(self, nav, P0):
        """Start the filter at solution nav with covariance P0 (the first epoch). The
        levelled attitude is news to a follower: a compass that needs the roll and pitch waited
        for the first update to bring it (the simulated car standing with fixes only: its first
        mag/heading 5.0 s after the start of the data, 3.8 s after the levelling)."""
        s = self._state
        s.nav, s.ekf, s.t_epoch = nav, ErrorStateEKF(self._space, self.config.noise, P0), nav.t
        self._revision += 1
        self._recorder.epoch(s, np.eye(self._space.size), P0, self._published_var())

    def _segment(self, i, j):
        """Mechanise samples i..j-1 and propagate the covariance to the end of the segment."""
        s, cfg = self._state, self.config
        rows = self._imu.rows(i, j)
        at_rest = self._at_rest(s.nav.t)
        if at_rest:
            self._rest_noise.add(*rows[:3])
            errors = SensorErrors.of_estimates(s.estimates)  # those the segment is compensated by
        else:
            self._rest_noise.moved()
            s.rest_dtheta, s.rest_time = np.zeros(3), 0.0
        s.ekf.set_noise(self._rest_noise.noise)
        track = self._recorder.sample_buffer(len(rows[0]))
        phi = propagate(s, rows, s.ekf.noise, cfg.cov_interval, self._gaps, self._space, track)
        self._recorder.samples(rows[0], track)
        if self._space.lever_arm:
            # the GNSS velocity's lever-arm consider columns take a smoothed rate
            # (measurements.py, LEVER_RATE_TAU)
            decay = np.expm1(-s.omega_time / LEVER_RATE_TAU)
            s.omega_smooth = s.omega_smooth - decay * (s.omega - s.omega_smooth)
            s.omega_smooth2 = s.omega_smooth2 - decay * (s.omega_smooth - s.omega_smooth2)
        if at_rest:
            # The ZARU averages the gyros over all of the rest since the last one (_zero_rate),
            # as measured: the estimates may move before it.
            s.rest_dtheta = s.rest_dtheta + ((1.0 + errors.gyro_scale) * s.omega
                                             + errors.gyro_bias) * s.omega_time
            s.rest_time += s.omega_time
        s.next_sample = j
        self._recorder.epoch(s, phi, s.ekf.P, self._published_var())  # stored as a copy
        if s.slip_held:
            self._slip_update()
        if s.mode != ALIGNING:
            learned = self._learned_nhc
            nhc_sigma = cfg.nhc_sigma if learned is None else learned.sigma
            if nhc_sigma is not None and s.nav.t - s.t_nhc >= cfg.nhc_interval - 1e-9:
                s.t_nhc = s.nav.t
                # An unknown distance to the rear axle turns the yaw rate into lateral
                # velocity at the IMU: widen the lateral noise with the rate.
                sigma_lat = np.hypot(nhc_sigma[0], cfg.nhc_rate_arm * s.omega[2])
                self._update(meas.nonholonomic(self._space, s.nav, sigma_lat, nhc_sigma[1],
                                               s.omega, cfg.nhc_lever_b,
                                               s.estimates.get("nhc", np.zeros(2)),
                                               np.eye(3) if learned is None else learned.axes),
                             s.nav.t, aiding=False)
            s.mode = modes.after_epoch(s.mode, s.nav.t, s.t_last_aid, cfg.dr_timeout)
            self._recorder.set_mode(s.mode)
            if learned is not None and s.mode == NAVIGATING:
                learned.add(s.nav.t, s.nav.v_enu, s.nav.q_nb,
                            s.estimates.get("nhc", np.zeros(2)))
        oldest = self._rewind.keep(s, self._recorder.epochs, self._recorder.update_count,
                                   self._recorder.last_epoch)
        if oldest is not None:
            self._recorder.forget_updates(oldest.update_count)

    # -- measurements ----------------------------------------------------------------------
    def _apply_pending(self, t_next):
        """Apply every pending measurement whose epoch lies before the next sample's end."""
        s = self._state
        while self._pending and self._pending[0][0] < t_next:
            _, _, m = self._pending.pop(0)
            self._rewind.applied(m)
            # The epoch with the latest time-offset estimate (it may have moved since the
            # measurement was queued; the difference is a fraction of a second).
            epoch = self._epoch_of(m)
            if epoch < s.nav.t - self.config.cov_interval - 0.5:
                # Queued before the filter started and older than its first epoch.
                self._refuse(m, epoch, "too old")
                continue
            self._measure(m, extrapolate(s.nav, epoch - s.nav.t, s.a_enu), epoch)

    def _refuse(self, m, epoch, reason):
        """Report m as rejected without an update."""
        self._recorder.add_update(rejected(type(m).__name__, epoch, np.zeros(0),
                                           np.zeros((0, 0)), reason))

    def _measure(self, m, st, epoch):
        """Apply measurement m at its epoch (s); st is the solution moved there."""
        handler = self._HANDLERS.get(type(m))
        if handler is None:
            raise TypeError(f"unknown measurement {type(m).__name__}")
        handler(self, m, st, epoch)

    def _at_rest(self, epoch):
        """At rest by the last GNSS speed, or by a zero-velocity update (or the rest detector's
        Rest) within REST_HOLD s."""
        s = self._state
        return s.gnss_speed <= self.config.static_speed or epoch - s.t_rest <= REST_HOLD

    def _held_for_alignment(self, m, st, epoch):
        """While aligning, GNSS is used only at rest: reject m ("aligning") in motion, where the
        INS is kept level on gravity (:meth:`_level_on_the_move`)."""
        if self._state.mode == ALIGNING and not self._state.heading_known and \
                not self._at_rest(epoch):
            self._level_on_the_move(st, epoch)
            self._refuse(m, epoch, "aligning")
            return True
        return False

    def _level_on_the_move(self, st, epoch):
        """An INS aligning on the move runs unaided until its heading is known, and its tilt
        grows with its gyros' biases (default.yaml's 3 deg/s of session 36: a tilt sigma of 24
        deg after 9 s and 60 deg after 40 s on a simulated robot started on the move, where its
        yaw is no heading and its alignment no small correction): at most every LEVEL_INTERVAL s
        its horizontal acceleration is taken for the vehicle's, unknown to ``moving_accel_sigma``
        (meas.horizontal_acceleration). The vehicle's acceleration lasts for seconds, so more
        often would count it as news; and only while the tilt is less certain than that
        acceleration leaves it (a standing start's levelled tilt is better: there the update
        would only trade the tilt against the biases)."""
        s, sigma_a = self._state, self.config.moving_accel_sigma
        if epoch - s.t_levelled < LEVEL_INTERVAL or \
                self._tilt_sigma() <= sigma_a / normal_gravity(st.lat, st.h):
            return
        s.t_levelled = epoch
        self._update(meas.horizontal_acceleration(self._space, st, s.a_enu, s.omega, sigma_a),
                     epoch, aiding=False)

    def _gnss_fix(self, m, st, epoch):
        s = self._state
        if m.t <= s.t_fixes_aligned:
            self._refuse(m, epoch, "in the alignment")
            return
        if self._held_for_alignment(m, st, epoch):
            return
        self._fix_common_var = m.common_var
        if m.refutes_covariance:
            self._forget_position(m.cov_enu)
        v_ant = point_velocity(st.v_enu, st.q_nb, s.omega, self._lever, st.lat)
        innov = meas.gnss_position(self._space, st, m.lat, m.lon, m.h, m.cov_enu, self._lever,
                                   dzdt=v_ant, P=s.ekf.P, stamp_sigma=m.stamp_sigma)
        fix = (m.lat, m.lon, m.h)
        frozen = fix == s.last_fix and np.linalg.norm(v_ant) > self.config.frozen_speed
        s.last_fix = fix
        if frozen:
            self._recorder.add_update(rejected("gnss_pos", epoch, innov.z, innov.R, "frozen"))
            return
        if not self._update(innov, epoch).accepted:
            self._heading_missed(innov, epoch)
        else:
            s.t_fix_accepted = m.t
            if not s.heading_known or (s.heading_by is not None and self._at_rest(epoch)):
                # The corrected solution's antenna (a correction turned with the run would err
                # by up to twice its size); the epoch's record publishes the offset from it.
                # A heading not yet confirmed by the motion keeps it at the last rest.
                here = extrapolate(s.nav, epoch - s.nav.t, s.a_enu)
                s.pinned_antenna = lever_arm_position(here.lat, here.lon, here.h, here.q_nb,
                                                      self._lever)
                self._recorder.correct(s, np.zeros(self._space.size), self._published_var())

    def _gnss_velocity(self, m, st, epoch):
        s, cfg = self._state, self.config
        s.gnss_speed = float(np.hypot(*np.asarray(m.v_enu)[:2]))
        self._rest_noise.confirm(epoch, self._at_rest(epoch))
        if s.heading_by is not None and s.gnss_speed >= cfg.align_speed and m.aligns:
            self._check_heading_on_course(m, epoch)
            if s.heading_known and m.fixes:  # a course of fixes checks; they are fixes
                return
        elif s.turn_in_bias and s.heading_known and m.checks_only and \
                s.gnss_speed >= cfg.align_speed:
            self._check_turn_on_course(m, epoch)
        if m.checks_only:
            return
        if s.course_check is not None and s.heading_known and \
                self._check_course_direction(m, st, epoch):
            return
        aligned_by = None  # the INS velocity's course gradient where m turned the yaw against it
        if s.mode == ALIGNING and not s.heading_known and s.gnss_speed >= cfg.align_speed \
                and m.aligns:
            vel = self._space["vel"]
            v, sigma_ins = np.asarray(m.v_enu, float), np.sqrt(s.ekf.P[vel.start, vel.start])
            # The INS ran unaided too long (a start on the move without a receiver speed) for
            # its velocity to keep a direction, or too slow to have one (the motion started
            # before the filter), or its velocity ran off the body x axis (_velocity_off_x):
            # the body x axis takes the course, and the INS that velocity.
            too_slow = np.hypot(*s.nav.v_enu[:2]) <= MIN_INS_SPEED_SHARE * s.gnss_speed
            restart = sigma_ins >= UNINFORMED_VELOCITY * s.gnss_speed or too_slow
            drift = 0.0 if restart else self._velocity_off_x(vel)
            restart = restart or drift != 0.0
            if restart:
                delta, sigma = yaw_error_from_course(v, m.cov_enu, s.nav.q_nb)
            else:
                delta, sigma, aligned_by = yaw_error_from_motion(v, m.cov_enu, s.nav.v_enu,
                                                                 s.nav.q_nb)
            # the distance run followed the INS velocity: it turns by the velocity's course
            self._rotate_yaw(delta, sigma, aligned_by, run_turn=delta - drift)
            gain = course_error_gain(s.nav, self._space, v, s.pinned_antenna, restart)
            if restart:
                s.nav, s.ekf.P = restart_velocity(s.nav, s.ekf.P, self._space, v, m.cov_enu,
                                                  gain)
            if (restart or s.started_on_x) and self._learned_nhc is not None and \
                    self._learned_nhc.moving < LEARN_S and "nhc" in self._space:
                # the body x axis taken for the direction of motion: its side slip is held
                s.slip_held, s.t_slip = True, np.nan
            if m.rate_error is not None:
                # the gyros' bias about the vertical a start on the move never measured at rest
                self._update(meas.vertical_rate_error(self._space, s.nav, *m.rate_error), epoch)
            if (restart or s.started_on_x) and not m.fixes:
                # the body x axis taken for the direction of motion (a course of fixes comes no
                # more once the heading is known: nothing checks it there)
                s.course_check = (((epoch, v[:2], s.nav.v_enu[:2].copy()),), np.zeros(3))
            if m.fixes:
                if too_slow:
                    # The position ran from the start at a speed that was not the vehicle's:
                    # as far from the course's last fix as that left it, at least (an
                    # aircraft started at 190 m/s with fixes alone, 30 m/s sigma: 300 m
                    # behind them, the fixes gated; docs/results/product_path.md,
                    # "2026-12-07 (session 47)").
                    last, here = m.fixes[-1][0], extrapolate(s.nav, epoch - s.nav.t, s.a_enu)
                    self._forget_position(np.diag(meas.position_residual_enu(
                        here.lat, here.lon, here.h, last.lat, last.lon, last.h) ** 2))
                self._fixes_of_course(m, gain, epoch)
                return
            if restart:
                return
            st = extrapolate(s.nav, st.t - s.nav.t, s.a_enu)
        if self._held_for_alignment(m, st, epoch):
            return
        def innovation(st):
            return meas.gnss_velocity(self._space, st, m.v_enu, m.cov_enu, s.omega, self._lever,
                                      dzdt=s.a_enu, latency=s.estimates.get("vd", (0.0,))[0],
                                      lever_rate=2.0 * s.omega_smooth - s.omega_smooth2,
                                      stamp_sigma=m.stamp_sigma)
        innov = innovation(st)
        # The vertical row goes apart, after the horizontal ones and as a kind of its own
        # (integrity.NOT_VOUCHING), while it is beyond its own gate or its kind is forced or
        # rejected: together, the whole velocity was refused for it. Otherwise one update
        # (apart at every epoch, the simulated cars' heading RMS after their alignment came
        # out 3-10 % higher).
        apart = aligned_by is None and self._integrity.troubled(
            s.ekf, innov.rows([2], meas.GNSS_VEL_UP))
        if aligned_by is not None:
            innov = without_cross_track(innov, m.v_enu)
        elif apart:
            innov = innov.rows([0, 1])
        # A receiver's velocity does not repeat to the last bit while it moves: a repeat is an
        # old solution republished (a 1 Hz receiver's driver at 5 Hz), late by up to a second
        # of acceleration (a simulated car so published: velocity NEES 4.5 -> 16.6).
        velocity = tuple(np.asarray(m.v_enu, float).tolist())
        frozen = velocity == s.last_velocity and s.gnss_speed > cfg.frozen_speed
        s.last_velocity = velocity
        if frozen:
            self._recorder.add_update(rejected("gnss_vel", epoch, innov.z, innov.R, "frozen"))
            return
        if self._at_rest(epoch):
            self._zero_rate(st, epoch)
        if not self._update(innov, epoch).accepted:
            self._heading_missed(innov, epoch)
        if apart:  # on the solution the horizontal rows corrected
            up = innovation(extrapolate(s.nav, epoch - s.nav.t, s.a_enu))
            self._update(up.rows([2], meas.GNSS_VEL_UP), epoch)

    def _check_heading_on_course(self, m, epoch):
        """A heading aligned on a source with a bias of its own (an AHRS's orientation, a
        compass) against the first course that knows more than it: the INS velocity's
        direction (the IMU turned it by that heading since the velocity was known; the body x
        axis where it is not, and for a run of fixes: seconds into the motion, the fixes'
        updates have kept the INS velocity on their course whatever the heading) and the course
        of the GNSS velocity m. A heading that misses it by HEADING_CONFIRM_SIGMAS standard
        deviations of the three was not the body's: the source is refuted (refused from now on,
        Aiding.heading) and the heading aligned again on this course (on the next one where m
        only checks: GnssVelocity.checks_only). A yaw relative to where a 6-axis unit started,
        its covariance small against REP-145: on a simulated car the filter held a heading
        107 deg off (NEES 7,400; docs/results/product_path.md, "2026-12-06 (session 28)")."""
        s = self._state
        vel = self._space["vel"]
        from_motion = not m.checks_only and \
            np.sqrt(s.ekf.P[vel.start, vel.start]) < UNINFORMED_VELOCITY * s.gnss_speed
        checked = self._course_miss(m, from_motion)
        if checked is None:
            return  # a faster course will tell more
        miss, variance = checked
        if abs(miss) <= HEADING_CONFIRM_SIGMAS * np.sqrt(variance):
            # What the heading left uncertain in the position while it waited stays so, now
            # in P for the fixes to pull in (published only, it vanished with the confirmation
            # while the solution was still off: a simulated drive's AHRS confirmed on a run of
            # fixes put 11 valid fixes 1.4 m off with a 0.2 m sigma). The velocity's direction
            # is the heading's, now confirmed (its variance in P as well: the heading RMS of
            # eight drives with a good AHRS 0.45-1.88 -> 0.54-2.64 deg).
            pos = self._space["pos"]
            s.ekf.P[pos, pos] += np.diag(self._unknown_direction_var()[pos])
            s.heading_by = None
            return
        self._refute_heading(f"missed the course by {np.degrees(miss):+.0f} deg (sigma "
                             f"{np.degrees(np.sqrt(variance)):.0f} deg)")

    def _course_miss(self, m, from_motion):
        """How far the heading misses the course of the GNSS velocity m, and the variance of
        that miss (rad, wrapped; rad^2): against the INS velocity's direction (``from_motion``:
        alignment.yaw_error_from_motion) or the body x axis, with the yaw's own variance; None
        where the course's sigma is beyond CONFIRM_COURSE_SIGMA."""
        s = self._state
        v = np.asarray(m.v_enu, float)
        vel, yaw = self._space["vel"], self._space["att"].stop - 1
        P_vv = s.ekf.P[vel, vel]
        if from_motion:
            delta, sigma, gain = yaw_error_from_motion(v, m.cov_enu, s.nav.v_enu, s.nav.q_nb)
        else:
            (delta, sigma), gain = yaw_error_from_course(v, m.cov_enu, s.nav.q_nb), None
        if sigma > CONFIRM_COURSE_SIGMA:
            return None
        variance = sigma * sigma + s.ekf.P[yaw, yaw] + (0.0 if gain is None else
                                                       gain @ P_vv @ gain)
        return wrap_pi(delta), variance

    def _check_turn_on_course(self, m, epoch):
        """The heading of gyros whose bias about the vertical was taken from a still IMU's
        mean on the move (RunState.turn_in_bias) against a later course of fixes m. A vehicle
        turning steadily through the levelling gave its rate to that mean, and its INS then
        holds a yaw the course turns away from at that rate (a robot circling at 5.7 deg/s
        was NAVIGATING with its heading running round, 180 deg off at a sigma of 3.4 deg:
        docs/results/product_path.md, "2026-12-07 (session 39)"). A course missed by
        HEADING_CONFIRM_SIGMAS standard deviations refutes the bias: back to its data-sheet
        prior, the heading forgotten, and the next course aligns it with the run's rate
        error measured (nav/course.py). The check goes on as long as the fixes alone steer,
        the miss of a slow turn growing with time, or until a rest measures the bias."""
        s = self._state
        checked = self._course_miss(m, from_motion=False)
        if checked is None:
            return
        miss, variance = checked
        if abs(miss) <= HEADING_CONFIRM_SIGMAS * np.sqrt(variance):
            return
        s.turn_in_bias = False
        z = self._space["bg"].start + 2
        s.ekf.P = at_prior(s.ekf.P, slice(z, z + 1), self.config.noise.blocks["bg"].sigma0)
        s.estimates["bg"] = s.estimates["bg"].copy()
        s.estimates["bg"][2] = 0.0
        self._forget_heading()
        self._recorder.add_update(rejected(
            "course_on_x", epoch, np.array([miss]), np.array([[variance]]),
            "the course turned away from the heading: the gyros' bias about the vertical, "
            "taken on the move, held a turn; bias back to its prior, heading aligned anew"))

    def _levelling_tilt_sigma(self, g):
        """The levelling's own tilt sigma at a start on the move, rad: levelled on a specific
        force that holds the vehicle's acceleration, the tilt errs by it over g (m/s^2), whose
        mean horizontal part the receiver's velocities over the levelling tell (a simulated car
        accelerating at 1.4 m/s^2 started pitched 8.5 deg off, its tilt sigma 2.3 deg with the
        accelerometers', its updates gated and forced in: docs/results/product_path.md,
        "2026-12-06 (session 32)"). Without two velocities it is unknown, ``moving_accel_sigma``
        (simulated cars started on fixes alone levelled on 0.65-1.3 m/s^2 where a 1 deg tilt
        sigma allows 0.17, took it for accelerometer bias, and ran with their roll 1-2 deg off
        at an attitude NEES of 10-28: "2026-12-06 (session 35)")."""
        s, cfg = self._state, self.config
        unknown = float(np.hypot(cfg.sigma_tilt0, cfg.moving_accel_sigma / g))
        if s.levelling_velocities is None:
            return unknown
        (t0, v0), (t1, v1) = s.levelling_velocities
        if t1 <= t0:
            return unknown
        accel = np.hypot(v1[0] - v0[0], v1[1] - v0[1]) / (t1 - t0)
        return float(np.hypot(cfg.sigma_tilt0, accel / g))

    def _velocity_off_x(self, vel):
        """The angle (rad) by which the INS velocity's course, aligning on the move, has turned
        away from the body x axis beyond what its covariance and a forward-moving vehicle's
        side slip allow (DRIFT_SIGMAS of the two), else 0: the body axis is the better heading
        then (an INS too slow to compare, alignment.MIN_INS_SPEED_SHARE, the caller restarts
        at the course before asking). An INS that runs unaided tilts by what its gyros' biases
        leave, and its velocity turns with the tilt's share of gravity; the linearised
        covariance misses that when a bias lies sigmas out (a simulated consumer unit's 12.8
        deg/s x gyro bias, 2.6 sigma: its velocity 30 deg off the body axis after 3.6 s at a
        sigma of 7.8, the heading aligned on it ran away at 11 deg/s:
        docs/results/product_path.md, "2026-12-07 (session 45)"). More than a quarter turn
        off, the vehicle reverses (or the IMU is mounted backwards): the velocity is the
        heading's, as ever."""
        s = self._state
        v = s.nav.v_enu
        drift = wrap_pi(np.arctan2(v[1], v[0]) - yaw_of_x(s.nav.q_nb))
        across = course_gradient(v)
        var = across @ s.ekf.P[vel, vel] @ across + SIDE_SLIP_SIGMA ** 2
        return drift if np.pi / 2 > abs(drift) > DRIFT_SIGMAS * np.sqrt(var) else 0.0

    def _check_course_direction(self, m, st, epoch):
        """Whether the body x axis a start on the move aligned on the course points along the
        motion: the INS's own velocity change over the last COURSE_WINDOW s (its velocity less
        the updates' corrections, st at the epoch of the receiver's velocity m) against the
        receiver's, once that is COURSE_CHECK_DV and twice the drift the tilt and the
        accelerometer biases (their sigmas now) leave in the INS's over it. More than 90 deg
        apart, the axis points backwards (reversing when the recording started, or an IMU
        mounted backwards and nobody said; a simulated car so replayed aligned 180 deg off,
        published 7 valid fixes beyond 5 sigma and never recovered: docs/results/
        product_path.md, "2026-12-06 (session 32)"): the heading is turned 180 deg and the
        velocity restarted on m, which is so taken (True), and checked again; else the
        direction stands."""
        s = self._state
        history, corrections = s.course_check
        v_enu = np.asarray(m.v_enu, float)
        v, own = v_enu[:2], st.v_enu[:2] - corrections[:2]
        history = tuple(h for h in history if epoch - h[0] <= COURSE_WINDOW) + ((epoch, v, own),)
        s.course_check = (history, corrections)
        t0, v0, own0 = history[0]
        dv, dv_ins = v - v0, own - own0
        P, S = s.ekf.P, self._space
        drift = normal_gravity(st.lat, st.h) * self._tilt_sigma()
        if "ba" in S:
            ba = S["ba"].start
            drift += np.sqrt(max(P[ba, ba], P[ba + 1, ba + 1]))
        drift *= epoch - t0
        if np.hypot(*dv) < max(COURSE_CHECK_DV, 2.0 * drift):
            return False
        if dv @ dv_ins >= 0.0:
            s.course_check = None
            return False
        yaw = S["att"].stop - 1
        self._rotate_yaw(np.pi, np.sqrt(P[yaw, yaw]), pivot=False)  # (the fixes kept it)
        gain = course_error_gain(s.nav, S, v_enu, restarted=True)
        s.nav, s.ekf.P = restart_velocity(s.nav, s.ekf.P, S, v_enu, m.cov_enu, gain)
        s.course_check = (((epoch, v, s.nav.v_enu[:2].copy()),), np.zeros(3))
        self._recorder.add_update(rejected(
            "course_on_x", epoch, dv_ins, np.eye(2) * drift ** 2,
            "the body x axis pointed against the motion (reversing at the start, or the IMU "
            "mounted backwards): heading turned 180 deg"))
        return True

    def _heading_missed(self, innov, epoch):
        """A GNSS update refused in motion before the motion confirmed the heading. Aligned on
        a heading source, the INS has run off on that heading (an AHRS's yaw relative to its
        start: a simulated car's fixes 7 m off within 3.6 s, flagged valid with a 0.1 m sigma,
        before a course of fixes could check it), so the source is refuted there. Aligned on
        the course at a start on the move, the body x axis may point against the motion
        (_check_course_direction, which needs some m/s of velocity change to tell): the
        solution is not vouched for (DEAD_RECKONING) until a measurement is taken again (an
        IMU mounted backwards published 7 valid fixes beyond 5 sigma in the manoeuvre before
        the turn, its velocities refused from 0.3 s before the first: docs/results/
        product_path.md, "2026-12-07 (session 43)")."""
        s = self._state
        if self._at_rest(epoch):
            return
        if s.heading_by is not None:
            self._refute_heading(f"missed {innov.name} beyond its gate")
        elif s.course_check is not None and s.mode == NAVIGATING:
            s.mode = DEAD_RECKONING

    def _refute_heading(self, what):
        """The heading source the heading was aligned on is not an absolute heading (``what``
        it did as the vehicle moved off)."""
        self._refute(self._state.heading_by, f"its alignment {what} as the vehicle moved off: "
                     "not a heading of the body (a yaw relative to where it started, whose "
                     "covariance should say so, REP-145?)")

    def _refute(self, bias, why):
        """The heading source of bias block ``bias`` is none of the body's: refused from now
        on (its readings here and in Aiding.heading, with ``why``), the heading it may have
        aligned or steered aligned anew. A source refuted twice (by the motion, then by its
        turns) steers no heading the second time: the heading aligned on the course after the
        first stays (forgotten again, a simulated drive's was aligned anew on a course of
        fixes 1.2 s later: heading RMS after 50 s 1.55 deg, kept 1.05). The refused sources
        are the navigator's, kept over rewinds; which of them steered the heading is the
        state's (heading_steered_by), rewound with it."""
        self.refuted_headings[bias] = why
        if bias in self._state.heading_steered_by:
            self._forget_heading()

    def _fixes_of_course(self, m, gain, epoch):
        """After an alignment on a velocity made of fixes (nav/course.py), those of its fixes
        the filter has not taken, as one update with their correlation to the alignment's
        errors (alignment.fixes_with_course); the velocity itself is not applied, its
        along-track part is in the fixes. A first fix taken already (at rest) stays out, its
        correlation with the course not modelled."""
        s = self._state
        fixes = [(f, x) for f, x in m.fixes if f.t > s.t_fix_accepted]
        s.t_fixes_aligned = m.fixes[-1][0].t
        if not fixes:
            return
        innov = fixes_with_course(self._space, s.nav, s.ekf.P, fixes,
                                  [self._epoch_of(f) for f, _ in fixes], gain, s.a_enu, s.omega,
                                  self._lever)
        if self._update(innov, epoch).accepted:
            s.t_fix_accepted = fixes[-1][0].t

    def _zero_rate(self, st, epoch):
        """ZARU at rest: the gyros see only the Earth rate, so their biases become observable
        (while aligning, the unknown yaw hides the horizontal Earth rate, hence the added
        Omega cos(lat) term).

        The measured rate is the mean over every segment at rest since the last ZARU, not the
        last segment's alone: the cues come once per still block or GNSS velocity (0.25 or
        0.2 s) and a segment lasts at most the covariance interval (0.1 s), cut shorter by the
        measurement epochs, so most of the rest's gyro data was never averaged: the z gyro bias
        of a static start stayed twice as uncertain as the white noise over the rest makes it
        (test_aiding.py; the simulated car with fixes only at 1 Hz: 0.033 deg/s instead of
        0.018 after 30 s), and the heading of a receiver without velocity drifts with it until
        the vehicle turns."""
        s, cfg = self._state, self.config
        if cfg.zaru_sigma is None:
            return
        s.turn_in_bias = False  # the bias measured at rest
        omega, T = s.omega, s.omega_time
        if s.rest_time > 0.0:
            errors = SensorErrors.of_estimates(s.estimates)
            omega, T = (s.rest_dtheta / s.rest_time - errors.gyro_bias) \
                / (1.0 + errors.gyro_scale), s.rest_time
            s.rest_dtheta, s.rest_time = np.zeros(3), 0.0
        sigma = np.sqrt(cfg.noise.gyro_psd / T + cfg.zaru_sigma ** 2)
        if not s.heading_known:
            sigma = np.hypot(sigma, WGS84.omega * np.cos(st.lat))
        self._update(meas.zero_angular_rate(self._space, st, omega, sigma), epoch,
                     aiding=False)

    def _heading(self, m, st, epoch):
        s = self._state
        if m.bias in self.refuted_headings:  # (queued before the verdict)
            self._refuse(m, epoch, "refuted")
            return
        if not s.heading_known:
            # The alignment takes the source's bias uncertainty along (its block's variance).
            variance = m.variance + (s.ekf.P[self._space[m.bias], self._space[m.bias]][0, 0]
                                     if m.bias in self._space else 0.0)
            self._rotate_yaw(*yaw_error_from_heading(m.azimuth, variance, s.nav.q_nb))
            s.heading_by, s.heading_steered_by = m.bias, frozenset({m.bias})
        elif m.bias is not None:
            s.heading_steered_by |= {m.bias}
            bias = s.estimates[m.bias][0] if m.bias in s.estimates else 0.0
            field = m.field_enu if m.field_enu is not None and self._known_to_move(st) else None
            self._update(meas.biased_heading(self._space, st, m.azimuth, m.variance, bias,
                                             m.bias, field), epoch)
        else:
            self._update(meas.heading(self._space, st, m.azimuth, m.variance), epoch)

    def _known_to_move(self, st):
        """Whether the vehicle is known to move at st: its speed 3 sigma above align_speed. Only
        then is a compass levelled with the INS's roll and pitch fused with the filter's tilt
        in its error (measurements.biased_heading): standing, that error is a constant the
        compass bias carries, and the velocity updates, which at rest tell only the tilt's sum
        with the held accelerometer biases, move the tilt back and forth; the tilt columns
        dragged the yaw 3.4 times as far (10 deg in 2 s) and a standing car left with its tilt
        2.6 deg off at a sigma of 0.6 (docs/results/product_path.md, "2026-12-06 (session
        35)"), as did the first seconds of a start whose speed was still unknown."""
        vel = self._space["vel"].start
        sigma = np.sqrt(0.5 * np.trace(self._state.ekf.P[vel:vel + 2, vel:vel + 2]))
        return np.hypot(*st.v_enu[:2]) - 3.0 * sigma > self.config.align_speed

    def _heading_refuted(self, m, st, epoch):
        self._refute(m.bias, m.why)

    def _forget_position(self, cov_enu):
        """The position the fixes pinned while their reported covariance passed for theirs
        known no better than one fix as now taken (cov_enu, m^2): the first fixes of a start,
        2 m off at a reported 0.1 m, held a simulated car's solution 3 m off for a minute of
        fixes weighted at 2.3 m against its 0.12 m (docs/results/product_path.md, "2026-12-07
        (session 46)")."""
        s, pos = self._state, self._space["pos"]
        sigma = np.sqrt(np.maximum(np.diag(s.ekf.P)[pos], np.diag(cov_enu)))
        s.ekf.P = at_prior(s.ekf.P, pos, sigma)

    def _forget_heading(self):
        """Back to ALIGNING with the yaw out of P (as before the first alignment) and the
        velocity unknown, the tilt, the sensor errors and the position kept: the next course
        aligns the body's x axis on it and restarts the velocity (a start on the move), or a
        heading source aligns it. The INS velocity's direction cannot align it again: the
        fixes kept it on the course while the attitude erred."""
        s = self._state
        if not s.heading_known:
            return
        s.heading_by = None
        yaw = self._space["att"].stop - 1
        s.ekf.P = at_prior(at_prior(s.ekf.P, self._space["vel"], UNKNOWN_SPEED_SIGMA),
                           slice(yaw, yaw + 1), 0.0)
        s.heading_known, s.mode = False, ALIGNING
        s.t_model = -np.inf  # the system matrix holds the attitude: rebuilt at the next step
        self._revision += 1  # the followers hear that the heading is unknown
        self._recorder.correct(s, np.zeros(self._space.size), self._published_var())

    def _phase_differences(self, m, st, epoch):
        if not self._state.heading_known:  # linearised about the heading: a heading aligns
            self._refuse(m, epoch, "aligning")
            return
        self._update(meas.phase_differences(self._space, st, m.baseline_b, m.geometry, m.value,
                                            m.cov), epoch)

    def _speed_log(self, m, st, epoch):
        log = self._state.estimates.get("log", np.zeros(3))
        self._update(meas.speed_log(self._space, st, m.speed, m.variance, log[:2], log[2]),
                     epoch)

    def _wheel_odometry(self, m, st, epoch):
        if self._held_for_alignment(m, st, epoch):  # body axes without a heading: not linear
            return
        scale = self._state.estimates.get("wheel", np.zeros(1))[0]
        self._update(meas.wheel_velocity(self._space, st, m.velocity_b, m.variance,
                                         self._state.omega, self.config.wheel_lever_b, scale),
                     epoch)

    def _zero_velocity(self, m, st, epoch):
        self._state.t_rest = epoch
        self._rest_noise.confirm(epoch, True)
        self._zero_rate(st, epoch)
        self._update(meas.zero_velocity(self._space, st, m.sigma_v), epoch)

    def _rest(self, m, st, epoch):
        self._state.t_rest = epoch

    def _still_imu(self, m, st, epoch):
        """Queued before the start, applied after it: the filter already started."""

    def _satellite_ranges(self, m, st, epoch):
        if self._held_for_alignment(m, st, epoch):
            return
        s = self._state
        clock = s.estimates.get("clock", np.zeros(3))
        self._update(meas.pseudoranges(self._space, st, m.sat_pos, m.sat_clock, m.pseudorange,
                                       m.pr_var, clock[0], self._lever), epoch)
        if m.range_rate is not None:
            self._update(meas.range_rates(self._space, st, m.sat_pos, m.sat_vel,
                                          m.sat_clock_drift, m.range_rate, m.rr_var, s.omega,
                                          clock[1], self._lever), epoch)

    #: Measurement type -> handler(self, m, st, epoch).
    _HANDLERS = {GnssFix: _gnss_fix, GnssVelocity: _gnss_velocity, HeadingFix: _heading,
                 HeadingRefuted: _heading_refuted, PhaseDifferences: _phase_differences,
                 SpeedLog: _speed_log, WheelOdometry: _wheel_odometry,
                 ZeroVelocity: _zero_velocity, Rest: _rest, StillImu: _still_imu,
                 SatelliteRanges: _satellite_ranges}

    def _update(self, innov, epoch, aiding=True):
        """Gate and apply one measurement, forced in after `max_reject_time` s of continuous
        rejection (integrity.py); only aiding (not constraints) counts for the mode."""
        s, guard = self._state, self._integrity
        since = rejection_start(s.reject_since.get(innov.name), epoch,
                                self.config.max_reject_time)
        res = guard.update(s.ekf, self._space, innov, epoch, since, self._recorder.widen_prior,
                           self._held(epoch))
        if aiding:
            self._recorder.add_update(res)
        if not res.accepted:
            s.reject_since[innov.name] = (epoch if since is None else since, epoch)
            if aiding:
                guard.rejected(innov.name, epoch)
                s.mode = modes.after_rejected(s.mode, guard.degraded(epoch))
            return res
        s.reject_since.pop(innov.name, None)
        guard.accepted(innov.name)
        self._feedback()
        self._revision += 1
        if aiding:
            s.t_last_aid = epoch
            s.mode = modes.after_accepted(s.mode, guard.degraded(epoch))
        return res

    def _held(self, epoch):
        """The states an update at `epoch` (s) leaves as they are: at rest, the biases of the
        two accelerometers closest to horizontal, or None.

        At rest the horizontal specific force tells only the sum of the tilt and those biases
        (levelling takes one for the other: alignment.couple_tilt_to_accelerometers); the
        motion's turns part them. Updated at rest, the filter took information on each from
        the sum through its Jacobians, which move with every correction (the inconsistency of
        the linearised filter along an unobservable direction; Huang, Mourikis and
        Roumeliotis, "Observability-based rules for designing consistent EKF SLAM estimators",
        IJRR 29(5), 2010): a simulated robot's MEMS unit 94 mg off along x stood 30 s and left
        with that bias' sigma 50 -> 22 mg and its pitch 5.5 -> 7.0 deg off (sigma 2.0), and
        its attitude NEES over the motion was 59 (14 held; docs/results/product_path.md,
        "2026-12-06 (session 30)"). Held (their gain zero, Schmidt's consider update), they keep
        their sigma through the rest and the tilt its correlation with them."""
        if "ba" not in self._space or not self._at_rest(epoch):
            return None
        up = quat_to_dcm(self._state.nav.q_nb)[2]  # the body axes' vertical components
        return self._space["ba"].start + np.sort(np.argsort(np.abs(up))[:2])

    def _feedback(self):
        s, S = self._state, self._space.slices
        dx = s.ekf.take_correction()
        s.nav = apply_error_state(s.nav, dx, *self._nav_blocks)
        estimates = s.estimates
        for name, value in estimates.items():
            estimates[name] = value + dx[S[name]]
        if s.course_check is not None:
            history, corrections = s.course_check
            s.course_check = (history, corrections - dx[S["vel"]])
        for name, valid_range in self._ranges.items():  # projected onto its physical range
            if name in estimates:
                estimates[name] = np.clip(estimates[name], *valid_range)
        self._recorder.correct(s, dx, self._published_var())

    def _slip_update(self):
        """The side slip a heading aligned on the course assumed (alignment.SIDE_SLIP_SIGMA),
        held as a lateral constraint on the vehicle's own axes until the learned constraint
        has decided (vehicle_constraint.hold_side_slip): started on the first epoch after the
        alignment, ended with the heading, at that decision or at the first rejection."""
        s, cfg, S = self._state, self.config, self._space
        learned = self._learned_nhc
        if not s.heading_known or learned.moving >= LEARN_S:
            self._end_slip_hold()
            return
        if np.isnan(s.t_slip):
            # after the alignment's own changes to P (the course's fixes included)
            self._reset_boresight(hold_side_slip(s.ekf.P, S["att"].stop - 1,
                                                 S["nhc"].start + 1, SIDE_SLIP_SIGMA ** 2))
            s.t_slip = s.nav.t
            return
        if s.nav.t - s.t_slip < cfg.nhc_interval - 1e-9 or \
                np.hypot(*s.nav.v_enu[:2]) < cfg.align_speed:
            return
        slip = slice(S["nhc"].start + 1, S["nhc"].stop)
        walk = SLIP_RATE ** 2 * (s.nav.t - s.t_slip)
        s.ekf.P[slip, slip] += walk
        self._recorder.widen_prior(slip, [walk])  # this epoch's process noise for the smoother
        s.t_slip = s.nav.t
        sigma = np.hypot(SLIP_HOLD_SIGMA, SLIP_RATE_ARM * s.omega[2])
        innov = meas.nonholonomic(S, s.nav, sigma, 1.0, s.omega, boresight=s.estimates["nhc"])
        lateral = innov.rows([0], "slip")
        if not self._update(lateral, s.nav.t, aiding=False).accepted:
            self._end_slip_hold()

    def _end_slip_hold(self):
        """Back to the boresight state's prior: the learned axes (or none) take over."""
        self._state.slip_held = False
        self._reset_boresight(at_prior(self._state.ekf.P, self._space["nhc"],
                                       self._space.extras["nhc"].sigma0))

    def _reset_boresight(self, P):
        """The boresight estimate back to zero with the covariance P, recorded as a correction
        of the epoch (the smoother's P+ and dx)."""
        s = self._state
        dx = np.zeros(self._space.size)
        dx[self._space["nhc"]] = -s.estimates["nhc"]
        s.ekf.P, s.estimates["nhc"] = P, np.zeros(2)
        self._recorder.correct(s, dx, self._published_var())

    def _rotate_yaw(self, delta, sigma, velocity_gain=None, pivot=True, run_turn=None):
        """The heading alignment (alignment.rotate_yaw; ``pivot``: about the pinned antenna,
        else about the solution itself): from here on NAVIGATING."""
        s = self._state
        if s.slip_held:
            self._end_slip_hold()
        s.nav, s.ekf.P = rotate_yaw(s.nav, s.ekf.P, self._space, delta, sigma,
                                    self.config.sigma_yaw_align,
                                    s.pinned_antenna if pivot else None, velocity_gain, run_turn)
        # The last segment's acceleration turns with the solution: it moves the solution to
        # the epochs of the measurements that follow and is their time offsets' coefficient
        # (measurements.py, "td", "vd"); left as it was, a car's first velocity after a course
        # alignment took 0.13 s off a 0.25 s receiver latency, the wrong way (docs/results/
        # product_path.md, "2026-12-07 (session 42)").
        s.a_enu = quat_rotate(quat_from_rotvec([0.0, 0.0, delta]), s.a_enu)
        s.heading_known, s.mode, s.t_last_aid = True, NAVIGATING, s.nav.t
        s.heading_steered_by = frozenset()
        s.t_model = -np.inf  # the system matrix holds the attitude: rebuilt at the next step
        # The followers hear of it at once: a start on the move whose velocity restarts with
        # the course (no update follows) left the graph's strapdown on the unaligned heading
        # until the next accepted update, a fix interval (docs/results/product_path.md,
        # "2026-12-07 (session 44)").
        self._revision += 1
        self._recorder.correct(s, np.zeros(self._space.size), self._published_var())
