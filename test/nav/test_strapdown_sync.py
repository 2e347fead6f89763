"""nav/strapdown_sync.py: the closed loop between strapdown and filter, without ROS."""

from __future__ import annotations

import numpy as np

from ins_gnss_ros.nav.increments import SensorErrors
from ins_gnss_ros.nav.modes import ALIGNING, DEAD_RECKONING, INVALID, NAVIGATING
from ins_gnss_ros.nav.strapdown import NavState
from ins_gnss_ros.nav.strapdown_sync import ClosedLoopStrapdown, Correction, StrapdownSync

G = 9.81
LEVEL = np.array([1.0, 0.0, 0.0, 0.0])


def at_rest(loop, t_from, t_to, dt=0.01):
    """Feed level increments that hold the strapdown at rest (gravity along up)."""
    out = []
    for k in range(int(round(t_from / dt)), int(round(t_to / dt))):
        out.append(loop.add((k + 1) * dt, np.zeros(3), np.array([0.0, 0.0, G * dt]), dt))
    return out


def test_a_late_correction_is_applied_at_its_epoch_and_the_increments_since_replayed():
    loop = ClosedLoopStrapdown(NavState(1.0, 0.5, 0.0, np.zeros(3), LEVEL, np.nan), 5.0, 2.5)
    assert set(at_rest(loop, 0.0, 2.0)) == {None}
    epoch = loop.history[-51].state  # 0.5 s before the newest state
    t_ns = int(round(epoch.t * 1e9))
    # the filter says the state at that epoch had 0.1 m/s east too much
    event = loop.correct(Correction(t_ns, 1, np.zeros(3), np.array([0.1, 0.0, 0.0]), np.zeros(3),
                                    SensorErrors(), NAVIGATING))
    assert event is None and loop.correction_sequence == 1
    assert loop.state.t == 2.0
    assert abs(loop.state.v_enu[0] + 0.1) < 1e-3  # removed at the epoch, carried to now


def test_corrections_of_a_previous_run_are_ignored_and_a_long_gap_starts_a_new_run():
    loop = ClosedLoopStrapdown(NavState(1.0, 0.5, 0.0, np.zeros(3), LEVEL, np.nan), 5.0, 2.5)
    at_rest(loop, 0.0, 1.0)
    assert loop.add(5.0, np.zeros(3), np.array([0.0, 0.0, G * 0.01]), 0.01) == "lost"
    assert loop.lost
    stale = Correction(int(0.5e9), 3, np.ones(3), np.zeros(3), np.zeros(3), SensorErrors(),
                       NAVIGATING)
    assert loop.correct(stale) == "older than this run"
    assert loop.add(4.0, np.zeros(3), np.zeros(3), 0.01) == "stale"


