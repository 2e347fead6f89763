"""strapdown node in-process: stationary navigation and late corrections against known truth."""

from __future__ import annotations

import numpy as np
import pytest
from rclpy.parameter import Parameter

from ins_gnss_ros.io import codec, sec_to_stamp
from ins_gnss_ros.nav.earth import WGS84, earth_rate_enu, normal_gravity, radii
from ins_gnss_ros.nodes.convert import to_vector3

LAT = np.radians(60.0)
DT = 0.01


def _payload(msg) -> bytes:
    """An ImuDelta as the nodes take it: its CDR payload."""
    from ins_gnss_msgs.msg import ImuDelta

    from ins_gnss_ros.io import codec

    return codec(ImuDelta).encode(msg)


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
        node.on_delta(_payload(_delta(t0 + k * DT)))
    # The filter found, for the epoch 0.5 s ago, a 10 m north position error.
    corr = InsCorrection(sequence=1, mode=InsCorrection.MODE_NAVIGATING)
    corr.header.stamp = sec_to_stamp(t0 + 0.5)
    corr.position_error.y = 10.0
    node.on_correction(corr)
    state = node.loop.state
    rm, _ = radii(LAT)
    assert state.t == pytest.approx(t0 + 1.0)
    assert (state.lat - LAT) * rm == pytest.approx(0.0, abs=1e-4)
    assert np.degrees(state.lon) == pytest.approx(30.0, abs=1e-9)
    assert np.abs(state.v_enu).max() < 1e-5
    assert node.loop.correction_sequence == 1


def test_bad_increments_are_counted_not_used(node):
    msg = _delta(5.0)
    node.on_delta(_payload(msg))
    bad = _delta(5.01)
    bad.delta_angle.x = float("nan")
    node.on_delta(_payload(bad))
    node.on_delta(_payload(_delta(5.0)))  # backwards in time
    for variance in (-1e-9, float("inf")):  # what a bridge may miss: never negative or infinite
        odd = _delta(5.01)
        odd.bridged_angle_variance = variance
        node.on_delta(_payload(odd))
    assert node.loop.state.t == pytest.approx(5.0)
    assert sum(node.diag.counts.values()) == 4
    assert node.diag.counts["increment with a negative or non-finite bridged variance dropped"] \
        == 2


def test_gap_is_bridged_by_held_rates_and_a_long_gap_loses_the_imu(node):
    """At rest (constant increments) holding the rates over a 0.5 s gap is exact: the state
    stays at rest. A gap beyond max_imu_gap_s (2.5 s) starts a new run: ins/state is INVALID until
    a correction of this run arrives; a correction of the old run is ignored."""
    from ins_gnss_msgs.msg import InsCorrection, InsState

    published = []
    # the messages (decoded payloads), without the DDS round trip
    node.pub.publish = lambda data: published.append(codec(InsState).decode(data))
    t0 = 1000.0
    for k in range(1, 51):
        node.on_delta(_payload(_delta(t0 + k * DT)))
    node.on_delta(_payload(_delta(t0 + 1.0)))  # 0.49 s of increments lost
    assert node.diag.counts["gap in increments: bridged by holding the rates"] == 1
    assert node.loop.state.t == pytest.approx(t0 + 1.0)
    assert np.abs(node.loop.state.v_enu).max() < 1e-3  # without holding: 4.8 m/s of free fall
    assert published[-1].mode == InsState.MODE_ALIGNING  # no correction yet
    node.on_delta(_payload(_delta(t0 + 5.0)))  # 4 s lost: the IMU was lost
    assert node.diag.counts["imu lost: gap in increments beyond max_imu_gap_s, new run"] == 1
    assert published[-1].mode == InsState.MODE_INVALID
    old = InsCorrection(sequence=1, mode=InsCorrection.MODE_NAVIGATING)
    old.header.stamp = sec_to_stamp(t0 + 0.5)
    node.on_correction(old)
    assert node.diag.counts["correction older than this run ignored"] == 1
    node.on_delta(_payload(_delta(t0 + 5.0 + DT)))
    assert published[-1].mode == InsState.MODE_INVALID
    new = InsCorrection(sequence=2, mode=InsCorrection.MODE_NAVIGATING)
    new.header.stamp = sec_to_stamp(t0 + 5.0)
    node.on_correction(new)
    node.on_delta(_payload(_delta(t0 + 5.0 + 2 * DT)))
    assert published[-1].mode == InsState.MODE_NAVIGATING
    assert published[-1].correction_sequence == 2
    for k in range(3, 214):  # 2.1 s without a correction: aligned once, dead reckoning now
        node.on_delta(_payload(_delta(t0 + 5.0 + k * DT)))
    assert published[-1].mode == InsState.MODE_DEAD_RECKONING


