"""Fault specification: which fault, on which topics, when, with which parameters.

A specification is a YAML mapping (read with :mod:`ins_gnss_ros.params_io`, so it is bounded in
size and structure like every untrusted file)::

    seed: 7                       # optional, default 0: every random choice derives from it
    faults:
      - kind: gnss_outage         # drop every gnss/* message
        start: 120.0              # s after the first message of the stream
        duration: 30.0            # s; omitted: until the end of the stream
      - kind: step
        topic: imu/data_raw       # fnmatch pattern over topic names; relative = root namespace
        start: 60
        duration: 10
        field: angular_velocity.z # dotted path of a numeric field (or array) of the message
        value: 0.01               # added, in the field's unit (rad/s here)

Every entry has ``kind``, ``start`` (s, >= 0) and optionally ``topic``, ``duration`` (s, > 0),
``name`` (a label for the injection record); the other keys depend on the kind (``KINDS``). A
problem is one :class:`FaultSpecError` naming the entry (``faults[3] (step)``) and the key.
Topics under ``/truth/`` are never faulted: the evaluation needs the truth intact.
"""

from __future__ import annotations

import fnmatch
import math
from dataclasses import dataclass, field
from typing import Any, Mapping

from ..params_io import ParamsFileError, load_yaml, load_yaml_file

#: Marks a kind's parameter that has no default.
REQUIRED = object()
_NUM = (int, float)

#: For each kind: its default topic pattern (None: ``topic`` is required) and its parameters,
#: name -> (accepted types, default or REQUIRED, check, what the check demands).
KINDS: dict[str, tuple[str | None, dict[str, tuple]]] = {
    "drop": (None, {"probability": (_NUM, 1.0, lambda v: 0.0 < v <= 1.0, "in (0, 1]")}),
    "delay": (None, {"delay_s": (_NUM, REQUIRED, lambda v: 0.0 < v <= 3600.0, "in (0, 3600] s")}),
    "duplicate": (None, {
        "copies": (int, 1, lambda v: 1 <= v <= 100, "in 1..100"),
        "probability": (_NUM, 1.0, lambda v: 0.0 < v <= 1.0, "in (0, 1]")}),
    "reorder": (None, {"window": (int, 5, lambda v: 2 <= v <= 10_000, "in 2..10000 messages")}),
    "freeze": (None, {}),
    "step": (None, {"field": (str, REQUIRED, None, ""),
                    "value": (_NUM, REQUIRED, math.isfinite, "finite")}),
    "ramp": (None, {"field": (str, REQUIRED, None, ""),
                    "rate": (_NUM, REQUIRED, math.isfinite, "finite (field unit per s)")}),
    "nan": (None, {"field": (str, REQUIRED, None, ""),
                   "probability": (_NUM, 1.0, lambda v: 0.0 < v <= 1.0, "in (0, 1]")}),
    "inf": (None, {"field": (str, REQUIRED, None, ""),
                   "negative": (bool, False, None, ""),
                   "probability": (_NUM, 1.0, lambda v: 0.0 < v <= 1.0, "in (0, 1]")}),
    "absurd": (None, {"field": (str, REQUIRED, None, ""),
                      "value": (_NUM, 1.0e12, math.isfinite, "finite"),
                      "probability": (_NUM, 1.0, lambda v: 0.0 < v <= 1.0, "in (0, 1]")}),
    "clock_jump": (None, {"offset_s": (_NUM, REQUIRED, lambda v: v != 0 and abs(v) <= 1e6,
                                       "non-zero, |offset| <= 1e6 s")}),
    "clock_drift": (None, {"ppm": (_NUM, REQUIRED, lambda v: v != 0 and abs(v) <= 1e5,
                                   "non-zero, |ppm| <= 1e5")}),
    "loop": (None, {}),
    "gnss_outage": ("/gnss/*", {}),
    "satellite_loss": ("/gnss/observations", {
        "remaining": (int, 0, lambda v: 0 <= v <= 255, "in 0..255 satellites"),
        "ramp_s": (_NUM, 0.0, lambda v: 0.0 <= v <= 1e6, "in [0, 1e6] s")}),
    "position_jump": ("/gnss/fix", {
        "north_m": (_NUM, 0.0, lambda v: abs(v) <= 1e7, "|north| <= 1e7 m"),
        "east_m": (_NUM, 0.0, lambda v: abs(v) <= 1e7, "|east| <= 1e7 m"),
        "up_m": (_NUM, 0.0, lambda v: abs(v) <= 1e7, "|up| <= 1e7 m"),
        "ramp_s": (_NUM, 0.0, lambda v: 0.0 <= v <= 1e6, "in [0, 1e6] s")}),
    "magnetic_disturbance": ("/imu/mag_raw", {
        "field_t": (list, REQUIRED, lambda v: len(v) == 3 and all(
            isinstance(x, _NUM) and not isinstance(x, bool) and abs(x) <= 1e-2 for x in v),
            "of 3 numbers, each within +-0.01 T"),
        "ramp_s": (_NUM, 0.0, lambda v: 0.0 <= v <= 1e6, "in [0, 1e6] s")}),
    "cycle_slip": ("/gnss/observations", {
        "cycles": (int, REQUIRED, lambda v: v != 0 and abs(v) <= 1_000_000, "non-zero integer"),
        "fraction": (_NUM, 1.0, lambda v: 0.0 < v <= 1.0, "in (0, 1] of the satellites")}),
}

