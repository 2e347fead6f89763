"""Deterministic fault injection into a time-ordered message stream.

:class:`FaultInjector` is a filter: an iterable of ``(t_ns, topic, msg)`` in (ordered by ``t_ns``,
the log/arrival time; ``msg`` an rclpy message object), an iterable of the same out, again ordered
by ``t_ns``. It plugs into a replay between reading the bag and publishing::

    injector = FaultInjector(load_fault_spec("faults.yaml"))
    for t_ns, topic, msg in injector(stream): ...
    injector.summary()    # the windows and what was done in them, for the evaluation

Two times are kept apart: ``t_ns`` is when a message reaches the nodes, ``header.stamp`` is the
sensor time it carries. Delays and reordering move the former and leave the stamps (so stamps
arrive late or out of order); clock jumps and loops change the stamps and leave the arrival
order. Messages are copied before anything in them changes: the input objects are never
modified, so the same decoded bag can be replayed with and without faults.

Everything random (which message a ``probability`` hits, the reorder permutation, which
satellites disappear or slip) comes from ``numpy`` generators seeded with the specification's
``seed`` and the fault's index: the same stream and specification give the same output.
Windows are relative to the first message of the stream (``t0``).
"""

from __future__ import annotations

import copy
import heapq
import math
from dataclasses import dataclass
from typing import Any, Iterable, Iterator

import numpy as np

from ..io import msg_stamp_ns, ns_to_stamp
from ..nav.earth import radii
from .spec import Fault, FaultSpec

#: (arrival time ns, message) pairs that one input message has become so far.
Items = list[tuple[int, Any]]


class FaultError(ValueError):
    """A fault that cannot act on the message it matched (e.g. a missing or non-numeric field)."""


@dataclass
class FaultRecord:
    """What one fault did: its window on the stream's time axis and the messages it changed.

    Attributes
    ----------
    name, kind, topic : str
        From the specification (``topic`` is the pattern).
    start_ns, end_ns : int
        Window ``[start_ns, end_ns)``, ns on the stream's time axis; an open window ends at the
        last message of the stream.
    affected : int
        Messages dropped, delayed, copied, altered or replayed by this fault.
    first_ns, last_ns : int or None
        Arrival times of the first and last affected input message.
    """

    name: str
    kind: str
    topic: str
    start_ns: int
    end_ns: int
    affected: int = 0
    first_ns: int | None = None
    last_ns: int | None = None

    def hit(self, t_ns: int, n: int = 1) -> None:
        self.affected += n
        if self.first_ns is None:
            self.first_ns = t_ns
        self.last_ns = t_ns


# ---------------------------------------------------------------------------------------------
# Field access (dotted paths such as "angular_velocity.z" or "pseudorange")
# ---------------------------------------------------------------------------------------------
def _modify_field(fault: Fault, msg, path: str, fn) -> None:
    """Replace the numeric field (or every element of a numeric array) ``v`` by ``fn(v)``."""
    *parents, last = path.split(".")
    obj = msg
    try:
        for part in parents:
            obj = getattr(obj, part)
        value = getattr(obj, last)
    except AttributeError:
        raise FaultError(f"fault {fault.name}: {type(msg).__name__} has no field {path!r}") \
            from None
    if isinstance(value, float):
        new = float(fn(value))
    elif isinstance(value, (int, bool, str, bytes)) or not hasattr(value, "__len__") \
            or any(not isinstance(v, float) for v in value):
        # Integer fields (counts, flags, enums) cannot hold NaN or a fraction of a step.
        raise FaultError(f"fault {fault.name}: field {path!r} of {type(msg).__name__} is not a"
                         " float or an array of floats")
    else:
        new = np.array([fn(v) for v in value], dtype=float)
    try:
        setattr(obj, last, new)
    except (AssertionError, TypeError, ValueError) as err:  # rclpy's setters check the range
        raise FaultError(f"fault {fault.name}: cannot set {path!r}: {err}") from None


def _set_stamp(msg, t_ns: int) -> None:
    msg.header.stamp = ns_to_stamp(t_ns)


def _stable_keys(rng_seed: list[int], system, prn) -> np.ndarray:
    """A random key in [0, 1) per satellite, the same for that satellite at every epoch."""
    return np.array([np.random.default_rng(rng_seed + [int(s), int(p)]).random()
                     for s, p in zip(system, prn)])


def _sequence_fields(msg) -> list[str]:
    return [name for name, kind in msg.get_fields_and_field_types().items()
            if kind.startswith("sequence<")]


