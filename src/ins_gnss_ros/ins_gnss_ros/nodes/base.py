"""What every ins-gnss-ros node shares: validated parameters, QoS, diagnostics, start-up and shutdown.

A node subclasses :class:`NavNode`, lists its parameters as :class:`Param` specs (each with a
description and a range, checked once at start so that a bad value is one clear error naming the
parameter), creates its endpoints with ``self.publisher(...)``/``self.subscribe(...)`` and
:data:`SENSOR_QOS` or :data:`STATE_QOS`, counts what went wrong with ``self.diag.count(...)`` and is
started by :func:`run`, which turns SIGINT/SIGTERM into a clean shutdown and a parameter error into
exit status 2 instead of a traceback.

Given ``bus=InProcessBus()``, the same node exchanges messages through that bus instead of DDS:
deterministic, single-threaded and fast, which is how replays and tests run a whole graph in one
process. Navigation logic must therefore use message stamps, never the wall clock.
"""

from __future__ import annotations

import ctypes
import os
import sys
import time
from collections import Counter, defaultdict, deque
from functools import partial, wraps
from typing import Any, Callable, Sequence

import rclpy
from builtin_interfaces.msg import Time
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from rcl_interfaces.msg import FloatingPointRange, IntegerRange, ParameterDescriptor
from rclpy._rclpy_pybind11 import RCLError
from rclpy.event_handler import PublisherEventCallbacks
from rclpy.exceptions import ParameterException
from rclpy.experimental import EventsExecutor
from rclpy.executors import ExternalShutdownException, SingleThreadedExecutor
from rclpy.node import Node
from rclpy.parameter import Parameter
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
from rclpy.task import Future

from ..io import NS, ns_to_stamp, stamp_or_arrival
from ..io.arrival import ArrivalForecast
from ..io.cdr import codec, payload_stamp_ns
from ..io.messages import msgtype_of_class
from ..params import Param, ParameterError

# Sensor streams: reliable so that our own pipeline never silently drops an IMU increment (a
# reliable publisher still serves best-effort subscribers such as rviz), deep enough for 1 s of
# 200 Hz data while a subscriber is busy.
SENSOR_QOS = QoSProfile(
    history=HistoryPolicy.KEEP_LAST, depth=200, reliability=ReliabilityPolicy.RELIABLE
)
# Inputs from third-party sensor drivers, which publish best effort (REP-2003 SensorDataQoS): a
# best-effort subscription matches both best-effort and reliable publishers.
DRIVER_QOS = QoSProfile(
    history=HistoryPolicy.KEEP_LAST, depth=200, reliability=ReliabilityPolicy.BEST_EFFORT
)
# Navigation state, status and broadcast ephemerides: late joiners get the recent ones (deep
# enough for one ephemeris per satellite of a multi-constellation receiver).
STATE_QOS = QoSProfile(
    history=HistoryPolicy.KEEP_LAST,
    depth=100,
    reliability=ReliabilityPolicy.RELIABLE,
    durability=DurabilityPolicy.TRANSIENT_LOCAL,
)

# /tf and /tf_static as tf2_ros' TransformBroadcaster and StaticTransformBroadcaster offer them
# (REP-105 consumers subscribe with these); the static transforms reach late joiners.
TF_QOS = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=100,
                    reliability=ReliabilityPolicy.RELIABLE)
TF_STATIC_QOS = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=1,
                           reliability=ReliabilityPolicy.RELIABLE,
                           durability=DurabilityPolicy.TRANSIENT_LOCAL)
# The last value of a slowly changing fact (the datum), latched for late joiners.
LATCHED_QOS = TF_STATIC_QOS
# Reading /tf_static: every publisher's latched transforms (a URDF's, static_transform_
# publishers'), also those published before this node started.
TF_STATIC_READ_QOS = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=100,
                                reliability=ReliabilityPolicy.RELIABLE,
                                durability=DurabilityPolicy.TRANSIENT_LOCAL)


