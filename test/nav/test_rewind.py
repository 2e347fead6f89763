"""The run state a delayed measurement rewinds (nav/rewind.py), the IMU buffer it re-runs
(nav/imu_buffer.py), the mode machine (nav/modes.py) and the forced-update floors that stay
outside the rewind (nav/integrity.py)."""
from dataclasses import fields

import numpy as np

from ins_gnss_ros.nav import modes
from ins_gnss_ros.nav.ekf import ErrorStateEKF, StateSpace
from ins_gnss_ros.nav.error_model import make_layout
from ins_gnss_ros.nav.imu_buffer import ImuBuffer
from ins_gnss_ros.nav.integrity import Integrity
from ins_gnss_ros.nav.measurements import GNSS_VEL_UP, Innovation
from ins_gnss_ros.nav.navigator_config import NavigatorConfig
from ins_gnss_ros.nav.rewind import Rewind, RunState
from ins_gnss_ros.nav.sensor_errors import MEMS_ADIS16405, filter_noise
from ins_gnss_ros.nav.strapdown import NavState

NOISE = filter_noise(MEMS_ADIS16405, "rw")
SPACE = StateSpace(make_layout("15", NOISE))


def running_state(t=1.0):
    s = RunState.initial(SPACE)
    s.nav = NavState(0.8, 0.1, 10.0, np.zeros(3), np.array([1.0, 0.0, 0.0, 0.0]), t)
    s.ekf = ErrorStateEKF(SPACE, NOISE, np.eye(SPACE.size))
    s.reject_since["gnss_pos"] = (0.5, 0.5)
    return s


def test_a_copy_shares_nothing_that_the_filter_changes_in_place():
    s = running_state()
    c = s.copy()
    assert [f.name for f in fields(c)] == [f.name for f in fields(s)]
    s.ekf.P[0, 0] = 7.0
    s.ekf.x[0] = 7.0
    s.estimates["ba"] *= 0.0
    s.estimates["ba"] += 7.0
    s.reject_since["gnss_vel"] = (2.0, 2.0)
    s.a_enu[0] = 7.0
    assert c.ekf.P[0, 0] == 1.0 and c.ekf.x[0] == 0.0 and c.ekf is not s.ekf
    assert np.all(c.estimates["ba"] == 0.0) and "gnss_vel" not in c.reject_since
    assert c.a_enu[0] == 0.0 and c.nav is s.nav  # NavState is immutable: shared


def test_rewind_keeps_checkpoints_of_the_history_and_replays_what_came_after():
    rewind = Rewind(history=1.0, interval=0.5)
    s = running_state(0.0)
    kept = []
    for k in range(10):  # epochs every 0.25 s
        s.nav = NavState(s.nav.lat, s.nav.lon, s.nav.h, s.nav.v_enu, s.nav.q_nb, 0.25 * k)
        s.next_sample = 10 * k
        rewind.applied(f"m{k}")
        kept.append(rewind.keep(s, k, 2 * k))
    times = [c.state.nav.t for c in rewind.checkpoints]
    assert times == [0.5, 1.0, 1.5, 2.0]  # the newest older than 2.0 - history stays
    assert kept[-1] is None and kept[-2] is rewind.checkpoints[0]
    assert not any(kept[:-2])
    cp = rewind.before(1.2)
    assert cp.state.nav.t == 1.0 and cp.epochs == 4 and cp.update_count == 8
    assert rewind.needed_sample(s) == 20
    again = rewind.back_to(cp)
    assert again == ["m5", "m6", "m7", "m8", "m9"]
    assert [c.state.nav.t for c in rewind.checkpoints] == [0.5, 1.0]
    assert rewind.applied_count == 5
    # The checkpoint itself is never changed: it can be restored again.
    restored = cp.state.copy()
    restored.ekf.P[0, 0] = 9.0
    assert cp.state.ekf.P[0, 0] == 1.0


def test_imu_buffer_numbers_survive_a_trim():
    buf = ImuBuffer()
    t = 0.01 * np.arange(1, 3001)
    th, dv = np.tile([1e-4, 0.0, 0.0], (3000, 1)), np.tile([0.0, 0.0, 0.098], (3000, 1))
    buf.add(t[:2500], th[:2500], dv[:2500], needed=0)
    buf.add(t[2500:], th[2500:], dv[2500:], needed=2100)  # at least keep_min: trimmed
    assert buf.first == 2100 and buf.end == 3000 and len(buf) == 900
    assert buf.time(2100) == t[2100] and buf.search(t[2600]) == 2601
    assert np.array_equal(buf.times(2500, 2502), t[2500:2502])
    # The coning and sculling terms of the second batch are chained to the first batch's last
    # sample: with constant increments its first sample gets the same terms as the others.
    cth, cdv = buf.rows(2100, 3000)[3:]
    assert np.any(cdv[0] != 0.0)
    assert np.array_equal(cth[400], cth[399]) and np.array_equal(cdv[400], cdv[399])