# ---------------------------------------------------------------------------------------------
# One class per kind of fault: apply(t_in, topic, items) -> items, called for messages of a
# matching topic inside the window (and, for the stateful ones, observe() outside it).
# ---------------------------------------------------------------------------------------------
class _Action:
    def __init__(self, fault: Fault, seed: int, t0: int, record: FaultRecord):
        self.fault, self.p, self.t0, self.record = fault, fault.params, t0, record
        self.rng = np.random.default_rng([seed, fault.index])
        self.seed = [seed, fault.index]
        # Messages released other than as the result of apply() (held back, or of other
        # topics): (t_out, topic, msg), collected by the injector after every call.
        self.emit: list[tuple[int, str, Any]] = []

    def observe(self, t_in: int, topic: str, items: Items) -> None:
        """See a matching message outside the window (for faults that need history)."""

    def apply(self, t_in: int, topic: str, items: Items) -> Items:
        """What the matching message ``items`` (of ``topic``, inside the window) become."""
        raise NotImplementedError

    def flush(self, t_in: int) -> None:
        """Release what is held back into ``emit`` (window ended or stream ended)."""

    def elapsed_s(self, t_in: int) -> float:
        return (t_in - self.record.start_ns) * 1e-9

    def hits(self) -> bool:
        """One draw against ``probability`` (always True without that parameter)."""
        p = self.p.get("probability", 1.0)
        return p >= 1.0 or self.rng.random() < p

    def edit(self, items: Items, fn) -> Items:
        """Copy each message, let ``fn`` change the copy in place."""
        out = []
        for t, msg in items:
            msg = copy.deepcopy(msg)
            fn(msg)
            out.append((t, msg))
        return out


class _Drop(_Action):
    def apply(self, t_in, topic, items):
        return [] if self.hits() else items


class _Delay(_Action):
    def apply(self, t_in, topic, items):
        d = int(round(self.p["delay_s"] * 1e9))
        return [(t + d, msg) for t, msg in items]


class _Duplicate(_Action):
    def apply(self, t_in, topic, items):
        if not self.hits():
            return items
        return [(t, copy.deepcopy(msg) if k else msg) for t, msg in items
                for k in range(1 + self.p["copies"])]


class _Reorder(_Action):
    """Hold ``window`` messages, release them together in a random order at the last arrival.

    Released messages skip the faults listed after this one (they leave the pipeline here).
    """

    def __init__(self, *args):
        super().__init__(*args)
        self.held: list[tuple[int, str, Any]] = []

    def apply(self, t_in, topic, items):
        self.held.extend((t, topic, msg) for t, msg in items)
        if len(self.held) >= self.p["window"]:
            self.flush(t_in)
        return []

    def flush(self, t_in):
        held, self.held = self.held, []
        t_out = max([t_in] + [t for t, _, _ in held])
        self.emit.extend((t_out, held[i][1], held[i][2]) for i in self.rng.permutation(len(held)))


class _Freeze(_Action):
    """Repeat the last content seen before the window, with the stamps of the new messages.

    Messages without a header, or with nothing seen before the window, pass unchanged.
    """

    def __init__(self, *args):
        super().__init__(*args)
        self.last: dict[str, Any] = {}

    def observe(self, t_in, topic, items):
        if items:
            self.last[topic] = items[-1][1]

    def apply(self, t_in, topic, items):
        frozen = self.last.get(topic)
        if frozen is None or not hasattr(frozen, "header"):
            return items
        out = []
        for t, msg in items:
            repeat = copy.deepcopy(frozen)
            repeat.header.stamp = copy.deepcopy(msg.header.stamp)
            out.append((t, repeat))
        return out


class _Step(_Action):
    def apply(self, t_in, topic, items):
        return self.edit(items, lambda m: _modify_field(self.fault, m, self.p["field"],
                                                        lambda v: v + self.p["value"]))


class _Ramp(_Action):
    def apply(self, t_in, topic, items):
        offset = self.p["rate"] * self.elapsed_s(t_in)
        return self.edit(items, lambda m: _modify_field(self.fault, m, self.p["field"],
                                                        lambda v: v + offset))


class _SetValue(_Action):
    """nan, inf and absurd: the field takes one bad value."""

    def apply(self, t_in, topic, items):
        if not self.hits():
            return items
        kind = self.fault.kind
        bad = (math.nan if kind == "nan" else
               (-math.inf if self.p["negative"] else math.inf) if kind == "inf" else
               float(self.p["value"]))
        return self.edit(items, lambda m: _modify_field(self.fault, m, self.p["field"],
                                                        lambda v: bad))


class _ClockJump(_Action):
    def apply(self, t_in, topic, items):
        d = int(round(self.p["offset_s"] * 1e9))
        return self.edit(items, lambda m: _set_stamp(m, msg_stamp_ns(m) + d)
                         if hasattr(m, "header") else None)