def descriptor(spec: Param) -> ParameterDescriptor:
    """The ROS descriptor of a parameter spec (ROS enforces scalar ranges itself; lists are
    checked by :meth:`Param.validate`)."""
    d = ParameterDescriptor(name=spec.name, description=spec.description)
    constraints = []
    if spec.low is not None or spec.high is not None:
        constraints.append(f"range [{spec.low}, {spec.high}]")
        if isinstance(spec.default, float):
            d.floating_point_range = [
                FloatingPointRange(from_value=float(spec.low), to_value=float(spec.high))
            ]
        elif isinstance(spec.default, int) and not isinstance(spec.default, bool):
            d.integer_range = [IntegerRange(from_value=int(spec.low), to_value=int(spec.high))]
    if spec.choices:
        constraints.append("one of " + ", ".join(spec.choices))
    if spec.length is not None:
        constraints.append(f"{spec.length} elements")
    d.additional_constraints = "; ".join(constraints)
    return d


class Diagnostics:
    """Counts events (bad samples, rejected updates, ...) and publishes them on /diagnostics.

    The level is the worst one reported since the last publication, so a transient fault is seen
    at least once by a monitor sampling at 1 Hz.
    """

    def __init__(self, node: "NavNode", period_s: float = 1.0):
        self._node = node
        self._pub = node.publisher(DiagnosticArray, "/diagnostics", 10)
        self.counts: Counter[str] = Counter()
        # Messages taken and published per topic, on DDS only (bench/live_load.py reads them):
        # "received /imu/delta", "published /ins/state".
        self.traffic: Counter[str] = Counter()
        self._level = DiagnosticStatus.OK
        self._message = "ok"
        self._values: dict[str, str] = {}
        self._state = (DiagnosticStatus.OK, "ok")  # a lasting condition, see set_state
        # Called first by publish: inputs the node takes only when it asks for them
        # (NavNode.subscribe_queued) are handled, and counted, before the counts go out.
        self.before_publish: list[Callable[[], None]] = []
        if node.bus is None:  # on a bus the replay publishes diagnostics on bag time
            node.create_timer(period_s, self.publish)

    def count(self, what: str, level: int = DiagnosticStatus.WARN, log: bool = True) -> None:
        """Record one occurrence of ``what``; log the first one and then every 100th."""
        self.counts[what] += 1
        if level > self._level:
            self._level, self._message = level, what
        n = self.counts[what]
        if log and (n == 1 or n % 100 == 0):
            self._node.get_logger().warning(f"{what} (x{n})")

    def set_value(self, key: str, value: Any) -> None:
        self._values[key] = str(value)

    def set_state(self, level: int, message: str) -> None:
        """A lasting condition (e.g. "aligning: no gnss/fix received yet"), reported with every
        publication until replaced; events of a higher level since the last publication take
        precedence for that one."""
        self._state = (level, message)

    def publish(self) -> None:
        for hook in self.before_publish:
            hook()
        level, message = max((self._state, (self._level, self._message)),
                             key=lambda state: state[0])
        status = DiagnosticStatus(
            level=level,
            name=f"{self._node.get_namespace().rstrip('/')}/{self._node.get_name()}",
            message=message,
            hardware_id=self._node.get_name(),
            values=[KeyValue(key=k, value=str(v)) for k, v in sorted(self.counts.items())]
            + [KeyValue(key=k, value=str(v)) for k, v in sorted(self.traffic.items())]
            + [KeyValue(key=k, value=v) for k, v in sorted(self._values.items())],
        )
        msg = DiagnosticArray(status=[status])
        msg.header.stamp = self._node.now_msg()
        self._pub.publish(msg)
        self._level, self._message = DiagnosticStatus.OK, "ok"


