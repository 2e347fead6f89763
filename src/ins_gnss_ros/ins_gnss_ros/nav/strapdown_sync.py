"""The closed loop between the strapdown and the filter, as two ROS-free halves.

The ``strapdown`` node mechanises the IMU and publishes its state; the ``ekf`` node runs the
filter and keeps the strapdown on the filter's solution by state synchronisation. The two halves
of that protocol:

* :class:`ClosedLoopStrapdown` (the strapdown's side): mechanises increments, keeps the raw
  increments of the last ``history`` seconds, and applies a :class:`Correction` at the epoch it
  refers to by re-mechanising the increments since, so that a filter running late never corrects
  the wrong epoch. Sensor-error increments in a correction are accumulated and applied to every
  increment from that epoch on (unless the IMU preprocessor applies them instead).
* :class:`StrapdownSync` (the filter's side): keeps the strapdown states it receives; whenever
  the filter has corrected its solution (GNSS or a constraint such as the non-holonomic one:
  ``Navigator.revision``), it compares the strapdown's state of a common epoch with the filter's
  solution and makes the difference a :class:`Correction` referred to that epoch (errors
  "computed minus true", :func:`ins_gnss_ros.nav.strapdown.correction_to`). A correction that was
  lost, a strapdown restarted from its parameters or a state published before the last
  correction arrived are all handled the same way: the next comparison sees the difference and
  removes it.

Every correction carries a sequence number and every strapdown state the sequence of the last
correction applied to it: a state with the current sequence is the filter's solution.

The graph's outputs agree about when the solution is aligned: the filter's heading alignment
changes its own state at once, but the strapdown's (``ins/state``, hence ``nav/fix`` and
``nav/odom``) only when the first correction made after it arrives, a few of its states later.
:meth:`StrapdownSync.mode` reports the filter ALIGNING until a strapdown state acknowledges that
correction (carries its sequence or a later one).

Every correction also carries the filter's mode when it was made, and the strapdown's state is in
that mode (:meth:`ClosedLoopStrapdown.mode`): the filter corrects the strapdown while it is still
ALIGNING (levelled, heading not yet known) and while it is DEAD_RECKONING (degraded, or aided by
constraints only), and a corrected state is not a NAVIGATING one then.
"""
from __future__ import annotations

import bisect
from collections import deque
from dataclasses import dataclass

import numpy as np

from .increments import BRIDGED, LOST, SENSOR_BLOCKS, SensorErrors, classify_gap, held_increments
from .modes import ALIGNING, DEAD_RECKONING, INVALID, NAVIGATING
from .strapdown import NavState, Strapdown, apply_correction, correction_to

__all__ = ["Correction", "ClosedLoopStrapdown", "StrapdownSync"]

#: What a strapdown that leaves the sensor errors to the IMU preprocessor compensates: none.
_NO_ERRORS = SensorErrors()


@dataclass(frozen=True)
class Correction:
    """What the filter tells the strapdown: its errors at epoch ``t_ns`` (the stamp of one of the
    strapdown's states), computed minus true, and the sensor-error increments to apply from then.

    Attributes
    ----------
    t_ns : int
        Epoch, ns (ROS time axis).
    sequence : int
    position_error : (3,) m, ENU
    velocity_error : (3,) m/s, ENU
    attitude_error : (3,) rad, ENU (the phi convention of :mod:`ins_gnss_ros.nav.strapdown`)
    sensor : SensorErrors
        Increments to the sensor errors the strapdown applies; zero where the filter has no state.
    mode : str
        The filter's mode (:mod:`.modes`) when it made the correction.
    """

    t_ns: int
    sequence: int
    position_error: np.ndarray
    velocity_error: np.ndarray
    attitude_error: np.ndarray
    sensor: SensorErrors
    mode: str


@dataclass(slots=True)
class _Step:
    """One mechanised interval: the raw increments and the state they produced."""

    dtheta: np.ndarray
    dv: np.ndarray
    dt: float
    state: NavState