_COMMON = {"kind", "topic", "start", "duration", "name"}
_TRUTH_PREFIX = "/truth/"


class FaultSpecError(ParamsFileError):
    """A fault specification that cannot be used (one line naming the entry and the key)."""


@dataclass(frozen=True)
class Fault:
    """One parsed fault.

    Attributes
    ----------
    index : int
        Position in the specification (its ``faults[index]``).
    kind : str
        One of :data:`KINDS`.
    topic : str
        fnmatch pattern over absolute topic names.
    start_s, end_s : float
        Window relative to the first message of the stream, s; ``end_s`` is ``inf`` when open.
    params : dict
        The kind's parameters with defaults filled in.
    name : str
        Label in the injection record (default ``<index>:<kind>``).
    """

    index: int
    kind: str
    topic: str
    start_s: float
    end_s: float
    params: dict = field(default_factory=dict)
    name: str = ""

    def matches(self, topic: str) -> bool:
        """True if ``topic`` (absolute) is one this fault acts on (never ``/truth/*``)."""
        return not topic.startswith(_TRUTH_PREFIX) and fnmatch.fnmatchcase(topic, self.topic)


@dataclass(frozen=True)
class FaultSpec:
    """A parsed specification: the seed and the faults in the order they are applied."""

    seed: int
    faults: tuple[Fault, ...]


def _is_type(value: Any, types) -> bool:
    # bool is an int in Python but never a number or a count in a specification.
    if isinstance(value, bool):
        return types is bool
    return isinstance(value, types)