class InProcessBus:
    """Delivers messages between nodes of one process, in a deterministic order.

    ``publish`` only queues; :meth:`drain` delivers queued messages first-in first-out to the
    subscribers in the order they subscribed, including what their callbacks publish in turn.
    A message travels as it was published, a message object or its CDR payload (``bytes``, of
    the type its publisher :meth:`advertise` d: the high-rate streams, packed by field as on
    DDS), and is converted at most once each way for the subscribers that take the other form
    (:meth:`subscribe`'s ``form``). Every published message is also passed to the
    ``recorders`` as an object (``f(topic, msg)``) and to the ``raw_recorders`` as it was
    published (``f(topic, msg, msg_class)``), unless published with ``recorded`` false.
    Topics are absolute names: a relative name is taken in the root namespace.
    """

    #: Subscriber forms: the message object, its CDR payload, or whichever was published.
    OBJECT, PAYLOAD, AS_PUBLISHED = "object", "payload", "as published"

    def __init__(self):
        self._subscribers: dict[str, list[tuple[Callable[[Any], None], str]]] = \
            defaultdict(list)
        self._services: dict[str, tuple[Any, Callable[[Any, Any], Any]]] = {}
        # topic -> the message class published or taken on it (one per topic)
        self._types: dict[str, Any] = {}
        self.published: set[str] = set()  # topics a node has a publisher on
        self._queue: deque[tuple[str, Any, bool]] = deque()
        self.recorders: list[Callable[[str, Any], None]] = []
        self.raw_recorders: list[Callable[[str, Any, Any], None]] = []
        self.now_ns = 0  # replay time, set by whoever drives the bus

    @staticmethod
    def resolve(topic: str) -> str:
        return topic if topic.startswith("/") else "/" + topic

    def advertise(self, topic: str, msg_type) -> None:
        """Messages published on ``topic`` are of ``msg_type`` (a payload is decoded as one).

        Raises
        ------
        TypeError
            Another type is published or taken on the topic.
        """
        topic = self.resolve(topic)
        known = self._types.setdefault(topic, msg_type)
        if known is not msg_type:
            raise TypeError(f"{topic}: {msgtype_of_class(msg_type)} published where "
                            f"{msgtype_of_class(known)} is")

    def subscribe(self, topic: str, callback: Callable[[Any], None],
                  form: str = OBJECT, msg_type=None) -> Callable[[], None]:
        """``callback`` takes the topic's messages in ``form``; ``msg_type``, if given, is the
        class it takes (:meth:`advertise` refuses another). Returns what ends the
        subscription."""
        if msg_type is not None:
            self.advertise(topic, msg_type)
        topic, entry = self.resolve(topic), (callback, form)
        self._subscribers[topic].append(entry)
        return partial(self._unsubscribe, topic, entry)

    def _unsubscribe(self, topic: str, entry: tuple) -> None:
        # a new list: a delivery under way goes on over the one it has
        self._subscribers[topic] = [e for e in self._subscribers[topic] if e is not entry]

    def publish(self, topic: str, msg: Any, recorded: bool = True) -> None:
        """Queue ``msg`` (an object, or the payload of the type advertised on ``topic``);
        ``recorded`` false: not passed to the recorders (a replay's input)."""
        self._queue.append((self.resolve(topic), msg, recorded))

    def add_service(self, name: str, srv_type, callback: Callable[[Any, Any], Any]) -> None:
        self._services[self.resolve(name)] = (srv_type, callback)

    def call(self, name: str, request):
        """Call service ``name`` in-process: its callback runs now, and what it publishes is
        delivered (:meth:`drain`) before the response is returned."""
        srv_type, callback = self._services[self.resolve(name)]
        response = callback(request, srv_type.Response())
        self.drain()
        return response

    def drain(self) -> None:
        payload_form, object_form = self.PAYLOAD, self.OBJECT
        while self._queue:
            topic, msg, recorded = self._queue.popleft()
            if type(msg) is bytes:
                cls, payload, obj = self._types.get(topic), msg, None
            else:
                cls, payload, obj = type(msg), None, msg
            if recorded:
                for record in self.raw_recorders:
                    record(topic, msg, cls)
                for record in self.recorders:
                    if obj is None:
                        obj = codec(cls).decode(payload)
                    record(topic, obj)
            for callback, form in self._subscribers.get(topic, ()):
                if form == payload_form:
                    if payload is None:
                        payload = codec(cls).encode(obj)
                    callback(payload)
                elif form == object_form:
                    if obj is None:
                        obj = codec(cls).decode(payload)
                    callback(obj)
                else:
                    callback(msg)


class _BusPublisher:
    def __init__(self, bus: InProcessBus, msg_type, topic: str):
        self._bus, self.topic = bus, bus.resolve(topic)
        bus.advertise(topic, msg_type)
        bus.published.add(self.topic)

    def publish(self, msg: Any) -> None:
        self._bus.publish(self.topic, msg)

    @staticmethod
    def wanted() -> bool:
        """Always: a replay records every message published on the bus."""
        return True

    def get_subscription_count(self) -> int:
        return len(self._bus._subscribers.get(self.topic, ()))


