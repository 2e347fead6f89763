"""The node base: parameter validation, diagnostics, sim time, executors and signal handling."""

from __future__ import annotations

import os
import signal
import subprocess

import pytest
from rclpy.exceptions import InvalidParameterValueException
from rclpy.node import Node
from rclpy.parameter import Parameter

from ins_gnss_ros.nodes.base import EXECUTOR_ENV, EXECUTORS, NavNode, Param, ParameterError
from rosutil import VENV_BIN, NodeProcess, spin_until


def test_param_validation_names_the_parameter():
    lever = Param("lever_arm", [0.0, 0.0, 0.0], "antenna lever arm FLU, m", -50.0, 50.0, length=3)
    assert lever.validate([1.0, 2.0, 3.0]) == [1.0, 2.0, 3.0]
    with pytest.raises(ParameterError, match="lever_arm"):
        lever.validate([1.0, 2.0])
    with pytest.raises(ParameterError, match="lever_arm.*outside"):
        lever.validate([1.0, 2.0, 99.0])
    with pytest.raises(ParameterError, match="not finite"):
        Param("rate", 1.0, "rate, Hz", 0.0, 10.0).validate(float("nan"))
    with pytest.raises(ParameterError, match="one of"):
        Param("mode", "loose", "coupling", choices=("loose", "tight")).validate("medium")


class _Counting(NavNode):
    PARAMS = (Param("gain", 0.5, "a gain, -", 0.0, 1.0),)

    def __init__(self, **kwargs):
        super().__init__("counting", **kwargs)


def test_diagnostics_report_counts_and_use_sim_time(executor, probe, ros_context):
    from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus
    from rosgraph_msgs.msg import Clock

    node = _Counting(context=ros_context, parameter_overrides=[Parameter("use_sim_time", value=True)])
    executor.add_node(node)
    assert node.p["gain"] == 0.5
    arrays: list[DiagnosticArray] = []
    probe.create_subscription(DiagnosticArray, "/diagnostics", arrays.append, 10)
    clock = probe.create_publisher(Clock, "/clock", 10)
    spin_until(executor, lambda: clock.get_subscription_count() > 0, what="/clock subscriber")
    msg = Clock()
    msg.clock.sec = 1234
    clock.publish(msg)
    spin_until(executor, lambda: node.now_ns() == 1234 * 10**9, what="sim time")
    node.diag.count("bad sample: NaN")
    node.diag.publish()
    spin_until(executor, lambda: any(a.status[0].values for a in arrays), what="diagnostics")
    status = [a for a in arrays if a.status[0].values][-1].status[0]
    assert status.level == DiagnosticStatus.WARN
    assert {kv.key: kv.value for kv in status.values} == {"bad sample: NaN": "1"}
    assert [a for a in arrays if a.status[0].values][-1].header.stamp.sec == 1234


class _Refusing(_Counting):
    def __init__(self, **kwargs):
        super().__init__(**kwargs)
        raise ParameterError("parameter 'gain': refused")


@pytest.mark.parametrize("node_class, gain, match", [(_Counting, 2.0, "gain"),
                                                     (_Refusing, 0.5, "refused")])
def test_a_node_whose_constructor_raises_destroys_itself(ros_context, monkeypatch, node_class,
                                                         gain, match):
    destroyed = []
    monkeypatch.setattr(NavNode, "destroy_node",
                        lambda self: destroyed.append(Node.destroy_node(self)))
    with pytest.raises((ParameterError, InvalidParameterValueException), match=match):
        node_class(context=ros_context, parameter_overrides=[Parameter("gain", value=gain)])
    assert len(destroyed) == 1


def test_now_is_the_system_time_without_sim_time(ros_context):
    import time

    node = _Counting(context=ros_context)
    try:
        before = time.time_ns()
        assert before <= node.now_ns() <= time.time_ns()
    finally:
        node.destroy_node()


def test_a_volatile_output_is_wanted_while_someone_subscribes(executor, probe, ros_context):
    from sensor_msgs.msg import Imu

    from ins_gnss_ros.nodes.base import SENSOR_QOS

    node = _Counting(context=ros_context)
    executor.add_node(node)
    pub = node.publisher(Imu, "base_test/imu", SENSOR_QOS)
    assert not pub.wanted()
    got = []
    sub = probe.create_subscription(Imu, "base_test/imu", got.append, SENSOR_QOS)
    spin_until(executor, pub.wanted, what="the subscriber matched")
    pub.publish(Imu())
    spin_until(executor, lambda: got, what="the message")
    probe.destroy_subscription(sub)
    spin_until(executor, lambda: not pub.wanted(), what="the subscriber gone")
    pub.publish(Imu())  # skipped, not counted
    assert node.diag.traffic["published /base_test/imu"] == 1


