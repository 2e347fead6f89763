"""The per-message helpers of the nodes: stamps and in-place message filling."""

from __future__ import annotations

import numpy as np
from ins_gnss_msgs.msg import InsState

from ins_gnss_ros.io import sec_to_stamp, stamp_to_sec
from ins_gnss_ros.nav.strapdown import NavState
from ins_gnss_ros.nodes.convert import fill_ins_state, nav_state_from_msg


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