class Latest:
    """The newest message of a topic, decoded when it is read.

    For a node that needs a state now and then from a stream published at the navigation rate
    (``ins/state`` at 100-1000 Hz, read by ``mag_compass`` per field sample and by
    ``phase_heading`` per GNSS epoch). On DDS ``subscribe()`` makes a subscription no executor
    dispatches (:meth:`NavNode.subscribe_latest`) and returns ``take_newest``, which takes the
    newest message serialized (or None): nothing runs in Python per message published, and
    :meth:`take` decodes only the one it reads; on an :class:`InProcessBus` the bus
    :meth:`put` s each message object and the newest is kept.
    """

    def __init__(self, msg_type, handler,
                 subscribe: Callable[[], tuple[Callable[[], Any], Callable[[], None]]]
                 | None = None):
        self._codec, self._handler = codec(msg_type), handler
        # makes the DDS subscription, returns its take_newest and what ends it
        self._subscribe = subscribe
        self._take_newest = None
        self._pending = None
        self.unsubscribe: Callable[[], None] | None = None  # ends the subscription (stop)

    def start(self) -> None:
        """Subscribe on DDS, if not yet (:meth:`NavNode.subscribe_latest` with ``start``
        false): what was published before is not received."""
        if self._subscribe is not None:
            (self._take_newest, self.unsubscribe), self._subscribe = self._subscribe(), None

    def stop(self) -> None:
        """Receive no more: for a node that needs the stream only for a while (an
        undispatched subscription still wakes its process for every message)."""
        if self.unsubscribe is not None:
            self.unsubscribe()
        self.unsubscribe = self._subscribe = self._take_newest = self._pending = None

    def put(self, data) -> None:
        self._pending = data

    def _fetch(self) -> None:
        if self._take_newest is not None:
            data = self._take_newest()
            if data is not None:
                self._pending = data

    @property
    def waiting(self) -> bool:
        """A message came that has not been taken."""
        self._fetch()
        return self._pending is not None

    def take(self):
        """The newest message not taken before, or None."""
        self._fetch()
        data, self._pending = self._pending, None
        return self._codec.decode(data) if isinstance(data, bytes) else data

    def handle(self) -> None:
        """Hand the newest message not taken before, if any, to the handler (the messages
        before it would have been overwritten by it)."""
        msg = self.take()
        if msg is not None:
            self._handler(msg)


class Queued:
    """Every message of a topic, handed to the handler when the node is ready for them rather
    than as each comes.

    For a node that needs every message of a stream but not at once (the ``ekf`` keeps each
    ``ins/state`` for the comparison with its filter at a common epoch, and reads them at its
    next increment). On DDS :meth:`handle` takes the messages that came, serialized and in
    order, from a subscription no executor dispatches (:meth:`NavNode.subscribe_queued`); on an
    :class:`InProcessBus` the bus delivers each to the handler as it comes, in the replay's
    order, and :meth:`handle` has nothing to do.
    """

    def __init__(self, handler: Callable[[bytes], None],
                 take: Callable[[], Any] | None = None):
        # On DDS: ``handler`` takes one serialized message, ``take()`` gives the next or None.
        self._handler, self._take = handler, take

    def handle(self) -> None:
        """Hand every message that came since the last call to the handler, oldest first."""
        if self._take is None:
            return
        while (data := self._take()) is not None:
            self._handler(data)