class _ClockDrift(_Action):
    """The sensor's clock runs ``ppm`` fast from the window's first message on (an IMU stamped by
    counting its samples at the nominal rate, its crystal off): each stamp moves by ppm 1e-6
    times its distance from that message's stamp; arrival times stay."""

    def __init__(self, *args):
        super().__init__(*args)
        self.reference_ns = None

    def apply(self, t_in, topic, items):
        return self.edit(items, self._drift)

    def _drift(self, msg) -> None:
        if not hasattr(msg, "header"):
            return
        stamp = msg_stamp_ns(msg)
        if self.reference_ns is None:
            self.reference_ns = stamp
        _set_stamp(msg, stamp + round((stamp - self.reference_ns) * self.p["ppm"] * 1e-6))


class _Loop(_Action):
    """The stream starts again: in the window, the first ``duration`` s are played once more.

    Originals in the window are withheld; the copies of the stream's beginning (every matching
    topic) arrive at the same offsets from the window start as they had from ``t0``, carrying
    their old stamps, so stamps go backwards at the window start and forward again at its end.
    """

    def __init__(self, *args):
        super().__init__(*args)
        self.prefix: list[tuple[int, str, Any]] | None = []
        self.length_ns = self.record.end_ns - self.record.start_ns

    def observe(self, t_in, topic, items):
        if self.prefix is not None and t_in - self.t0 < self.length_ns:
            self.prefix.extend((t_in, topic, msg) for _, msg in items)

    def apply(self, t_in, topic, items):
        if self.prefix is not None:  # first message in the window: schedule the replay
            self.record.hit(t_in, len(self.prefix))
            self.emit.extend((max(t_in, self.record.start_ns + t - self.t0), top,
                              copy.deepcopy(msg)) for t, top, msg in self.prefix)
            self.prefix = None
        return []


class _SatelliteLoss(_Action):
    """Satellites disappear from the observation arrays, down to ``remaining`` over ``ramp_s``."""

    def apply(self, t_in, topic, items):
        ramp = self.p["ramp_s"]
        gone = 1.0 if ramp <= 0.0 else min(1.0, self.elapsed_s(t_in) / ramp)

        def remove(msg):
            sats = list(zip(msg.system, msg.prn))
            unique = sorted(set(sats))
            n_keep = max(self.p["remaining"],
                         int(round(len(unique) * (1.0 - gone)))) if unique else 0
            keys = _stable_keys(self.seed, [s for s, _ in unique], [p for _, p in unique])
            kept = {unique[i] for i in np.argsort(keys, kind="stable")[:n_keep]}
            index = [i for i, sat in enumerate(sats) if sat in kept]
            for name in _sequence_fields(msg):
                values = getattr(msg, name)
                if len(values) == len(sats):
                    setattr(msg, name, [values[i] for i in index])

        return self.edit(items, remove)


class _PositionJump(_Action):
    """A spoofer's position offset (north, east, up in m) on NavSatFix, ramped in over ramp_s."""

    def apply(self, t_in, topic, items):
        ramp = self.p["ramp_s"]
        k = 1.0 if ramp <= 0.0 else min(1.0, self.elapsed_s(t_in) / ramp)

        def move(msg):
            lat, h = math.radians(msg.latitude), msg.altitude
            rm, rn = radii(lat)  # metres to angle on the WGS-84 ellipsoid (Groves eq. 2.119)
            msg.latitude += math.degrees(k * self.p["north_m"] / (rm + h))
            msg.longitude += math.degrees(k * self.p["east_m"] / ((rn + h) * math.cos(lat)))
            msg.altitude += k * self.p["up_m"]

        for _, msg in items:
            if not all(hasattr(msg, f) for f in ("latitude", "longitude", "altitude")):
                raise FaultError(f"fault {self.fault.name}: {type(msg).__name__} has no"
                                 " latitude/longitude/altitude")
        return self.edit(items, move)


class _MagneticDisturbance(_Action):
    """A disturbing field (T, sensor frame) added to MagneticField, ramped in over ramp_s."""

    def apply(self, t_in, topic, items):
        ramp = self.p["ramp_s"]
        k = 1.0 if ramp <= 0.0 else min(1.0, self.elapsed_s(t_in) / ramp)
        dx, dy, dz = (k * float(v) for v in self.p["field_t"])
        for axis, d in zip("xyz", (dx, dy, dz)):
            items = self.edit(items, lambda m, a=axis, d=d: _modify_field(
                self.fault, m, f"magnetic_field.{a}", lambda v: v + d))
        return items


