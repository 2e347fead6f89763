"""live_view: a Foxglove WebSocket client (the ``websockets`` package, speaking the subprotocol
the server selects) connects, reads the advertised channels, subscribes and decodes what the
node serves against the schemas the server advertised: nav/fix as a LocationFix with the
heading of ins/state, attitude, filter mode and logs; in process on the bus and as a process on
DDS; nothing is translated while no client watches; local-only by default."""

from __future__ import annotations

import base64
import json
import math
import re
import struct
import time

import numpy as np
import pytest
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from google.protobuf import descriptor_pb2, descriptor_pool, message_factory
from ins_gnss_msgs.msg import FilterStatus, InsState
from rclpy.parameter import Parameter
from sensor_msgs.msg import NavSatFix, NavSatStatus
from websockets.sync.client import connect

from ins_gnss_ros.io import sec_to_stamp
from ins_gnss_ros.nav.conventions import quat_from_seed_angles
from ins_gnss_ros.nodes.base import InProcessBus, ParameterError
from ins_gnss_ros.nodes.live_view_node import LiveViewNode
from rosutil import NodeProcess, spin_until, wait_for_endpoints

#: The Foxglove WebSocket subprotocols a client offers: the published protocol and the SDK's.
SUBPROTOCOLS = ["foxglove.websocket.v1", "foxglove.sdk.v1"]
STAMP_S = 1_767_225_600.25  # 2026-01-01 00:00:00.25 UTC
AZIMUTH, PITCH, ROLL = math.radians(30.0), math.radians(2.0), math.radians(-4.0)


class FoxgloveClient:
    """The client side of the Foxglove WebSocket protocol v1 (ws-protocol docs/spec.md):
    serverInfo and advertise (JSON), subscribe, message data (binary opcode 0x01: uint32
    subscription id, uint64 log time ns, payload), decoded with the advertised schema."""

    def __init__(self, url: str):
        self._connection = connect(url, subprotocols=SUBPROTOCOLS, open_timeout=10)

    def __enter__(self) -> "FoxgloveClient":
        self.ws = self._connection.__enter__()
        self.info = json.loads(self.ws.recv(timeout=10))
        self.channels = {}
        while not self.channels:
            msg = json.loads(self.ws.recv(timeout=10))
            if msg["op"] == "advertise":
                self.channels = {c["topic"]: c for c in msg["channels"]}
        self._subscriptions = {}
        return self

    def __exit__(self, *exc):
        return self._connection.__exit__(*exc)

    def subscribe(self, *topics: str) -> None:
        subs = [{"id": len(self._subscriptions) + i, "channelId": self.channels[t]["id"]}
                for i, t in enumerate(topics)]
        self._subscriptions.update({s["id"]: self.channels[t] for s, t in zip(subs, topics)})
        self.ws.send(json.dumps({"op": "subscribe", "subscriptions": subs}))

    def receive(self, timeout: float = 10.0):
        """(topic, log time ns, decoded message) of the next message data."""
        while True:
            data = self.ws.recv(timeout=timeout)
            if isinstance(data, bytes) and data[0] == 0x01:
                break
        _, sub, log_ns = struct.unpack_from("<BIQ", data)
        channel = self._subscriptions[sub]
        payload = data[13:]
        if channel["encoding"] == "json":
            return channel["topic"], log_ns, json.loads(payload)
        files = descriptor_pb2.FileDescriptorSet.FromString(base64.b64decode(channel["schema"]))
        pool = descriptor_pool.DescriptorPool()
        for f in files.file:
            pool.Add(f)
        cls = message_factory.GetMessageClass(pool.FindMessageTypeByName(channel["schemaName"]))
        return channel["topic"], log_ns, cls.FromString(payload)


def _wait(condition, timeout=10.0, what=""):
    deadline = time.monotonic() + timeout
    while not condition():
        assert time.monotonic() < deadline, f"timed out waiting for {what}"
        time.sleep(0.005)


def _fix(status=NavSatStatus.STATUS_FIX) -> NavSatFix:
    fix = NavSatFix()
    fix.header.stamp, fix.header.frame_id = sec_to_stamp(STAMP_S), "base_link"
    fix.status.status = status
    fix.latitude, fix.longitude, fix.altitude = 59.9342802, 30.3350986, 21.5
    fix.position_covariance = [0.25, 0.01, 0.0, 0.01, 0.36, 0.0, 0.0, 0.0, 1.44]
    fix.position_covariance_type = NavSatFix.COVARIANCE_TYPE_KNOWN
    return fix


