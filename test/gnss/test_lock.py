"""Loss-of-lock flags: u-blox lock time and half-cycle flag, and the simulated receiver's."""
import math

from ins_gnss_ros.gnss.lock import HalfCycleTracker, LockTracker
from ins_gnss_ros.gnss.observations import RawEpoch, SatObs


def _obs(prn, lock_ms, phase=100.0, half_cycle=True):
    return SatObs("G", prn, 0, "1C", 1575.42e6, 2.0e7, 0.0, phase, 45.0, lock_ms, 0.3, 0.01,
                  0.1, half_cycle, False)


def _epoch(tow, obs, clock_reset=False):
    return RawEpoch(2381, tow, 18, True, clock_reset, obs)


def test_lock_tracker_flags_new_relocked_and_newly_usable_signals():
    lock = LockTracker()
    assert lock.update(_epoch(0.0, [_obs(1, 5000.0), _obs(2, 5000.0, half_cycle=False)])) \
        == [True, True]  # first sight
    # 1 s later: G01 locked throughout; G02's phase became usable (half cycle resolved).
    assert lock.update(_epoch(1.0, [_obs(1, 6000.0), _obs(2, 6000.0)])) == [False, True]
    # G01 re-locked 0.5 s ago (lock time shorter than the 1 s since the last epoch).
    assert lock.update(_epoch(2.0, [_obs(1, 500.0), _obs(2, 7000.0)])) == [True, False]
    assert lock.update(_epoch(3.0, [_obs(1, 1500.0), _obs(2, 8000.0)], clock_reset=True)) \
        == [True, True]
    assert lock.update(_epoch(4.0, [_obs(2, 9000.0, phase=math.nan)])) == [False]


def test_half_cycle_tracker_flags_the_epoch_a_phase_becomes_valid_per_antenna():
    track = HalfCycleTracker()
    pending, valid = _obs(1, 0.0, half_cycle=False), _obs(1, 0.0)
    assert track.update(0, _epoch(0.0, [pending]), [False]) == [False]
    assert track.update(1, _epoch(0.0, [valid]), [False]) == [True]   # antenna 1 on its own
    assert track.update(0, _epoch(1.0, [valid]), [False]) == [True]
    assert track.update(0, _epoch(2.0, [valid]), [False]) == [False]
    assert track.update(0, _epoch(3.0, [valid]), [True]) == [True]    # the simulator's slip
    assert track.update(0, _epoch(4.0, []), []) == []                 # G01 set
    assert track.update(0, _epoch(5.0, [valid]), [False]) == [True]   # risen again
