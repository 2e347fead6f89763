"""The per-message helpers of the nodes: in-place message filling and the ekf's state lookup."""

from __future__ import annotations

import math
from collections import deque
from types import SimpleNamespace

import numpy as np
from geometry_msgs.msg import Vector3
from ins_gnss_msgs.msg import InsState

from ins_gnss_ros.io import sec_to_stamp, stamp_to_sec
from ins_gnss_ros.nav.strapdown import NavState
from ins_gnss_ros.nodes.convert import fill_ins_state, increment_problem, nav_state_from_msg
from ins_gnss_ros.nodes.ekf_node import EkfNode


def test_stamps_round_trip_and_carry_into_the_next_second():
    assert (sec_to_stamp(1_750_000_000.25).sec, sec_to_stamp(1_750_000_000.25).nanosec) == \
        (1_750_000_000, 250_000_000)
    carried = sec_to_stamp(12.9999999999)  # rounds to 1e9 ns
    assert (carried.sec, carried.nanosec) == (13, 0)
    negative = sec_to_stamp(-0.5)
    assert (negative.sec, negative.nanosec) == (-1, 500_000_000)
    assert isinstance(sec_to_stamp(np.float64(3.5)).sec, int)


def test_fill_ins_state_round_trips_a_nav_state():
    state = NavState(1.0, 0.5, 20.0, np.array([1.0, -2.0, 0.5]),
                     np.array([0.5, 0.5, -0.5, 0.5]), 1_750_000_000.005)
    msg = InsState()
    fill_ins_state(msg, state)
    back = nav_state_from_msg(msg)
    assert (back.lat, back.lon, back.h) == (state.lat, state.lon, state.h)
    assert np.array_equal(back.v_enu, state.v_enu) and np.array_equal(back.q_nb, state.q_nb)
    assert abs(stamp_to_sec(msg.header.stamp) - state.t) < 1e-6
    assert all(isinstance(v, float) for v in (msg.velocity.x, msg.orientation.w))


def test_increment_problem_checks_every_component():
    from ins_gnss_msgs.msg import ImuDelta

    def delta(angle=(1e-3, -2e-3, 3e-3), velocity=(0.01, 0.0, 0.098), dt=0.01):
        return ImuDelta(delta_angle=Vector3(x=angle[0], y=angle[1], z=angle[2]),
                        delta_velocity=Vector3(x=velocity[0], y=velocity[1], z=velocity[2]),
                        dt=dt)

    assert increment_problem(delta()) is None
    non_finite = "non-finite or non-positive increment dropped"
    for bad in (math.nan, math.inf, -math.inf):
        for k in range(3):
            vector = [0.0, 0.0, 0.0]
            vector[k] = bad
            assert increment_problem(delta(angle=vector)) == non_finite
            assert increment_problem(delta(velocity=vector)) == non_finite
        assert increment_problem(delta(dt=bad)) == non_finite
    assert increment_problem(delta(dt=0.0)) == non_finite
    assert increment_problem(delta(angle=(1.01, 0.0, 0.0))) == "implausible increment dropped"
    assert increment_problem(delta(velocity=(0.0, 0.0, 101.0))) == "implausible increment dropped"


def test_ins_state_at_takes_the_newest_state_of_the_epoch_with_the_current_sequence():
    def state(sequence):
        return SimpleNamespace(correction_sequence=sequence)

    a, b, c, d = state(1), state(1), state(2), state(1)
    kept = deque([(1_000_000_000, a), (1_004_000_000, b), (1_005_000_000, c),
                  (1_005_500_000, d), (1_010_000_000, state(1))])
    ekf = SimpleNamespace(ins_states=kept, sequence=1)
    assert EkfNode.ins_state_at(ekf, 1_005_000_000) is d       # newest within 1 ms, sequence 1
    assert EkfNode.ins_state_at(ekf, 1_004_000_001) is b       # window (t - 1 ms, t + 1 ms)
    assert EkfNode.ins_state_at(ekf, 1_003_000_000) is None    # 1 ms away exactly: outside
    ekf.sequence = 2
    assert EkfNode.ins_state_at(ekf, 1_005_200_000) is c
    assert EkfNode.ins_state_at(SimpleNamespace(ins_states=deque(), sequence=1), 0) is None