def test_a_queued_subscription_hands_over_every_message_in_order_when_asked(
        executor, probe, ros_context):
    from ins_gnss_msgs.msg import InsState

    from ins_gnss_ros.io import sec_to_stamp
    from ins_gnss_ros.nodes.base import SENSOR_QOS

    node = _Counting(context=ros_context)
    executor.add_node(node)
    handled = []
    queued = node.subscribe_queued(InsState, "base_test/state", SENSOR_QOS, handled.append)
    pub = probe.create_publisher(InsState, "base_test/state", SENSOR_QOS)
    spin_until(executor, lambda: pub.get_subscription_count() > 0, what="the subscription")
    for k in range(1, 4):
        state = InsState(correction_sequence=k)
        state.header.stamp = sec_to_stamp(0.01 * k)
        pub.publish(state)
    # Nothing is dispatched: the messages wait until the node asks for them.
    spin_until(executor, lambda: queued.handle() or len(handled) == 3, what="three states")
    assert [m.correction_sequence for m in handled] == [1, 2, 3]
    assert handled[2].header.stamp == sec_to_stamp(0.03)
    assert node.diag.traffic["received /base_test/state"] == 3
    assert "/base_test/state" not in {sub.topic_name for sub in node.subscriptions}
    # What came is handed over, and counted, before the node reports its counts (1 Hz)
    pub.publish(InsState(correction_sequence=4))
    spin_until(executor, lambda: len(handled) == 4, what="the fourth state, at /diagnostics")
    assert node.diag.traffic["received /base_test/state"] == 4


def test_on_the_bus_a_queued_subscription_is_handled_as_it_comes(ros_context):
    from ins_gnss_msgs.msg import InsState

    from ins_gnss_ros.nodes.base import SENSOR_QOS, InProcessBus

    bus = InProcessBus()
    node = _Counting(context=ros_context, bus=bus)
    handled = []
    queued = node.subscribe_queued(InsState, "state", SENSOR_QOS, handled.append)
    msgs = [InsState(correction_sequence=k) for k in range(3)]
    for msg in msgs:
        bus.publish("state", msg)
    bus.drain()
    assert [id(m) for m in handled] == [id(m) for m in msgs]
    queued.handle()  # nothing waits
    assert len(handled) == 3
    node.destroy_node()


def test_a_latest_subscription_once_stopped_receives_nothing(executor, probe, ros_context):
    """A node that needs a stream only for a while (the ekf: one raw IMU sample's frame) stops
    its subscription: on DDS it is gone (the publisher no longer delivers to it, its process
    is no longer woken), on the bus nothing more is kept."""
    from ins_gnss_msgs.msg import InsState

    from ins_gnss_ros.nodes.base import SENSOR_QOS, InProcessBus

    node = _Counting(context=ros_context)
    executor.add_node(node)
    latest = node.subscribe_latest(InsState, "base_test/latest", SENSOR_QOS, None)
    pub = probe.create_publisher(InsState, "base_test/latest", SENSOR_QOS)
    spin_until(executor, lambda: pub.get_subscription_count() > 0, what="the subscription")
    pub.publish(InsState(correction_sequence=1))
    spin_until(executor, lambda: latest.waiting, what="the state")
    assert latest.take().correction_sequence == 1
    latest.stop()
    spin_until(executor, lambda: pub.get_subscription_count() == 0, what="the subscription gone")
    pub.publish(InsState(correction_sequence=2))
    assert latest.take() is None and not latest.waiting

    bus = InProcessBus()
    on_bus = _Counting(context=ros_context, bus=bus)
    latest = on_bus.subscribe_latest(InsState, "state", SENSOR_QOS, None)
    bus.publish("state", InsState(correction_sequence=1))
    bus.drain()
    latest.stop()
    bus.publish("state", InsState(correction_sequence=2))
    bus.drain()
    assert latest.take() is None
    on_bus.destroy_node()