def test_sync_corrects_against_the_matching_state_and_falls_back_when_out_of_step():
    states = {}

    def state_of(key):
        return states[key], SensorErrors()

    sync = StrapdownSync(3.0, 0.1, 1.0, state_of)
    assert not sync.current(0)  # an uncorrected strapdown is not the filter's solution
    for k in range(10):
        t = 1.0 + 0.01 * k
        states[k] = NavState(1.0, 0.5, 0.0, np.zeros(3), LEVEL, t)
        sync.add_state(int(round(t * 1e9)), 0, k)
    solution = NavState(1.0, 0.5, 0.0, np.array([0.0, 0.2, 0.0]), LEVEL, 1.05)
    estimates = {"bg": np.array([1e-4, 0.0, 0.0])}
    assert sync.due(1.05, 1)
    c, resent = sync.correction(1.05, lambda t: solution, estimates, 1, NAVIGATING)
    assert not resent and c.t_ns == 1_050_000_000 and c.sequence == 1 and c.mode == NAVIGATING
    assert np.allclose(c.velocity_error, [0.0, -0.2, 0.0])
    assert np.array_equal(c.sensor.gyro_bias, estimates["bg"])
    assert np.array_equal(c.sensor.accel_scale, np.zeros(3))  # no such block: zero
    assert not sync.due(1.06, 1) and not sync.current(0) and sync.current(1)
    # the state it was made on, and later ones still without it, lack only it; earlier not
    assert sync.lacking(1_050_000_000, 0) is c and sync.lacking(1_090_000_000, 0) is c
    assert sync.lacking(1_040_000_000, 0) is None and sync.lacking(1_090_000_000, 1) is None
    # nothing carries sequence 1 yet: no match until resend_after, then the newest state
    assert sync.correction(1.5, lambda t: solution, estimates, 2, NAVIGATING) is None
    c, resent = sync.correction(2.2, lambda t: solution, estimates, 2, NAVIGATING)
    assert resent and c.t_ns == 1_090_000_000
    assert sync.synced_revision == 2 and not sync.due(3.0, 2) and sync.due(3.0, 3)
    # A gap the strapdown bridged before the filter applied its measurements: its states are no
    # longer current, and a correction is due at once, not at the filter's next update (in a
    # GNSS outage that may be its end).
    sync.invalidate()
    assert not sync.current(2) and sync.due(3.0, 2)
    assert sync.lacking(1_090_000_000, 1) is None  # it lacks the invalidation as well
    c, resent = sync.correction(3.0, lambda t: solution, estimates, 2, NAVIGATING)
    assert resent and c.sequence == 4 and c.t_ns == 1_090_000_000  # the newest state, at once


def test_an_update_a_sample_after_the_last_is_corrected_at_once():
    """The filter updates at two successive strapdown states; the second was published before
    the first correction arrived. It is compared with that correction applied, so its own goes
    out at once (it waited for a state carrying the first: the filter's next epoch, up to
    cov_interval s later, the strapdown and the graph's compass behind the filter that long),
    and the strapdown that applies both is on the filter's solution."""
    loop = ClosedLoopStrapdown(NavState(1.0, 0.5, 0.0, np.zeros(3), LEVEL, np.nan), 5.0, 2.5)
    kept = {}
    sync = StrapdownSync(3.0, 0.0, 1.0, lambda key: (kept[key], SensorErrors()))

    def publish():
        state = loop.state
        kept[state.t] = state
        sync.add_state(int(round(state.t * 1e9)), loop.correction_sequence, state.t)

    def solution(v_east):
        return lambda t: NavState(1.0, 0.5, 0.0, np.array([v_east, 0.0, 0.0]), LEVEL, t)

    at_rest(loop, 0.0, 1.0)
    publish()
    first, _ = sync.correction(1.0, solution(0.1), {}, 1, NAVIGATING)
    at_rest(loop, 1.0, 1.01)  # the next state goes out before the correction arrives
    publish()
    assert sync.due(1.01, 2)
    second, resent = sync.correction(1.01, solution(0.2), {}, 2, NAVIGATING)
    assert not resent and second.sequence == 2 and second.t_ns == 1_010_000_000
    assert np.allclose(second.velocity_error, [-0.1, 0.0, 0.0], atol=1e-3)  # on top of the first
    loop.correct(first)
    loop.correct(second)
    assert loop.correction_sequence == 2
    assert np.allclose(loop.state.v_enu, [0.2, 0.0, 0.0], atol=1e-3)