class Paced:
    """A high-rate input whose handler needs only some of its messages as soon as they come.

    For the imu_preprocessor's raw samples at 1 kHz: only the one that completes an
    increment is on the way to ``ins/state``; the nine before it just feed the integration.
    After each message the handler names (:meth:`due`) the stamp of the next message it needs
    at once. On DDS the callback then sleeps until :data:`WAKE_MARGIN_NS` before that message
    is expected (the stamp plus the least stamp-to-arrival delay seen lately:
    :class:`ArrivalForecast`) and handles what came meanwhile in one go, taken from the same
    subscription; the executor later finds those messages taken (an empty take each). The
    process then wakes once for them instead of once each (its main thread 1183 -> 296
    wake-ups a second at 1 kHz), and leaves the two cores to the strapdown and the state's
    readers while the increment is on its way (docs/results/live_cost.md). Other callbacks
    of the node wait while it sleeps (at most :data:`MAX_REST_NS`). On the bus, and with sim
    time (whose clock need not run at the wall clock's rate), :meth:`due` does nothing:
    every message is handled as it comes.
    """

    #: How long before the needed message is expected the sleep ends: long enough to wake and
    #: handle what waited before it comes (at 1 kHz ending 1 ms before it, the batch was still
    #: being handled: the increment's latency doubled, p50 0.63 -> 1.21 ms in a scratch run).
    WAKE_MARGIN_NS = 2_000_000
    #: The longest sleep: a forecast thrown off by a step of the sensor's clock (forgotten
    #: after two forecast windows) delays a needed message by no more than this.
    MAX_REST_NS = 20_000_000

    def __init__(self, handle: Callable[[Any], None] | None = None):
        # On DDS: count and hand over one serialized message; take() gives the next one
        # waiting, serialized, or None.
        self._handle = handle
        self.take: Callable[[], Any] | None = None
        self._forecast = ArrivalForecast()
        self._rest_until: int | None = None

    def due(self, stamp_ns: int) -> None:
        """The next message the handler needs as soon as it comes is the one stamped
        ``stamp_ns`` (on the clock of the stamps it gets): those before it may wait."""
        if self.take is not None:
            arrival = self._forecast.arrival(stamp_ns)
            self._rest_until = None if arrival is None else arrival - self.WAKE_MARGIN_NS

    def on_message(self, data) -> None:
        """The subscription's callback (DDS): handle the message, then rest if the handler
        allows, and handle what came meanwhile."""
        arrival = time.monotonic_ns()
        self._handle(data)
        self._forecast.add(payload_stamp_ns(data), arrival)
        now = time.monotonic_ns()
        until, self._rest_until = self._rest_until, None
        if until is None or until <= now:
            return
        time.sleep(min(until - now, self.MAX_REST_NS) / NS)
        while (taken := self.take()) is not None:
            self._handle(taken)
        # A rest asked for by a message taken here starts at the next message dispatched:
        # the node's other callbacks get their turn first.
        self._rest_until = None


class _CountedPublisher:
    """A DDS publisher that counts what it publishes in ``traffic["published <topic>"]`` and
    hands rclpy the message serialized by the project's codec (Imu 7 us; rclpy's conversion
    and serialization 27 us here). A volatile topic nobody subscribes to is not serialized
    (``imu/data`` at the IMU rate, read only where a compass levels from it): no late joiner
    could get it anyway. Its subscribers are counted from the publisher's matched events, not
    asked of rclpy per message."""

    def __init__(self, node: Node, msg_type, topic: str, qos, traffic: Counter):
        self._subscribers = 0
        self._publisher = node.create_publisher(
            msg_type, topic, qos, event_callbacks=PublisherEventCallbacks(matched=self._matched))
        self._traffic = traffic
        self._encode = codec(msg_type).encode
        self._key = f"published {self._publisher.topic_name}"
        self._volatile = not (isinstance(qos, QoSProfile)
                              and qos.durability == DurabilityPolicy.TRANSIENT_LOCAL)

    def _matched(self, status) -> None:
        self._subscribers = status.current_count

    def wanted(self) -> bool:
        """Whether a message published now reaches anyone: a node may skip building one
        nobody would get."""
        return not self._volatile or self._subscribers > 0

    def publish(self, msg) -> None:
        """Publish a message object, or its CDR payload as it is."""
        if not self.wanted():
            return
        self._traffic[self._key] += 1
        self._publisher.publish(msg if type(msg) is bytes else self._encode(msg))

    def __getattr__(self, name):
        return getattr(self._publisher, name)