def test_a_paced_subscription_handles_what_came_while_it_rested(executor, probe, ros_context):
    import time

    from sensor_msgs.msg import Imu

    from ins_gnss_ros.io import ns_to_stamp, stamp_to_ns
    from ins_gnss_ros.nodes.base import DRIVER_QOS, Paced

    node = _Counting(context=ros_context)
    executor.add_node(node)
    handled = []  # (stamp, when)

    def on_imu(msg):
        handled.append((stamp_to_ns(msg.header.stamp), time.monotonic_ns()))
        # The next message needed at once is far off: those before it may wait.
        paced.due(stamp_to_ns(msg.header.stamp) + 10**9)
    paced = node.subscribe_paced(Imu, "base_test/imu_raw", on_imu, DRIVER_QOS)
    pub = probe.create_publisher(Imu, "base_test/imu_raw", DRIVER_QOS)
    spin_until(executor, lambda: pub.get_subscription_count() > 0, what="the subscription")
    def sample(stamp_ns):
        msg = Imu()
        msg.header.stamp = ns_to_stamp(stamp_ns)
        return msg
    t0 = time.time_ns()
    pub.publish(sample(t0))
    spin_until(executor, lambda: handled, what="the first sample")  # the forecast learns
    for k in range(1, 4):
        pub.publish(sample(t0 + k))
    spin_until(executor, lambda: len(handled) == 4, what="three more samples")
    assert [stamp - t0 for stamp, _ in handled] == [0, 1, 2, 3]
    # The second sample's callback rested (at most MAX_REST_NS) and then took the other two.
    assert handled[2][1] - handled[1][1] >= 0.9 * Paced.MAX_REST_NS
    assert handled[3][1] - handled[2][1] < Paced.MAX_REST_NS
    assert node.diag.traffic["received /base_test/imu_raw"] == 4


def test_on_the_bus_a_paced_subscription_is_handled_as_it_comes(ros_context):
    from sensor_msgs.msg import Imu

    from ins_gnss_ros.io import codec
    from ins_gnss_ros.nodes.base import DRIVER_QOS, InProcessBus

    bus = InProcessBus()
    node = _Counting(context=ros_context, bus=bus)
    handled, payloads = [], []
    paced = node.subscribe_paced(Imu, "imu_raw", handled.append, DRIVER_QOS)
    node.subscribe_paced(Imu, "imu_raw", payloads.append, DRIVER_QOS, serialized=True)
    paced.due(10**18)  # nothing to wait for on the bus
    msgs = [Imu() for _ in range(3)]
    for msg in msgs:
        bus.publish("imu_raw", msg)
    bus.drain()
    assert [id(m) for m in handled] == [id(m) for m in msgs]
    assert payloads == [codec(Imu).encode(m) for m in msgs]
    node.destroy_node()


@pytest.mark.parametrize("kind", EXECUTORS)
@pytest.mark.parametrize("sig", [signal.SIGINT, signal.SIGTERM])
def test_node_process_shuts_down_cleanly_on_signal(sig, kind, probe, executor, monkeypatch):
    monkeypatch.setenv(EXECUTOR_ENV, kind)
    with NodeProcess("strapdown") as proc:
        proc.wait_on_graph(probe, executor)
        assert proc.stop(sig) == 0, proc.output()


def test_unknown_executor_is_a_one_line_error():
    env = dict(os.environ, **{EXECUTOR_ENV: "fastest"})
    done = subprocess.run([str(VENV_BIN / "strapdown")], env=env, capture_output=True, text=True,
                          timeout=60)
    assert done.returncode == 2
    assert done.stderr.strip().splitlines() == [
        f"error: executor 'fastest' ({EXECUTOR_ENV}) is not one of events, single"]


def test_default_executor_serves_timers_and_parameter_services(probe, executor):
    """The events executor (default) fires the diagnostics timer and answers parameter requests."""
    from diagnostic_msgs.msg import DiagnosticArray
    from rcl_interfaces.srv import GetParameters

    arrays: list[DiagnosticArray] = []
    probe.create_subscription(DiagnosticArray, "/diagnostics", arrays.append, 10)
    client = probe.create_client(GetParameters, "/strapdown/get_parameters")
    with NodeProcess("strapdown", "-p", "history_s:=7.5") as proc:
        proc.wait_on_graph(probe, executor)
        spin_until(executor, lambda: any(a.status[0].hardware_id == "strapdown" for a in arrays),
                   what="/diagnostics from the strapdown's 1 Hz timer")
        spin_until(executor, client.service_is_ready, what="the parameter service")
        future = client.call_async(GetParameters.Request(names=["history_s"]))
        spin_until(executor, future.done, what="the parameter reply")
        assert future.result().values[0].double_value == 7.5
        assert proc.stop() == 0, proc.output()


