"""strapdown node in-process: stationary navigation and late corrections against known truth."""

from __future__ import annotations

import numpy as np
import pytest
from rclpy.parameter import Parameter

from ins_gnss_ros.nav.earth import WGS84, earth_rate_enu, normal_gravity, radii
from ins_gnss_ros.nodes.convert import sec_to_stamp, to_vector3

LAT = np.radians(60.0)
DT = 0.01


def _delta(t):
    from ins_gnss_msgs.msg import ImuDelta

    # Body axes = ENU axes (yaw 0: x east), at rest: the gyro sees Earth rate, the accelerometer
    # the reaction to gravity.
    msg = ImuDelta(dt=DT)
    msg.header.stamp = sec_to_stamp(t)
    msg.delta_angle = to_vector3(earth_rate_enu(LAT) * DT)
    msg.delta_velocity = to_vector3(np.array([0.0, 0.0, normal_gravity(LAT, 0.0)]) * DT)
    return msg


@pytest.fixture
def node(executor, ros_context):
    from ins_gnss_ros.nodes.strapdown_node import StrapdownNode

    north_offset_m = 10.0
    rm, _ = radii(LAT)
    overrides = [
        Parameter("init.latitude_deg", value=np.degrees(LAT + north_offset_m / rm)),
        Parameter("init.longitude_deg", value=30.0),
        Parameter("init.heading_deg", value=90.0),  # x axis east
    ]
    n = StrapdownNode(context=ros_context, parameter_overrides=overrides)
    executor.add_node(n)
    return n


def test_stationary_and_late_correction_recover_truth(node):
    from ins_gnss_msgs.msg import InsCorrection

    t0 = 1000.0
    for k in range(1, 101):
        node.on_delta(_delta(t0 + k * DT))
    # The filter found, for the epoch 0.5 s ago, a 10 m north position error.
    corr = InsCorrection(sequence=1)
    corr.header.stamp = sec_to_stamp(t0 + 0.5)
    corr.position_error.y = 10.0
    node.on_correction(corr)
    state = node.ins.state
    rm, _ = radii(LAT)
    assert state.t == pytest.approx(t0 + 1.0)
    assert (state.lat - LAT) * rm == pytest.approx(0.0, abs=1e-4)
    assert np.degrees(state.lon) == pytest.approx(30.0, abs=1e-9)
    assert np.abs(state.v_enu).max() < 1e-5
    assert node.correction_sequence == 1


def test_bad_increments_are_counted_not_used(node):
    msg = _delta(5.0)
    node.on_delta(msg)
    bad = _delta(5.01)
    bad.delta_angle.x = float("nan")
    node.on_delta(bad)
    node.on_delta(_delta(5.0))  # backwards in time
    assert node.ins.state.t == pytest.approx(5.0)
    assert sum(node.diag.counts.values()) == 2


def test_publishes_ins_state_over_ros(node, probe, executor):
    from ins_gnss_msgs.msg import ImuDelta, InsState

    from ins_gnss_ros.nodes.base import SENSOR_QOS
    from rosutil import spin_until

    states = []
    probe.create_subscription(InsState, "ins/state", states.append, SENSOR_QOS)
    pub = probe.create_publisher(ImuDelta, "imu/delta", SENSOR_QOS)
    spin_until(executor, lambda: pub.get_subscription_count() > 0, what="strapdown subscription")
    for k in range(1, 4):
        pub.publish(_delta(10.0 + k * DT))
    spin_until(executor, lambda: len(states) == 3, what="3 ins/state")
    assert states[-1].mode == InsState.MODE_DEAD_RECKONING  # no filter running
    assert states[-1].header.stamp == sec_to_stamp(10.03)
