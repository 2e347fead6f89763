"""rclpy message objects: type names and classes, fast default instances, NaN-aware comparison.

rclpy's generated message classes are slow per object for the hot paths of this package: the
constructor imports and builds every default sub-message and then sets it through a property
(``Imu()`` ~30 µs, ``InsState()`` ~65 µs here). The classes of ``rosidl_generator_py`` keep each
field ``f`` in the slot ``_f`` (plus ``_check_fields``) and describe the fields in
``SLOT_TYPES``; the properties only check and store. :func:`new` builds a default instance
through the slots, and :mod:`ins_gnss_ros.io.cdr` decodes into them the same way.
"""
from __future__ import annotations

import math
from functools import lru_cache
from importlib import import_module

import numpy as np


class MessageTypeError(ValueError):
    """A message type name that is malformed or not installed."""


def msgtype_of(msg) -> str:
    """ROS type name ``pkg/msg/Name`` of an rclpy message object."""
    return msgtype_of_class(type(msg))


@lru_cache(maxsize=None)
def msgtype_of_class(cls) -> str:
    """ROS type name ``pkg/msg/Name`` of an rclpy message class."""
    return f"{cls.__module__.split('.')[0]}/msg/{cls.__name__}"


@lru_cache(maxsize=None)
def msg_class(msgtype: str):
    """rclpy class of a type name ``pkg/msg/Name`` (also ``pkg/Name``).

    Raises
    ------
    MessageTypeError
        Not a type name, or the type is not installed.
    """
    parts = msgtype.split("/")
    if len(parts) not in (2, 3) or (len(parts) == 3 and parts[1] != "msg"):
        raise MessageTypeError(f"not a message type name: {msgtype!r}")
    try:
        return getattr(import_module(f"{parts[0]}.msg"), parts[-1])
    except (ImportError, AttributeError):
        raise MessageTypeError(f"message type {msgtype!r} is not installed") from None


def new(cls):
    """A default instance of the rclpy message class ``cls``, equal to ``cls()``."""
    return _constructor(cls)()


@lru_cache(maxsize=None)
def template(cls):
    """One default instance of ``cls`` (shared: read it, never change it)."""
    return cls()


@lru_cache(maxsize=None)
def _constructor(cls):
    """Function making instances equal to ``cls()`` from the fields of one made by ``cls()``:
    numbers and strings shared (immutable), arrays copied, sub-messages made the same way."""
    plain, made = [], []
    for slot in cls.__slots__:
        value = getattr(template(cls), slot)
        if hasattr(value, "SLOT_TYPES"):
            made.append((slot, _constructor(type(value))))
        elif isinstance(value, list):      # an array of messages, or an empty sequence
            made.append((slot, lambda v=value: [_constructor(type(e))() for e in v]))
        elif hasattr(value, "copy"):       # numpy and array.array values (mutable)
            made.append((slot, value.copy))
        else:
            plain.append((slot, value))
    new_object = cls.__new__

    def construct():
        out = new_object(cls)
        for slot, value in plain:
            setattr(out, slot, value)
        for slot, make in made:
            setattr(out, slot, make())
        return out

    return construct


def messages_equal(a, b) -> bool:
    """Field-by-field equality of two messages, NaN equal to NaN (rclpy's ``==`` says NaN !=
    NaN)."""
    return first_difference(a, b) is None


def first_difference(a, b, path="") -> str | None:
    """Dotted path and values of the first field where messages a and b differ (NaN equal to
    NaN), or None when they are equal."""
    if hasattr(a, "get_fields_and_field_types"):
        if type(a) is not type(b):
            return f"{path or 'message'}: type {type(a).__name__} vs {type(b).__name__}"
        for name in a.get_fields_and_field_types():
            diff = first_difference(getattr(a, name), getattr(b, name),
                                    f"{path}.{name}" if path else name)
            if diff is not None:
                return diff
        return None
    if isinstance(a, (list, tuple, np.ndarray)) or type(a).__name__ == "array":
        if len(a) != len(b):
            return f"{path}: length {len(a)} vs {len(b)}"
        for i, (x, y) in enumerate(zip(a, b)):
            diff = first_difference(x, y, f"{path}[{i}]")
            if diff is not None:
                return diff
        return None
    if isinstance(a, float) or isinstance(b, float):
        same = (math.isnan(a) and math.isnan(b)) or a == b
    else:
        same = a == b
    return None if same else f"{path}: {a!r} vs {b!r}"