def test_ins_state_says_the_mode_of_the_filter_that_corrected_it(node):
    """A filter levelled at rest corrects the strapdown while it is still ALIGNING: ins/state
    says ALIGNING (levelled: sequence > 0) until a correction made NAVIGATING, and
    DEAD_RECKONING for one made degraded. A correction with a mode no filter has is
    rejected."""
    from ins_gnss_msgs.msg import InsCorrection, InsState

    published = []
    node.pub.publish = lambda data: published.append(codec(InsState).decode(data))
    t0 = 1000.0

    def correct(sequence, mode, k):
        msg = InsCorrection(sequence=sequence, mode=mode)
        msg.header.stamp = sec_to_stamp(t0 + k * DT)
        node.on_correction(msg)

    for k in range(1, 51):
        node.on_delta(_payload(_delta(t0 + k * DT)))
    assert (published[-1].mode, published[-1].correction_sequence) == (InsState.MODE_ALIGNING, 0)
    correct(1, InsCorrection.MODE_ALIGNING, 50)
    node.on_delta(_payload(_delta(t0 + 51 * DT)))
    assert (published[-1].mode, published[-1].correction_sequence) == (InsState.MODE_ALIGNING, 1)
    correct(2, InsCorrection.MODE_NAVIGATING, 51)
    node.on_delta(_payload(_delta(t0 + 52 * DT)))
    assert published[-1].mode == InsState.MODE_NAVIGATING
    correct(3, InsCorrection.MODE_DEAD_RECKONING, 52)
    node.on_delta(_payload(_delta(t0 + 53 * DT)))
    assert published[-1].mode == InsState.MODE_DEAD_RECKONING
    correct(4, 7, 53)
    node.on_delta(_payload(_delta(t0 + 54 * DT)))
    assert node.diag.counts["correction with an unknown mode rejected"] == 1
    assert (published[-1].mode, published[-1].correction_sequence) == \
        (InsState.MODE_DEAD_RECKONING, 3)


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
    assert states[-1].mode == InsState.MODE_ALIGNING  # no filter running: never corrected
    assert states[-1].header.stamp == sec_to_stamp(10.03)


def test_counts_its_traffic_on_dds(node, executor, probe):
    """The counters bench/live_load.py reads from /diagnostics: messages taken and published
    per topic."""
    from ins_gnss_msgs.msg import ImuDelta, InsState

    from ins_gnss_ros.nodes.base import SENSOR_QOS
    from rosutil import spin_until

    states = []
    probe.create_subscription(InsState, "ins/state", states.append, SENSOR_QOS)
    pub = probe.create_publisher(ImuDelta, "imu/delta", SENSOR_QOS)
    spin_until(executor, lambda: pub.get_subscription_count() > 0, what="strapdown subscription")
    for k in range(3):
        pub.publish(_delta(DT * (k + 1)))
    spin_until(executor, lambda: len(states) == 3, what="ins/state")
    assert node.diag.traffic == {"received /imu/delta": 3, "published /ins/state": 3}