class ClosedLoopStrapdown:
    """The strapdown's side of the loop (see the module docstring).

    Parameters
    ----------
    state0 : NavState
        Initial state; its time is ignored (the first increment fixes the time axis).
    history : float
        Increments kept for re-mechanisation after a late correction, s.
    max_gap : float
        Longest gap in the increments bridged by holding the rates of the increment after it; a
        longer one loses the IMU: a new run starts at that increment, s.
    apply_sensor_errors : bool
        Remove the accumulated sensor errors from the increments here (False: the IMU
        preprocessor does).
    """

    def __init__(self, state0: NavState, history: float, max_gap: float,
                 apply_sensor_errors: bool = True):
        # The vertical channel is left free here: the filter's height aiding closes that loop.
        self.ins = Strapdown(NavState(state0.lat, state0.lon, state0.h, state0.v_enu,
                                      state0.q_nb, np.nan))
        self.history_s, self.max_gap = history, max_gap
        self.apply_sensor_errors = apply_sensor_errors
        self.sensor = SensorErrors()
        self.history: deque[_Step] = deque()
        self.t_start = np.inf  # start of the first increment of this run, s
        self.last_correction_t = -np.inf
        self.correction_sequence = 0
        self.filter_mode = ALIGNING  # the filter's at the last correction applied
        self.lost = False  # the IMU was lost (gap beyond max_gap), no correction since
        # (angle and velocity increments (2, 3), dt) of the latest step, sensor-corrected
        self.last_compensated = None

    @property
    def state(self) -> NavState:
        return self.ins.state

    def add(self, t: float, dtheta: np.ndarray, dv: np.ndarray, dt: float) -> str | None:
        """Mechanise the increment (dtheta, dv) over dt ending at t (s). Returns what happened
        to the stream, for the caller's diagnostics: None, "lost", "bridged" or "stale" (a stamp
        not after the previous one: dropped)."""
        state = self.ins.state
        interval = t - state.t
        event = None
        if classify_gap(interval, dt, self.max_gap) == LOST:
            event = "lost"
            self.lost = not np.isnan(state.t)
            self.history.clear()
            state = NavState(state.lat, state.lon, state.h, state.v_enu, state.q_nb, np.nan)
        steps = [(t, dtheta, dv)]
        if np.isnan(state.t):  # first increment (of this run) fixes the time axis
            self.t_start = t - dt
            self.ins.state = NavState(state.lat, state.lon, state.h, state.v_enu, state.q_nb,
                                      t - dt)
        elif t <= state.t:
            return "stale"
        elif classify_gap(interval, dt, self.max_gap) == BRIDGED:
            # Hold the increment's rates over the interval its stamp says it covers, in steps
            # of its length as the filter does (a correction may refer to an epoch in the gap).
            event = "bridged"
            steps = zip(*held_increments(t, dtheta, dv, dt, interval))
        for t_k, dtheta_k, dv_k in steps:
            self._step(dtheta_k, dv_k, t_k - self.ins.state.t)
        return event

    def _step(self, dtheta, dv, dt) -> None:
        errors = self.sensor if self.apply_sensor_errors else _NO_ERRORS
        comp = self.ins.step_compensated(dtheta, dv, dt, errors)
        self.last_compensated = (comp, dt)
        history, state = self.history, self.ins.state
        history.append(_Step(dtheta, dv, dt, state))
        while state.t - history[0].state.t > self.history_s:
            history.popleft()

    def correct(self, c: Correction) -> str | None:
        """Apply a correction at its epoch. Returns None, "older than this run" (ignored: a
        restarted strapdown is first handed the corrections of its previous run, which refer to
        another state) or "outside the kept history" (applied to the latest state)."""
        sec, nanosec = divmod(c.t_ns, 1_000_000_000)
        t_c = sec + nanosec * 1e-9  # as the states' times are formed from their stamps
        if not self.history or t_c < self.t_start:
            return "older than this run"
        # Index of the step whose end state is the correction epoch (half a step tolerance),
        # searched from the newest: the filter lags the strapdown by a few steps only.
        replay_from = None
        for i in range(len(self.history) - 1, -1, -1):
            step = self.history[i]
            if abs(step.state.t - t_c) <= 0.5 * step.dt:
                replay_from = i
                break
            if step.state.t < t_c:
                break
        errors = (c.position_error, c.velocity_error, c.attitude_error)
        event = None
        if replay_from is None:
            event = "outside the kept history"
            self.ins.correct(*errors)
            self.sensor = self.sensor + c.sensor
        else:
            later = list(self.history)[replay_from + 1:]
            for _ in later:
                self.history.pop()
            self.ins.state = self.history[-1].state
            self.ins.correct(*errors)
            self.history[-1].state = self.ins.state
            self.sensor = self.sensor + c.sensor
            for step in later:
                self._step(step.dtheta, step.dv, step.dt)
        self.correction_sequence = c.sequence
        self.filter_mode = c.mode
        self.last_correction_t = t_c
        self.lost = False
        return event

    def mode(self, silent_after: float) -> str:
        """The mode of the state (:mod:`.modes`), the worst that applies: INVALID while the IMU
        is lost (no correction since); ALIGNING before the first correction (the state is the
        start-up parameters) and while the filter's last one was made ALIGNING (levelled, the
        heading unknown); DEAD_RECKONING when the filter's last one was, or when none came for
        ``silent_after`` s (no filter vouches for the state since); else NAVIGATING."""
        if self.lost:
            return INVALID
        if self.filter_mode == NAVIGATING and \
                self.state.t - self.last_correction_t > silent_after:
            return DEAD_RECKONING
        return self.filter_mode