def _state() -> InsState:
    state = InsState(mode=InsState.MODE_NAVIGATING)
    state.header.stamp = sec_to_stamp(STAMP_S - 0.01)
    w, x, y, z = quat_from_seed_angles(AZIMUTH, PITCH, ROLL)
    state.orientation.w, state.orientation.x, state.orientation.y, state.orientation.z = \
        float(w), float(x), float(y), float(z)
    state.velocity.x, state.velocity.y = 3.0, 4.0
    return state


def _check_location_fix(fix, log_ns, expected: NavSatFix, heading):
    assert log_ns == expected.header.stamp.sec * 10**9 + expected.header.stamp.nanosec
    assert (fix.timestamp.seconds, fix.timestamp.nanos) == (expected.header.stamp.sec,
                                                            expected.header.stamp.nanosec)
    assert (fix.latitude, fix.longitude, fix.altitude) == (expected.latitude, expected.longitude,
                                                           expected.altitude)
    assert list(fix.position_covariance) == list(expected.position_covariance)
    assert fix.position_covariance_type == 3  # KNOWN, as NavSatFix.COVARIANCE_TYPE_KNOWN
    assert fix.frame_id == "base_link"
    if heading is None:
        assert not fix.HasField("heading")
    else:
        assert fix.heading == pytest.approx(heading, abs=1e-12)


@pytest.fixture
def on_bus(ros_context):
    bus = InProcessBus()
    node = LiveViewNode(context=ros_context, bus=bus,
                        parameter_overrides=[Parameter("port", value=0)])
    yield bus, node
    node.destroy_node()


def test_client_decodes_nav_fix_attitude_status_and_logs(on_bus):
    bus, node = on_bus
    with FoxgloveClient(node.url) as client:
        assert client.ws.subprotocol in SUBPROTOCOLS
        assert client.info["op"] == "serverInfo" and client.info["capabilities"] == []
        schemas = {t: c["schemaName"] for t, c in client.channels.items()}
        assert schemas["/nav/fix"] == schemas["/gnss/fix"] == "foxglove.LocationFix"
        assert schemas["/nav/odom"] == "foxglove.PoseInFrame"
        assert schemas["/nav/odom/tf"] == "foxglove.FrameTransform"
        assert schemas["/diagnostics"] == "foxglove.Log"
        assert {"/ins/state/attitude", "/nav/status"} <= set(schemas)

        client.subscribe("/nav/fix")
        _wait(lambda: node.view.watched("nav/fix"), what="the nav/fix subscription")
        bus.publish("nav/fix", _fix())  # before any ins/state: no heading
        bus.drain()
        topic, log_ns, fix = client.receive()
        assert topic == "/nav/fix"
        _check_location_fix(fix, log_ns, _fix(), None)
        assert fix.color.b > fix.color.r  # a fix: blue

        client.subscribe("/ins/state/attitude", "/nav/status", "/diagnostics")
        _wait(lambda: all(node.view.watched(t) for t in ("ins/state", "nav/status",
                                                         "/diagnostics")), what="subscriptions")
        bus.publish("ins/state", _state())
        bus.drain()
        _, _, attitude = client.receive()
        assert attitude["heading_deg"] == pytest.approx(30.0, abs=1e-9)
        assert attitude["pitch_deg"] == pytest.approx(2.0, abs=1e-9)
        assert attitude["roll_deg"] == pytest.approx(-4.0, abs=1e-9)
        assert attitude["speed_mps"] == pytest.approx(5.0)
        assert attitude["mode"] == "NAVIGATING"

        bus.publish("nav/fix", _fix(NavSatStatus.STATUS_NO_FIX))
        bus.drain()
        _, log_ns, fix = client.receive()
        _check_location_fix(fix, log_ns, _fix(), AZIMUTH)  # heading of the latest ins/state
        assert fix.color.r > fix.color.b  # no fix (dead reckoning): red

        status = FilterStatus(mode=FilterStatus.MODE_DEAD_RECKONING,
                              coupling=FilterStatus.COUPLING_TIGHT, accepted_count=7,
                              state_names=["pos[0]"], state_std=[1.5])
        status.header.stamp = sec_to_stamp(STAMP_S)
        bus.publish("nav/status", status)
        array = DiagnosticArray(status=[DiagnosticStatus(
            level=DiagnosticStatus.WARN, name="/ekf", message="aligning",
            values=[KeyValue(key="gnss/fix rate", value="0")])])
        array.header.stamp = sec_to_stamp(STAMP_S)
        bus.publish("/diagnostics", array)
        bus.drain()
        _, _, status = client.receive()
        assert (status["mode"], status["coupling"]) == ("DEAD_RECKONING", "TIGHT")
        assert status["accepted_count"] == 7 and status["state_std"] == {"pos[0]": 1.5}
        _, _, log = client.receive()
        assert log.name == "/ekf" and log.message == "aligning (gnss/fix rate=0)"
        assert log.level == 3  # WARNING