def _parse_entry(i: int, entry: Any) -> Fault:
    if not isinstance(entry, dict):
        raise FaultSpecError(f"faults[{i}]: an entry is a mapping with 'kind' and 'start'")
    kind = entry.get("kind")
    if not isinstance(kind, str) or kind not in KINDS:
        raise FaultSpecError(f"faults[{i}]: unknown kind {kind!r}; known: {', '.join(KINDS)}")
    where = f"faults[{i}] ({kind})"
    default_topic, schema = KINDS[kind]
    unknown = sorted(set(entry) - _COMMON - set(schema), key=str)
    if unknown:
        raise FaultSpecError(f"{where}: unknown key {unknown[0]!r}; allowed:"
                             f" {', '.join(sorted(_COMMON | set(schema)))}")
    topic = entry.get("topic", default_topic)
    if topic is None:
        raise FaultSpecError(f"{where}: missing 'topic' (a topic name or fnmatch pattern)")
    if not isinstance(topic, str) or not topic.strip() or len(topic) > 256:
        raise FaultSpecError(f"{where}: 'topic' must be a topic name or pattern")
    topic = topic if topic.startswith("/") else "/" + topic
    start = entry.get("start")
    if not _is_type(start, _NUM) or not 0.0 <= start < 1e9:
        raise FaultSpecError(f"{where}: 'start' must be a number of seconds in [0, 1e9),"
                             f" got {start!r}")
    duration = entry.get("duration")
    if duration is None:
        end = math.inf
    elif not _is_type(duration, _NUM) or not 0.0 < duration < 1e9:
        raise FaultSpecError(f"{where}: 'duration' must be a number of seconds in (0, 1e9),"
                             f" got {duration!r}")
    else:
        end = float(start) + float(duration)
    params = {}
    for key, (types, default, check, demand) in schema.items():
        if key not in entry:
            if default is REQUIRED:
                raise FaultSpecError(f"{where}: missing {key!r}")
            params[key] = default
            continue
        value = entry[key]
        if not _is_type(value, types) or (check is not None and not check(value)):
            hint = ""
            if types is _NUM and isinstance(value, str) and _looks_numeric(value):
                hint = " (a quoted number is text: write it without quotes)"
            raise FaultSpecError(f"{where}: {key!r} must be {_type_name(types)}"
                                 f"{', ' + demand if demand else ''}, got {_short(value)}{hint}")
        params[key] = value
    if "field" in params:
        path = params["field"]
        if not all(part.isidentifier() for part in path.split(".")):
            raise FaultSpecError(f"{where}: 'field' must be a dotted field path such as"
                                 f" 'angular_velocity.z', got {path!r}")
    if kind == "loop":
        if start <= 0.0:
            raise FaultSpecError(f"{where}: 'start' must be > 0: the loop jumps back from there")
        if math.isinf(end):
            end = 2.0 * start  # default: replay everything before the jump back once
        if end - start > start:
            # The replayed beginning [0, duration) must precede the window it fills.
            raise FaultSpecError(f"{where}: 'duration' ({end - start:g} s) must not exceed"
                                 f" 'start' ({start:g} s): the loop replays the first"
                                 " 'duration' seconds")
    name = entry.get("name", f"{i}:{kind}")
    if not isinstance(name, str) or len(name) > 100:
        raise FaultSpecError(f"{where}: 'name' must be a string of at most 100 characters")
    return Fault(i, kind, topic, float(start), float(end), params, name)


def _looks_numeric(text: str) -> bool:
    try:
        float(text)
    except ValueError:
        return False
    return True


def _type_name(types) -> str:
    names = {bool: "true/false", int: "an integer", str: "a string", list: "a list",
             _NUM: "a number"}
    return names.get(types, "a value")


def _short(value: Any) -> str:
    text = repr(value)
    return text if len(text) <= 40 else text[:37] + "..."


def parse_fault_spec(data: Mapping) -> FaultSpec:
    """Check a specification already loaded as plain data (see the module documentation).

    Raises
    ------
    FaultSpecError
    """
    if not isinstance(data, dict):
        raise FaultSpecError("a fault specification is a mapping with 'faults' (and 'seed')")
    unknown = sorted(set(data) - {"seed", "faults"}, key=str)
    if unknown:
        raise FaultSpecError(f"unknown top-level key {unknown[0]!r}; allowed: seed, faults")
    seed = data.get("seed", 0)
    if not _is_type(seed, int) or not 0 <= seed < 2**63:
        raise FaultSpecError(f"'seed' must be a non-negative integer, got {_short(seed)}")
    faults = data.get("faults")
    if not isinstance(faults, list) or len(faults) > 1000:
        raise FaultSpecError("'faults' must be a list of at most 1000 entries")
    return FaultSpec(seed, tuple(_parse_entry(i, e) for i, e in enumerate(faults)))


def load_fault_spec(source, *, text: bool = False) -> FaultSpec:
    """Read a specification from a YAML file (or from YAML text with ``text=True``).

    Raises
    ------
    FaultSpecError
        File, YAML and content problems alike, prefixed with the file name.
    """
    name = "<text>" if text else str(source)
    try:
        data = load_yaml(source, name) if text else load_yaml_file(source)
        return parse_fault_spec(data)
    except FaultSpecError as err:
        raise FaultSpecError(f"{name}: {err}") from None
    except ParamsFileError as err:
        raise FaultSpecError(str(err)) from None