class StrapdownSync:
    """The filter's side of the loop (see the module docstring).

    Parameters
    ----------
    history : float
        Strapdown states kept for the comparison at a common epoch, s.
    min_interval : float
        Shortest interval between two corrections, s.
    resend_after : float
        With no kept state matching the filter's epoch for this long, correct the newest one,
        s.
    state_of : callable
        ``state_of(item) -> (NavState, SensorErrors applied)`` of a kept item: the caller keeps
        its own objects (messages) and only the matched one is converted.
    """

    def __init__(self, history: float, min_interval: float, resend_after: float, state_of):
        self.history_ns = history * 1e9
        self.min_interval, self.resend_after = min_interval, resend_after
        self.state_of = state_of
        self.sequence = 0
        self.states: deque[tuple[int, int, object]] = deque()  # (stamp ns, sequence, item)
        self.last_sync_t = -np.inf
        self.last_match_t = -np.inf
        self.synced_revision = 0
        self.aligned_sequence = None  # the first correction made after the filter aligned
        self.last = None  # the last Correction made
        self.alignment_applied = False  # a strapdown state has acknowledged that correction

    def add_state(self, t_ns: int, sequence: int, item) -> None:
        """Keep a strapdown state (stamp ns, the correction sequence it carries, the caller's
        object)."""
        if self.states and t_ns < self.states[-1][0]:
            self.states.clear()  # the strapdown restarted or the bag looped
        self.states.append((t_ns, sequence, item))
        # Bounded above too: a strapdown that outlived a restarted filter carries the sequences
        # of the old one.
        if self.aligned_sequence is not None and \
                self.aligned_sequence <= sequence <= self.sequence:
            self.alignment_applied = True
        while self.states and t_ns - self.states[0][0] > self.history_ns:
            self.states.popleft()

    def current(self, sequence: int) -> bool:
        """A state carrying ``sequence`` has every correction sent so far applied, and at least
        one (a strapdown that has not been corrected yet carries sequence 0: its state is its
        start-up parameters, not the filter's solution)."""
        return sequence == self.sequence > 0

    def lacking(self, t_ns: int, sequence: int):
        """The one correction a state (stamp ns, carrying ``sequence``) lacks to be the filter's
        solution, or None (it lacks none, or more): the last one, made on it (which waited for
        it) or on a state before it while it was on its way. With it applied the state is the
        solution, to the correction's change over the interval between them (second order): at
        an IMU rate near the output rate (10 Hz) the states skipped for it lost most fix
        epochs' output (docs/results/product_path.md, "2026-12-06 (session 32)")."""
        last = self.last
        if last is None or last.sequence != self.sequence or t_ns < last.t_ns:
            return None
        return last if sequence == last.sequence - 1 else None

    def aligning(self) -> None:
        """The filter aligns (again): its solution is not an aligned one until the first
        correction made after its next alignment reaches the strapdown."""
        self.aligned_sequence, self.alignment_applied = None, False

    def mode(self, filter_mode: str) -> str:
        """The filter's mode (:mod:`ins_gnss_ros.nav.modes`) as the graph reports it on
        nav/status and in nav/fix: ALIGNING until the strapdown has applied the alignment's
        correction."""
        return filter_mode if self.alignment_applied else ALIGNING

    def waiting_for(self, filter_mode: str) -> str | None:
        """What the reported mode waits for while the filter has aligned but the strapdown has
        not yet applied the alignment (for /diagnostics), else None."""
        if filter_mode == ALIGNING or self.alignment_applied:
            return None
        if self.aligned_sequence is None:
            return "aligned: waiting to send the strapdown the alignment's ins/correction"
        return (f"aligned: waiting for an ins/state carrying the alignment's ins/correction "
                f"{self.aligned_sequence}")

    def invalidate(self) -> None:
        """The strapdown's states are no longer the filter's solution (it bridged or lost a gap
        before the filter applied the measurements of the gap): make the next correction due
        now, against the strapdown's newest state (no kept state carries the new sequence).
        Waiting for the filter's next update left a drive with a lossy IMU link without
        nav/odom for the rest of a GNSS outage (15 s) after each gap held in it, and waiting
        for ``resend_after`` without any for a second after each."""
        self.sequence += 1
        self.synced_revision = -1
        self.last_match_t = -np.inf

    def due(self, t: float, revision: int) -> bool:
        """The filter (at time t, s) has corrected its solution since the last correction (its
        ``revision`` counts every correction, pseudo-measurements included: during a GNSS
        outage the non-holonomic constraint still corrects it) and the minimum interval has
        passed."""
        return revision > self.synced_revision and t - self.last_sync_t >= self.min_interval

    def _match(self, t_ns: int):
        """The newest kept item within 1 ms of t_ns that is the filter's solution with at most
        the last correction applied to it (:meth:`current`, :meth:`lacking`), or None.

        The kept states are in stamp order: bisection finds the 1 ms window instead of a scan of
        all of them, which ran on every message while a synchronisation was waiting.
        """
        states, key = self.states, (lambda entry: entry[0])
        lo = bisect.bisect_right(states, t_ns - 1e6, key=key)
        hi = bisect.bisect_left(states, t_ns + 1e6, lo=lo, key=key)
        return next((states[i] for i in range(hi - 1, lo - 1, -1)
                     if states[i][1] == self.sequence or self.lacking(*states[i][:2])), None)

    def correction(self, t: float, state_at, estimates: dict, revision: int, mode: str):
        """The correction that puts the strapdown on the filter's solution, or None (nothing to
        compare with yet).

        Parameters
        ----------
        t : float
            The filter's time, s.
        state_at : callable
            ``state_at(t) -> NavState | None``: the filter's solution moved to time t.
        estimates : dict of str to ndarray
            The filter's running sensor-error estimates by block name (SENSOR_BLOCKS).
        revision : int
            The filter's revision (marks the corrections of the solution this one covers).
        mode : str
            The filter's mode (:mod:`.modes`), carried by the correction; the first correction
            made in another mode than ALIGNING (the heading known) is the one :meth:`mode` waits
            for.

        Returns
        -------
        (Correction or None, bool) or None
            None when no kept state compares; else the correction (None if the filter's solution
            cannot be moved to the state's epoch) and whether it had to fall back on the newest
            state (the strapdown was out of step: no state matched for ``resend_after`` s).
        """
        match = self._match(int(round(t * 1e9)))
        resent = False
        if match is not None:
            self.last_match_t = t
        elif self.states and t - self.last_match_t > self.resend_after:
            # Nothing comparable for a while (lost correction, restarted strapdown): correct the
            # strapdown's newest state with the filter solution extrapolated to its epoch.
            match, resent = self.states[-1], True
            self.last_match_t = t
        else:
            return None
        strapdown, applied = self.state_of(match[2])
        last = self.lacking(*match[:2])
        if last is not None:
            # A state published before the last correction reached the strapdown, which
            # applies it at its epoch, before this state's: compared with that applied (to
            # the correction's change over the interval between them). Waiting for a state
            # carrying it held every update that followed another within a sample for the
            # filter's next epoch, up to cov_interval s (the graph's ins/state and its compass's
            # levelling behind the filter's solution that long).
            strapdown = apply_correction(strapdown, last.position_error, last.velocity_error,
                                         last.attitude_error)
            applied = applied + last.sensor
        target = state_at(strapdown.t)
        if target is None:
            return None, resent
        dp, dv, phi = correction_to(strapdown, target)
        sensor = {}
        for name, blocks in SENSOR_BLOCKS.items():
            estimate = sum(estimates[b] for b in blocks if b in estimates)
            # zero where the layout has none of the blocks
            sensor[name] = estimate - getattr(applied, name) if np.ndim(estimate) else np.zeros(3)
        self.sequence += 1
        if mode != ALIGNING and self.aligned_sequence is None:
            self.aligned_sequence = self.sequence
        self.synced_revision = revision
        self.last_sync_t = t
        self.last = Correction(match[0], self.sequence, dp, dv, phi, SensorErrors(**sensor),
                               mode)
        return self.last, resent
