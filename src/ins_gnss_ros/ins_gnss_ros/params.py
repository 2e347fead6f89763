"""Node parameters as ROS-free specifications: name, default, meaning with unit, admissible range.

The nodes declare them to ROS (:mod:`ins_gnss_ros.nodes.base`); the offline paths read the same
specifications to fill in defaults and check a profile's values (:func:`resolve`), so that a
parameter means one thing and is bounded the same way on every path.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, Mapping, Sequence


class ParameterError(ValueError):
    """A parameter value outside its documented range or type."""


@dataclass(frozen=True)
class Param:
    """One declared parameter: name, default, what it means (with unit) and its admissible range.

    ``low``/``high`` bound numbers (and every element of a numeric list), ``choices`` bounds
    strings, ``length`` fixes the length of a list (e.g. 3 for a lever arm).
    """

    name: str
    default: Any
    description: str
    low: float | None = None
    high: float | None = None
    choices: tuple[str, ...] | None = None
    length: int | None = None

    def validate(self, value: Any) -> Any:
        """Return ``value`` if admissible, else raise :class:`ParameterError` naming the parameter."""
        values = list(value) if isinstance(value, (list, tuple)) else [value]
        if self.length is not None and len(values) != self.length:
            raise ParameterError(f"parameter '{self.name}': expected {self.length} values, got {value!r}")
        expected = self._kind()
        accepted = _ACCEPTED.get(expected, (expected,))
        wrong = next((v for v in values if _kind_of(v) not in accepted), None)
        if wrong is not None:
            # (as ROS refuses a value of another type: a quoted number read as text reached
            # the filter's arithmetic and ended a replay in a TypeError)
            raise ParameterError(f"parameter '{self.name}' = {value!r}: {wrong!r} is not "
                                 f"a {expected}")
        for v in values:
            if isinstance(v, (int, float)) and not isinstance(v, bool):
                if not math.isfinite(v):
                    raise ParameterError(f"parameter '{self.name}': {value!r} is not finite")
                if (self.low is not None and v < self.low) or (self.high is not None and v > self.high):
                    raise ParameterError(
                        f"parameter '{self.name}' = {value!r} is outside [{self.low}, {self.high}]"
                        f" ({self.description})"
                    )
        if self.choices is not None and value not in self.choices:
            raise ParameterError(
                f"parameter '{self.name}' = {value!r} is not one of {', '.join(self.choices)}"
            )
        return value

    def _kind(self) -> str:
        """The kind of value the default is (its elements' for a list)."""
        default = self.default
        if isinstance(default, (list, tuple)):
            return _kind_of(default[0]) if default else "number"
        return _kind_of(default)


def _kind_of(value: Any) -> str:
    """'bool', 'integer', 'number' (float), 'string', or the type's name (the kind a
    parameter's default gives it)."""
    if isinstance(value, bool):
        return "bool"
    if isinstance(value, int):
        return "integer"
    if isinstance(value, float):
        return "number"
    if isinstance(value, str):
        return "string"
    return type(value).__name__


#: The kinds of value each kind of parameter takes (a float one an integer too, as the offline
#: paths always have; ROS itself takes a double for a double only).
_ACCEPTED = {"bool": ("bool",), "integer": ("integer",), "number": ("number", "integer"),
             "string": ("string",)}


def resolve(specs: Sequence[Param], values: Mapping[str, Any]) -> dict[str, Any]:
    """Every parameter of ``specs``: its value in ``values`` (validated) or its default.

    Raises
    ------
    ParameterError
        A value outside its range, or a name in ``values`` that no spec declares (a typo in a
        profile would otherwise silently leave the default in place).
    """
    names = {spec.name for spec in specs}
    unknown = sorted(set(values) - names)
    if unknown:
        raise ParameterError(f"unknown parameter(s): {', '.join(unknown)}")
    return {spec.name: spec.validate(values.get(spec.name, spec.default)) for spec in specs}