class NavNode(Node):
    """Base class of the project's nodes.

    Subclasses set ``PARAMS`` (a sequence of :class:`Param`) and read validated values from
    ``self.p`` (a dict) in their constructor after ``super().__init__``. ``bus`` (keyword only)
    runs the node on an :class:`InProcessBus` instead of DDS.
    """

    PARAMS: Sequence[Param] = ()

    def __init_subclass__(cls, **kwargs):
        """A node whose constructor raises (a bad parameter, found after rclpy created the
        node) destroys itself before the error leaves it. Left to the garbage collector, such
        half-built nodes are destroyed at whatever allocation triggers a collection, possibly
        inside rclpy's creation of the next node: a test run creating several hung there once
        (rclpy's destroy_node itself frees entities eagerly for a like hang, ros2/build_cop
        issue 248)."""
        super().__init_subclass__(**kwargs)
        init = cls.__dict__.get("__init__")
        if init is None:
            return

        @wraps(init)
        def init_or_destroy(self, *args, **kw):
            try:
                init(self, *args, **kw)
            except BaseException:
                outermost = type(self).__init__ is init_or_destroy
                if outermost and hasattr(self, "_type_description_service"):  # rclpy's, built
                    NavNode.destroy_node(self)  # a subclass's own may need what was not built
                raise

        cls.__init__ = init_or_destroy

    def __init__(self, name: str, *, bus: InProcessBus | None = None, **kwargs):
        super().__init__(name, **kwargs)
        self.bus = bus
        self._undispatched: Node | None = None  # see _undispatched_node
        self.p: dict[str, Any] = {}
        for spec in self.PARAMS:
            self.declare_parameter(spec.name, spec.default, descriptor(spec))
            self.p[spec.name] = spec.validate(self.get_parameter(spec.name).value)
        self.diag = Diagnostics(self)

    def publisher(self, msg_type, topic: str, qos):
        """A DDS publisher, or the bus' stand-in with the same ``publish``; either takes a
        message object or its CDR payload (``bytes``, e.g. packed by
        :func:`..io.cdr.field_writer`)."""
        if self.bus is not None:
            return _BusPublisher(self.bus, msg_type, topic)
        if topic == "/diagnostics":
            return self.create_publisher(msg_type, topic, qos)
        return _CountedPublisher(self, msg_type, topic, qos, self.diag.traffic)

    def subscribe(self, msg_type, topic: str, callback, qos, serialized: bool = False) -> None:
        """``callback`` takes each message decoded, or with ``serialized`` its CDR payload:
        for a handler that reads a few fields (:func:`..io.cdr.field_reader`) rather than
        build a message object per message, on DDS and on the bus alike."""
        if self.bus is not None:
            self.bus.subscribe(topic, callback, InProcessBus.PAYLOAD if serialized
                               else InProcessBus.OBJECT, msg_type)
            return
        self.create_subscription(msg_type, topic,
                                 self._counted(topic, self._taking(msg_type, callback,
                                                                   serialized)),
                                 qos, raw=True)

    @staticmethod
    def _taking(msg_type, callback, serialized: bool):
        """``callback`` as a DDS subscription's raw callback: messages are taken serialized and
        decoded by the project's codec (rclpy builds each through the generated class's
        constructor and properties: Imu ~33 us, InsState ~48 us here, the codec 12 us;
        docs/results/live_cost.md), or not decoded at all for a ``serialized`` handler."""
        if serialized:
            return callback
        decode = codec(msg_type).decode
        return lambda data: callback(decode(data))

    def subscribe_paced(self, msg_type, topic: str, callback, qos,
                        serialized: bool = False) -> Paced:
        """As :meth:`subscribe`, for a high-rate input of messages with a header of which
        ``callback`` needs only some at once: it calls :meth:`Paced.due` on the returned
        object to let the messages before the next needed one wait and be handled together
        (on DDS without sim time; see :class:`Paced`)."""
        if self.bus is not None:
            self.subscribe(msg_type, topic, callback, qos, serialized)
            return Paced()
        counted = self._counted(topic, self._taking(msg_type, callback, serialized))
        if self.get_clock().ros_time_is_active:
            self.create_subscription(msg_type, topic, counted, qos, raw=True)
            return Paced()
        paced = Paced(counted)
        sub = self.create_subscription(msg_type, topic, paced.on_message, qos, raw=True)
        paced.take = partial(_take_serialized, sub)
        return paced

    def _counted(self, topic: str, callback):
        """``callback`` counting each message in ``diag.traffic["received <topic>"]`` (the
        resolved topic name)."""
        key, traffic = f"received {self.resolve_topic_name(topic)}", self.diag.traffic

        def counted(data):
            traffic[key] += 1
            callback(data)
        return counted

    def subscribe_latest(self, msg_type, topic: str, qos, handler,
                         start: bool = True) -> Latest:
        """A subscription that keeps only the newest message, decoded when it is taken
        and handed to ``handler`` by :meth:`Latest.handle`.

        On DDS the subscription (depth 1, ``qos`` otherwise) belongs to a hidden node of this
        process that no executor spins, so that no callback runs per message (~190 us of CPU
        each here, docs/results/live_cost.md); the message is taken when the node reads it,
        and counted then in ``diag.traffic["taken <topic>"]``: what was used, not what was
        published. With ``start`` false it is made at :meth:`Latest.start`: a node with
        nothing to do until some other input comes does not receive the stream meanwhile (an
        undispatched subscription still wakes its process for every message, and costs the
        publisher a delivery). On the bus the topic is subscribed at once either way (a
        replay then reads as it always did), each message kept as it was published."""
        if self.bus is not None:
            latest = Latest(msg_type, handler)
            latest.unsubscribe = self.bus.subscribe(topic, latest.put,
                                                    InProcessBus.AS_PUBLISHED, msg_type)
            return latest
        latest = Latest(msg_type, handler,
                        partial(self._undispatched_take, msg_type, topic, qos, 1, "taken"))
        if start:
            latest.start()
        return latest

    def subscribe_queued(self, msg_type, topic: str, qos, handler,
                         serialized: bool = False) -> Queued:
        """A subscription whose messages reach ``handler`` (decoded, or with ``serialized``
        as their CDR payloads) when the node calls :meth:`Queued.handle`, all of them and in
        order, and at the latest at the node's next /diagnostics publication (1 s: when the
        node's other inputs stop, what came is still handled, and counted before the counts
        are reported).

        On DDS, as :meth:`subscribe_latest`, from a hidden node no executor spins, keeping
        ``qos.depth`` messages; each is counted in ``diag.traffic["received <topic>"]`` when
        taken. On the bus each message is handled as it comes."""
        if self.bus is not None:
            self.subscribe(msg_type, topic, handler, qos, serialized)
            return Queued(handler)
        queued = Queued(self._taking(msg_type, handler, serialized),
                        self._undispatched_take(msg_type, topic, qos, qos.depth, "received")[0])
        self.diag.before_publish.append(queued.handle)
        return queued

    def _undispatched_take(self, msg_type, topic: str, qos, depth: int, counted_as: str):
        """``take()``: the oldest message not taken yet of a subscription (``depth``, ``qos``
        otherwise) of :meth:`_undispatched_node`, serialized, or None; counted in
        ``diag.traffic["<counted_as> <topic>"]``; and what ends the subscription."""
        name = self.resolve_topic_name(topic)  # this node's namespace and remappings
        node = self._undispatched_node()
        sub = node.create_subscription(
            msg_type, name, lambda _: None,
            QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=depth, reliability=qos.reliability,
                       durability=qos.durability), raw=True)
        key, traffic = f"{counted_as} {name}", self.diag.traffic

        def take():
            taken = _take_serialized(sub)
            if taken is not None:
                traffic[key] += 1
            return taken
        return take, partial(node.destroy_subscription, sub)

    def _undispatched_node(self) -> Node:
        """The hidden node (``_<name>_latest``: ``ros2 node list`` omits it) that holds the
        subscriptions of :meth:`subscribe_latest` and :meth:`subscribe_queued`. It ignores the
        process' arguments (a node name remapping would give it this node's name); topics are
        resolved by this node."""
        if self._undispatched is None:
            self._undispatched = Node(
                f"_{self.get_name()}_latest", context=self.context,
                namespace=self.get_namespace(), use_global_arguments=False,
                start_parameter_services=False, enable_rosout=False,
                parameter_overrides=[Parameter("start_type_description_service", value=False)])
        return self._undispatched

    def destroy_node(self):
        if self._undispatched is not None:
            self._undispatched.destroy_node()
            self._undispatched = None
        return super().destroy_node()

    def service(self, srv_type, name: str, callback) -> None:
        """A DDS service, or the same callback registered with the bus (``bus.call``); a
        ``~/`` name is private to the node on both."""
        if self.bus is None:
            self.create_service(srv_type, name, callback)
            return
        if name.startswith("~/"):
            name = f"{self.get_fully_qualified_name()}/{name[2:]}"
        self.bus.add_service(name, srv_type, callback)

    def now_ns(self) -> int:
        """Current time, ns: the bus' replay time or the node clock."""
        if self.bus is not None:
            return self.bus.now_ns
        clock = self.get_clock()
        if clock.ros_time_is_active:  # use_sim_time: the /clock time
            return clock.now().nanoseconds
        # The system time the ROS clock reads without /clock, without building an rclpy Time
        # (9 us here; the imu_preprocessor reads it per sample).
        return time.time_ns()

    def transport_arrival_ns(self) -> int | None:
        """The time a message arrives as its transport gives it, ns: the bus' replay time (the
        log time) or the system time; None under /clock (use_sim_time), which is the player's
        time of a message, not the transport's (it may run ahead of the messages delivered)."""
        if self.bus is None and self.get_clock().ros_time_is_active:
            return None
        return self.now_ns()

    def stamp_unset_to_arrival(self, header, topic: str) -> None:
        """A header whose stamp the driver left unset (0) takes the arrival time, counted on
        /diagnostics (:func:`~ins_gnss_ros.io.stamp_or_arrival`); a stamped one is
        left as it is, without reading the clock."""
        if header.stamp.sec or header.stamp.nanosec:
            return
        stamp_ns, unset = stamp_or_arrival(0, self.now_ns(), topic)
        header.stamp = ns_to_stamp(stamp_ns)
        self.diag.count(unset)

    def now_msg(self) -> Time:
        """Current time as a message stamp (as rclpy's ``Time.to_msg``, without building an
        rclpy Time: replays call this for every sample)."""
        return ns_to_stamp(self.now_ns())