class _CycleSlip(_Action):
    """Whole cycles added to the carrier phase of (a fraction of) the satellites, unflagged.

    The receiver does not see it: ``loss_of_lock`` stays false, which is the case a slip
    detector in the phase processing has to catch. Valid for every antenna whose topic matches.
    """

    def apply(self, t_in, topic, items):
        def slip(msg):
            keys = _stable_keys(self.seed, msg.system, msg.prn)
            phase = np.array(msg.carrier_phase, dtype=float)
            hit = (keys < self.p["fraction"]) & np.isfinite(phase)
            phase[hit] += self.p["cycles"]
            msg.carrier_phase = phase
            msg.loss_of_lock = [bool(lol) and not h for lol, h in zip(msg.loss_of_lock, hit)]

        return self.edit(items, slip)


_ACTIONS = {"drop": _Drop, "gnss_outage": _Drop, "delay": _Delay, "duplicate": _Duplicate,
            "reorder": _Reorder, "freeze": _Freeze, "step": _Step, "ramp": _Ramp,
            "nan": _SetValue, "inf": _SetValue, "absurd": _SetValue, "clock_jump": _ClockJump,
            "clock_drift": _ClockDrift, "loop": _Loop, "satellite_loss": _SatelliteLoss,
            "position_jump": _PositionJump, "magnetic_disturbance": _MagneticDisturbance,
            "cycle_slip": _CycleSlip}


class FaultInjector:
    """Apply a :class:`~ins_gnss_ros.faults.spec.FaultSpec` to a message stream (module doc).

    One injector serves one stream: calling it starts a fresh pass (new records). Faults act in
    the order of the specification, each on what the previous ones left.
    """

    def __init__(self, spec: FaultSpec):
        self.spec = spec
        self.records: list[FaultRecord] = []

    def __call__(self, stream: Iterable[tuple[int, str, Any]]) -> Iterator[tuple[int, str, Any]]:
        pending: list[tuple[int, int, str, Any]] = []  # heap: (t_out, sequence, topic, msg)
        seq = 0
        actions: list[_Action] = []
        open_windows = [False] * len(self.spec.faults)
        self.records = []
        t_last = None

        def push(t_out, topic, msg):
            nonlocal seq
            heapq.heappush(pending, (t_out, seq, topic, msg))
            seq += 1

        for t_in, topic, msg in stream:
            t_in = int(t_in)
            topic = topic if topic.startswith("/") else "/" + topic
            if t_last is not None and t_in < t_last:
                raise ValueError(f"input stream not ordered by time at t_ns={t_in} ({topic})")
            t_last = t_in
            if not actions:
                actions = [self._action(f, t_in) for f in self.spec.faults]
            for i, act in enumerate(actions):
                if open_windows[i] and t_in >= act.record.end_ns:  # closed: release the held
                    open_windows[i] = False
                    act.flush(t_in)
            items: Items = [(t_in, msg)]
            for i, act in enumerate(actions):
                if not items:
                    break
                if not act.fault.matches(topic):
                    continue
                if not act.record.start_ns <= t_in < act.record.end_ns:
                    act.observe(t_in, topic, items)
                    continue
                open_windows[i] = True
                before = items
                items = act.apply(t_in, topic, items)
                if items is not before:
                    act.record.hit(t_in)
            for act in actions:
                for t_out, top, m in act.emit:
                    push(t_out, top, m)
                act.emit.clear()
            for t_out, m in items:
                push(t_out, topic, m)
            while pending and pending[0][0] <= t_in:
                t_out, _, top, m = heapq.heappop(pending)
                yield t_out, top, m
        for act in actions:
            act.flush(t_last)
            for t_out, top, m in act.emit:
                push(t_out, top, m)
            act.record.end_ns = min(act.record.end_ns, t_last + 1)
        while pending:
            t_out, _, top, m = heapq.heappop(pending)
            yield t_out, top, m

    def _action(self, fault: Fault, t0: int) -> _Action:
        end = t0 + int(round(fault.end_s * 1e9)) if math.isfinite(fault.end_s) else 2**62
        record = FaultRecord(fault.name, fault.kind, fault.topic,
                             t0 + int(round(fault.start_s * 1e9)), end)
        self.records.append(record)
        return _ACTIONS[fault.kind](fault, self.spec.seed, t0, record)

    def summary(self) -> list[dict]:
        """The records as plain data (for ``replay.json``): one dict per fault."""
        return [dict(vars(r)) for r in self.records]


def inject(stream: Iterable[tuple[int, str, Any]], spec: FaultSpec
           ) -> Iterator[tuple[int, str, Any]]:
    """Shorthand for ``FaultInjector(spec)(stream)`` when the record is not needed."""
    return FaultInjector(spec)(stream)