def test_nothing_is_translated_while_no_client_watches(on_bus):
    """Without a subscribed client a message is not even read: an object with none of the
    fields is forwarded without error (and counts nothing)."""
    bus, node = on_bus
    for topic in ("nav/fix", "gnss/fix", "nav/odom", "ins/state", "nav/status", "/diagnostics"):
        bus.publish(topic, object())
    bus.drain()
    assert not node.diag.counts


def test_bad_input_is_counted_not_raised(on_bus):
    bus, node = on_bus
    with FoxgloveClient(node.url) as client:
        client.subscribe("/gnss/fix")
        _wait(lambda: node.view.watched("gnss/fix"), what="the gnss/fix subscription")
        bad = _fix()
        bad.position_covariance_type = 7
        bus.publish("gnss/fix", bad)
        bus.drain()
        assert node.diag.counts == {"gnss/fix: not translatable (IndexError)": 1}


def test_local_only_by_default_and_a_busy_port_is_one_error(ros_context, on_bus):
    _, node = on_bus
    assert LiveViewNode.PARAMS[0].name == "host" and LiveViewNode.PARAMS[0].default == "127.0.0.1"
    assert node.url.startswith("ws://127.0.0.1:")
    with pytest.raises(ParameterError, match=f"cannot serve on 127.0.0.1:{node.view.port}"):
        LiveViewNode(context=ros_context, bus=InProcessBus(),
                     parameter_overrides=[Parameter("port", value=node.view.port)])


def test_process_on_dds_serves_a_published_nav_fix(probe, executor):
    """The console script with any free port: nav/fix published over DDS reaches the client."""
    publisher = probe.create_publisher(NavSatFix, "/nav/fix", 10)
    with NodeProcess("live_view", "-p", "port:=0") as proc:
        proc.wait_on_graph(probe, executor)
        wait_for_endpoints(probe, executor, subscribes=["/nav/fix", "/ins/state"])
        url = []
        spin_until(executor, lambda: url.extend(re.findall(r"ws://127\.0\.0\.1:\d+",
                                                          proc.output())) or url,
                   20, "the live view's address in its log")
        with FoxgloveClient(url[0]) as client:
            client.subscribe("/nav/fix")
            received = []

            def arrived():  # publish until the subscription is through to the server
                publisher.publish(_fix())
                try:
                    received.append(client.receive(timeout=0.05))
                except TimeoutError:
                    pass
                return received

            spin_until(executor, arrived, 20, "a LocationFix from the process")
            _, log_ns, fix = received[0]
            _check_location_fix(fix, log_ns, _fix(), None)
        assert proc.stop() == 0, proc.output()


def test_a_profile_with_a_live_view_section_replays_it_and_changes_no_output(tmp_path):
    """The live view is an optional node of the graph: a profile section starts it in
    `trial replay` (config/default.yaml has none), and watching changes nothing the graph
    publishes."""
    from ins_gnss_ros.trial.compare import compare
    from ins_gnss_ros.trial.replay import replay
    from ins_gnss_ros.trial.simulate import SimOptions, simulate

    bag = simulate("car", 3.0, 5, tmp_path / "car",
                   SimOptions(imu_topic="delta", imu_grade="navigation"))
    plain = tmp_path / "plain.yaml"
    plain.write_text("strapdown:\n  ros__parameters:\n    init.latitude_deg: 0.0\n"
                     "    init.longitude_deg: 0.0\n")
    viewed = tmp_path / "viewed.yaml"
    viewed.write_text(plain.read_text() + "live_view:\n  ros__parameters:\n    port: 0\n")
    assert replay(bag, plain, tmp_path / "a", init_from_truth=True)["graph"] == ["strapdown"]
    summary = replay(bag, viewed, tmp_path / "b", init_from_truth=True)
    assert summary["graph"] == ["strapdown", "live_view"]
    assert compare(tmp_path / "a", tmp_path / "b").identical