def test_in_process_bus_delivers_in_order_and_records(ros_context):
    from ins_gnss_msgs.msg import ImuDelta, InsState

    from ins_gnss_ros.nodes.base import InProcessBus
    from ins_gnss_ros.io import sec_to_stamp
    from ins_gnss_ros.nodes.strapdown_node import StrapdownNode

    bus = InProcessBus()
    recorded = []
    bus.recorders.append(lambda topic, msg: recorded.append((topic, type(msg).__name__)))
    node = StrapdownNode(context=ros_context, bus=bus)
    states = []
    bus.subscribe("ins/state", states.append)
    for k in range(1, 4):
        delta = ImuDelta(dt=0.01)
        delta.header.stamp = sec_to_stamp(k * 0.01)
        delta.delta_velocity.z = 9.81 * 0.01
        bus.publish("imu/delta", delta)
        bus.drain()  # a replay drains after every input message
    node.destroy_node()
    assert [type(s) for s in states] == [InsState] * 3
    assert [s.header.stamp for s in states] == [sec_to_stamp(k * 0.01) for k in range(1, 4)]
    assert recorded == [("/imu/delta", "ImuDelta"), ("/ins/state", "InsState")] * 3


def test_now_msg_equals_rclpy_time_conversion(ros_context):
    """now_msg builds the stamp from integer ns itself: the same stamp as rclpy's
    Time.to_msg, on the bus' replay time and on the node clock."""
    import rclpy.time

    from ins_gnss_ros.nodes.base import InProcessBus

    bus = InProcessBus()
    on_bus = NavNode("now_on_bus", context=ros_context, bus=bus)
    for t_ns in (0, 999_999_999, 1_000_000_000, 1_767_225_600_123_456_789):
        bus.now_ns = t_ns
        assert on_bus.now_ns() == t_ns
        assert on_bus.now_msg() == rclpy.time.Time(nanoseconds=t_ns).to_msg()
    on_bus.destroy_node()
    on_clock = NavNode("now_on_clock", context=ros_context)
    before = on_clock.get_clock().now().nanoseconds
    stamp = on_clock.now_msg()
    t_ns = stamp.sec * 1_000_000_000 + stamp.nanosec
    assert before <= t_ns <= on_clock.get_clock().now().nanoseconds
    on_clock.destroy_node()


def test_the_bus_hands_each_form_and_converts_once(ros_context):
    """A message travels as published, object or CDR payload: a subscriber of the other form
    gets it converted (once for all of them), one of either form gets it as it came; the
    recorders get objects, the raw recorders what was published, an input (``recorded``
    false) reaches neither; a topic carries one type, published or taken."""
    from ins_gnss_msgs.msg import ImuDelta
    from sensor_msgs.msg import Imu

    from ins_gnss_ros.io import codec, messages_equal, sec_to_stamp
    from ins_gnss_ros.nodes.base import InProcessBus

    bus = InProcessBus()
    node = _Counting(context=ros_context, bus=bus)
    pub = node.publisher(ImuDelta, "delta", 10)
    got = {form: [] for form in (bus.OBJECT, bus.PAYLOAD, bus.AS_PUBLISHED)}
    for form, seen in got.items():
        bus.subscribe("delta", seen.append, form)
    objects, raw = [], []
    bus.recorders.append(lambda topic, msg: objects.append(msg))
    bus.raw_recorders.append(lambda topic, msg, cls: raw.append((msg, cls)))
    delta = ImuDelta(dt=0.01)
    delta.header.stamp = sec_to_stamp(1.5)
    payload = codec(ImuDelta).encode(delta)
    pub.publish(delta)
    pub.publish(payload)
    bus.publish("delta", payload, recorded=False)
    bus.drain()
    obj, pay, as_published = got.values()
    assert obj[0] is delta and all(messages_equal(m, delta) for m in obj)
    assert obj[1] is objects[1]   # decoded once for the subscribers and the recorders
    assert pay == [payload] * 3 and pay[1] is payload
    assert as_published[0] is delta and as_published[1] is payload
    assert len(objects) == 2 and [cls for _, cls in raw] == [ImuDelta] * 2
    assert raw[0][0] is delta and raw[1][0] is payload
    with pytest.raises(TypeError, match="/delta: sensor_msgs/msg/Imu published where "
                                        "ins_gnss_msgs/msg/ImuDelta is"):
        node.publisher(Imu, "delta", 10)
    with pytest.raises(TypeError, match="/delta: sensor_msgs/msg/Imu"):
        node.subscribe(Imu, "delta", print, 10)
    node.destroy_node()