def test_mode_machine():
    A, N, D = modes.ALIGNING, modes.NAVIGATING, modes.DEAD_RECKONING
    assert modes.after_accepted(A, True) == A and modes.after_accepted(D, False) == N
    assert modes.after_accepted(N, True) == D
    assert modes.after_rejected(N, True) == D and modes.after_rejected(N, False) == N
    assert modes.after_rejected(A, True) == A
    assert modes.after_epoch(N, 10.0, 7.0, 2.0) == D and modes.after_epoch(A, 10.0, 7.0, 2.0) == A
    assert modes.after_epoch(N, 10.0, 9.0, 2.0) == N


def test_a_forced_kind_keeps_a_floor_that_decays_while_it_is_accepted():
    cfg = NavigatorConfig(noise=NOISE, floor_tau=10.0, confirm_time=10.0)
    guard = Integrity(cfg)
    ekf = ErrorStateEKF(SPACE, NOISE, np.eye(SPACE.size) * 0.01)
    H = np.zeros((3, SPACE.size))
    H[:, SPACE["pos"]] = np.eye(3)
    widened = []
    jump = Innovation("gnss_pos", np.array([30.0, 0.0, 0.0]), H, np.eye(3))
    res = guard.update(ekf, SPACE, jump, 5.0, 2.0, lambda s, v: widened.append(v))
    assert res.reason == "forced" and res.accepted and len(widened) == 1
    floor = guard.floors["gnss_pos"]
    assert [(name, list(axes)) for name, axes in floor.blocks] == [("pos", [0, 1, 2])]
    assert floor.var[0] == 900.0
    assert guard.degraded(5.0)
    var = guard.variances(SPACE)
    pos = SPACE["pos"]
    assert var[pos][0] == 900.0 and not np.delete(var, np.arange(pos.start, pos.stop)).any()
    ekf.take_correction()
    small = Innovation("gnss_pos", np.zeros(3), H, np.eye(3))
    guard.update(ekf, SPACE, small, 15.0, None, lambda s, v: None)
    assert np.isclose(guard.floors["gnss_pos"].var[0], 900.0 * np.exp(-1.0))
    # accepted for confirm_time since it was forced: confirmed, while the floor (331 m^2, far
    # beyond 9 x the 1 m^2 of the fixes) stays in the published covariance
    assert not guard.degraded(15.0) and guard.variances(SPACE)[pos][0] > 300.0
    guard.rejected("gnss_pos", 16.0)  # rejected again: not confirmed for 10 s from then
    guard.accepted("gnss_pos")
    assert guard.degraded(17.0) and guard.degraded(25.9) and not guard.degraded(26.0)


def test_the_vertical_velocity_forced_floors_its_own_axis_and_does_not_vouch():
    """The receiver's vertical velocity, gated apart from its horizontal rows: forced, it
    widens and floors the vertical velocity alone, and neither its rejections nor its floor
    degrade the solution (integrity.NOT_VOUCHING); the horizontal rows' do."""
    guard = Integrity(NavigatorConfig(noise=NOISE))
    ekf = ErrorStateEKF(SPACE, NOISE, np.eye(SPACE.size) * 0.01)
    H = np.zeros((3, SPACE.size))
    H[:, SPACE["vel"]] = np.eye(3)
    velocity = Innovation("gnss_vel", np.array([0.5, 0.0, 0.5]), H, np.eye(3) * 0.0025)
    up, vel = velocity.rows([2], GNSS_VEL_UP), SPACE["vel"].start
    for t in (1.0, 2.0, 3.0):
        guard.rejected(GNSS_VEL_UP, t)
    assert not guard.degraded(3.0)  # beyond suspect_time: a vouching kind would be
    widened = []
    res = guard.update(ekf, SPACE, up, 3.2, 1.0, lambda s, v: widened.append((s, v)))
    assert res.reason == "forced" and len(widened) == 1
    assert list(widened[0][0]) == [vel + 2] and list(widened[0][1]) == [0.25]
    var = guard.variances(SPACE)
    assert var[vel + 2] == 0.25 and not np.delete(var, vel + 2).any()
    assert not guard.degraded(3.2)
    ekf.take_correction()
    horizontal = velocity.rows([0, 1])
    assert guard.update(ekf, SPACE, horizontal, 3.4, 1.0, lambda s, v: None).reason == "forced"
    assert np.array_equal(guard.variances(SPACE)[vel:vel + 3], [0.25, 0.0, 0.25])
    assert guard.degraded(3.4)