def _take_serialized(sub):
    """The oldest message not taken yet of a raw subscription, serialized, or None."""
    taken = sub.handle.take_message(sub.msg_type, True)  # as rclpy.wait_for_message
    return None if taken is None else taken[0]


#: Executors a node process can spin in. ``events`` (rclpy's C++ EventsExecutor) takes each
#: message from DDS straight to its callback; the ``single``-threaded one rebuilds its wait set in
#: Python for every callback: ~0.7 ms more CPU per 200 Hz increment (one message in, one out),
#: 14 % of a core (docs/results/latency.md).
EXECUTORS = {"events": EventsExecutor, "single": SingleThreadedExecutor}
#: Environment variable that picks the executor of :func:`run` (default ``events``).
EXECUTOR_ENV = "INS_GNSS_ROS_EXECUTOR"


def executor_kind(kind: str | None = None) -> str:
    """``kind`` if given, else :data:`EXECUTOR_ENV`, else ``events``; ValueError if unknown."""
    kind = kind or os.environ.get(EXECUTOR_ENV) or "events"
    if kind not in EXECUTORS:
        raise ValueError(f"executor {kind!r} ({EXECUTOR_ENV}) is not one of {', '.join(EXECUTORS)}")
    return kind


def run(node_factory: Callable[[], Node], args: list[str] | None = None,
        executor: str | None = None) -> int:
    """Start a node, spin it until SIGINT/SIGTERM, shut down cleanly. Returns the exit status.

    ``executor`` names one of :data:`EXECUTORS` (default: :func:`executor_kind`). An unknown
    executor, a :class:`ParameterError` or ROS' own parameter-range error at start-up is printed
    as one line and gives status 2.
    """
    try:
        kind = executor_kind(executor)
    except ValueError as err:
        print(f"error: {err}", file=sys.stderr)
        return 2
    rclpy.init(args=args)
    node = spinner = None
    try:
        node = node_factory()
        spinner = EXECUTORS[kind]()
        spinner.add_node(node)
        # Spun a second at a time on a future that never completes, rather than spin():
        # rclpy 7.1's EventsExecutor.spin() polls without sleeping and never sees
        # SIGINT/SIGTERM; this returns on a signal (as KeyboardInterrupt or
        # ExternalShutdownException) and idles at no CPU. Not spin_once: the events executor
        # then stops and returns to Python after every callback, ~70 us more CPU per message
        # (docs/results/live_cost.md).
        forever = Future()
        while rclpy.ok():
            spinner.spin_until_future_complete(forever, timeout_sec=1.0)
    except (ParameterError, ParameterException) as err:
        print(f"error: {err}", file=sys.stderr)
        return 2
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    except RCLError:
        if rclpy.ok():
            raise
        # A signal shut the context down while the node was still creating its endpoints.
    finally:
        # The executor lets go of the node before either is destroyed: the events executor
        # aborts the process ("Destroying callback manager with callbacks remaining") when it
        # is garbage-collected while a node's entities are still registered with it. That
        # has not always been enough (a phase_heading process aborted so at exit in CI on
        # 2026-12-05, after both): the executor is never destroyed, the process ends with it.
        if spinner is not None:
            if node is not None:
                spinner.remove_node(node)
            spinner.shutdown()
            ctypes.pythonapi.Py_IncRef(ctypes.py_object(spinner))
        if node is not None:
            node.destroy_node()
        if rclpy.ok():
            rclpy.shutdown()
    return 0