def test_the_filter_is_reported_aligned_only_once_the_strapdown_applied_the_alignment():
    """The filter aligns between two corrections: nav/status may say NAVIGATING only from the
    strapdown state that carries the first correction made after the alignment, not while the
    strapdown still publishes the unaligned state (or, after a restart, another filter's
    sequences)."""
    states = {}
    sync = StrapdownSync(3.0, 0.0, 1.0, lambda key: (states[key], SensorErrors()))
    solution = NavState(1.0, 0.5, 0.0, np.zeros(3), LEVEL, 0.0)

    def state(k, sequence):
        t = 1.0 + 0.01 * k
        states[k] = NavState(1.0, 0.5, 0.0, np.zeros(3), LEVEL, t)
        sync.add_state(int(round(t * 1e9)), sequence, k)
        return t

    t = state(0, 0)
    sync.aligning()
    sync.correction(t, lambda t: solution, {}, 1, ALIGNING)  # levelling: sequence 1
    t = state(1, 1)
    assert sync.mode(ALIGNING) == ALIGNING and sync.waiting_for(ALIGNING) is None
    # the filter aligned; the strapdown has not been told
    assert sync.mode(NAVIGATING) == ALIGNING
    assert "waiting to send" in sync.waiting_for(NAVIGATING)
    c, _ = sync.correction(t, lambda t: solution, {}, 2, NAVIGATING)
    assert c.sequence == 2 and sync.aligned_sequence == 2
    state(2, 1)  # published before the correction arrived
    assert sync.mode(NAVIGATING) == ALIGNING and sync.waiting_for(NAVIGATING).endswith(" 2")
    state(3, 2)
    assert sync.mode(NAVIGATING) == NAVIGATING and sync.mode(DEAD_RECKONING) == DEAD_RECKONING
    assert sync.waiting_for(NAVIGATING) is None
    # later corrections in flight do not take it back; aligning again does
    t = state(4, 2)
    assert sync.correction(t, lambda t: solution, {}, 3, DEAD_RECKONING)[0].sequence == 3
    t = state(5, 2)
    assert sync.mode(NAVIGATING) == NAVIGATING
    sync.aligning()
    assert sync.mode(NAVIGATING) == ALIGNING
    t = state(6, 3)
    assert sync.correction(t, lambda t: solution, {}, 4, NAVIGATING)[0].sequence == 4
    # a strapdown that outlived a filter restart carries sequences ahead of this filter's
    state(7, 17)
    assert sync.mode(NAVIGATING) == ALIGNING
    state(8, 4)
    assert sync.mode(NAVIGATING) == NAVIGATING


def test_the_strapdown_state_is_in_the_mode_of_the_last_correction_or_worse():
    """ALIGNING until the filter's corrections say otherwise (levelled: sequence > 0, the
    heading unknown), then the filter's mode; DEAD_RECKONING instead of NAVIGATING after 2 s
    without a correction; INVALID from a lost IMU until the next correction."""
    loop = ClosedLoopStrapdown(NavState(1.0, 0.5, 0.0, np.zeros(3), LEVEL, np.nan), 5.0, 2.5)

    def correct(sequence, mode):
        t_ns = int(round(loop.state.t * 1e9))
        loop.correct(Correction(t_ns, sequence, np.zeros(3), np.zeros(3), np.zeros(3),
                                SensorErrors(), mode))

    at_rest(loop, 0.0, 1.0)
    assert loop.mode(2.0) == ALIGNING and loop.correction_sequence == 0
    correct(1, ALIGNING)  # levelled at rest, heading unknown
    at_rest(loop, 1.0, 4.0)
    assert loop.mode(2.0) == ALIGNING  # silent, but never aligned: not dead reckoning
    correct(2, NAVIGATING)
    at_rest(loop, 4.0, 5.9)
    assert loop.mode(2.0) == NAVIGATING
    at_rest(loop, 5.9, 6.1)
    assert loop.mode(2.0) == DEAD_RECKONING  # no correction for 2.1 s
    correct(3, DEAD_RECKONING)  # the filter degraded: corrected, not vouched for
    assert loop.mode(2.0) == DEAD_RECKONING
    correct(4, NAVIGATING)
    assert loop.mode(2.0) == NAVIGATING
    assert loop.add(10.0, np.zeros(3), np.array([0.0, 0.0, G * 0.01]), 0.01) == "lost"
    assert loop.mode(2.0) == INVALID
    correct(5, ALIGNING)  # the filter lost the IMU too and levels again
    assert loop.mode(2.0) == ALIGNING
