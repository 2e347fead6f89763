"""Safe loading of YAML files that come from outside the program: params, calibration, fault specs.

A params file, a calibration file or a fault specification is untrusted input: it may be damaged,
truncated, written by hand with a typo, or crafted. Everything here therefore

* reads at most ``max_bytes`` (default 1 MiB) and requires UTF-8 text;
* parses with PyYAML's safe loader only (plain data: no Python object construction);
* bounds the document before building Python objects from it: at most ``max_nodes`` nodes counted
  *with* alias expansion (a "billion laughs" document of nested aliases is refused after the
  budget, in time proportional to the budget, not to its expanded size), at most ``max_depth``
  levels of nesting, no duplicate keys (PyYAML would silently keep the last one);
* accepts only the JSON-like types (mapping with string keys, list, str, int, float, bool, null)
  and finite numbers (``.nan``/``.inf`` are refused where a number is expected, i.e. anywhere);
* reports every problem as one :class:`ParamsFileError` whose message is one line naming the file
  and, where it applies, the line and the key path.

``main()`` is the command-line pattern shared by the tools: check the named files, print one line
per problem, exit with status 2, never a traceback.
"""

from __future__ import annotations

import argparse
import math
import re
import sys
from pathlib import Path
from typing import Any, Iterable, Mapping

import numpy as np
import yaml

#: Largest file read, bytes. A params file of the whole graph is a few kB.
MAX_BYTES = 1 << 20
#: Largest number of YAML nodes (scalars, sequences, mappings), aliases counted each time used.
MAX_NODES = 100_000
#: Deepest nesting of sequences/mappings.
MAX_DEPTH = 32

# A ROS 2 params file value: a scalar or a homogeneous list of scalars (rcl_yaml_param_parser).
_ROS_SCALARS = (bool, int, float, str)


# (libyaml's parser when PyYAML was built with it: much faster on a 1 MiB file)
class _SafeLoader(yaml.CSafeLoader if yaml.__with_libyaml__ else yaml.SafeLoader):
    """PyYAML's safe loader, reading a number with an exponent and no point (``6e-3``) as a
    float, as ROS's params-file parser (rcl_yaml_param_parser's strtod) does: YAML 1.1 reads
    it as text, which reached the filter's arithmetic as a string."""


_SafeLoader.add_implicit_resolver(
    "tag:yaml.org,2002:float", re.compile(r"^[-+]?(?:[0-9]+\.?[0-9]*|\.[0-9]+)[eE][-+]?[0-9]+$"),
    list("-+0123456789."))


class ParamsFileError(ValueError):
    """An untrusted YAML file that cannot be used; the message is one line naming the problem."""


def _where(source: str, node=None, path: str = "") -> str:
    """``source:line: at path`` for a YAML node or event (either has a start mark)."""
    line = f":{node.start_mark.line + 1}" if node is not None and node.start_mark else ""
    return f"{source}{line}" + (f": at {path}" if path else "")


def _key_text(key: str) -> str:
    """A key as it may appear in a one-line message (quoted if it has odd characters)."""
    return key if key.isprintable() and key.strip() == key and len(key) <= 64 else repr(key[:64])


def _check_events(data: str, source: str, max_nodes: int, max_depth: int) -> None:
    """Bound nesting depth and node count on the event stream, before any node graph is built.

    PyYAML's composer recurses once per nesting level (the C one too), so a document of 100 000
    nested brackets must be refused here, where the parser is an iterative state machine.
    """
    depth = count = 0
    for event in yaml.parse(data, Loader=_SafeLoader):
        if isinstance(event, (yaml.SequenceStartEvent, yaml.MappingStartEvent)):
            depth += 1
            if depth > max_depth:
                raise ParamsFileError(f"{_where(source, event)}: nesting deeper than {max_depth}")
        elif isinstance(event, (yaml.SequenceEndEvent, yaml.MappingEndEvent)):
            depth -= 1
        if isinstance(event, yaml.NodeEvent):
            count += 1
            if count > max_nodes:
                raise ParamsFileError(f"{source}: more than {max_nodes} YAML nodes: refused")


def _check_tree(root: yaml.Node, source: str, max_nodes: int, max_depth: int) -> None:
    """Walk the composed node graph (aliases followed) within the node and depth budgets.

    Iterative, so a deep or self-referencing document cannot exhaust the Python stack; every
    visit spends budget, so the walk ends after at most ``max_nodes`` steps whatever the input.
    """
    count = 0
    stack: list[tuple[yaml.Node, int, str]] = [(root, 1, "")]
    while stack:
        node, depth, path = stack.pop()
        count += 1
        if count > max_nodes:
            raise ParamsFileError(f"{source}: more than {max_nodes} YAML nodes (aliases expanded):"
                                  " refused")
        if depth > max_depth:
            raise ParamsFileError(f"{_where(source, node, path)}: nesting deeper than {max_depth}")
        if isinstance(node, yaml.MappingNode):
            seen: set[str] = set()
            for key, value in node.value:
                if not isinstance(key, yaml.ScalarNode):
                    raise ParamsFileError(f"{_where(source, key, path)}: a key must be a plain"
                                          " string")
                if key.tag == "tag:yaml.org,2002:merge":
                    raise ParamsFileError(f"{_where(source, key, path)}: merge keys ('<<') are"
                                          " not accepted")
                if key.value in seen:
                    raise ParamsFileError(f"{_where(source, key, path)}: duplicate key"
                                          f" {key.value!r}")
                seen.add(key.value)
                name = _key_text(key.value)
                stack.append((value, depth + 1, f"{path}.{name}" if path else name))
        elif isinstance(node, yaml.SequenceNode):
            stack.extend((item, depth + 1, f"{path}[{i}]") for i, item in enumerate(node.value))


def _check_values(data: Any, source: str, path: str = "") -> None:
    """Only JSON-like types with string keys and finite floats (iterative, after _check_tree)."""
    stack = [(data, path)]
    while stack:
        value, where = stack.pop()
        if isinstance(value, dict):
            for key, item in value.items():
                if not isinstance(key, str):
                    raise ParamsFileError(f"{source}: at {where or '<root>'}: key {key!r} is not"
                                          " a string")
                name = _key_text(key)
                stack.append((item, f"{where}.{name}" if where else name))
        elif isinstance(value, list):
            stack.extend((item, f"{where}[{i}]") for i, item in enumerate(value))
        elif isinstance(value, float):
            if not math.isfinite(value):
                raise ParamsFileError(f"{source}: at {where or '<root>'}: {value} is not a finite"
                                      " number")
        elif value is not None and not isinstance(value, (bool, int, str)):
            # Timestamps, !!binary, !!set: legal YAML, but no parameter or calibration is one.
            raise ParamsFileError(f"{source}: at {where or '<root>'}: unsupported value of type"
                                  f" {type(value).__name__}")


def load_yaml(data: str | bytes, source: str = "<string>", *, max_bytes: int = MAX_BYTES,
              max_nodes: int = MAX_NODES, max_depth: int = MAX_DEPTH) -> dict:
    """Parse untrusted YAML text whose root must be a mapping.

    Parameters
    ----------
    data : str or bytes
        The document (bytes must be UTF-8).
    source : str
        Name used in error messages (normally the file path).
    max_bytes, max_nodes, max_depth : int
        Limits, see the module documentation.

    Returns
    -------
    dict
        Plain data: dict (str keys), list, str, int, float (finite), bool, None.

    Raises
    ------
    ParamsFileError
        Anything wrong with the document, as one line.
    """
    if isinstance(data, bytes):
        if len(data) > max_bytes:
            raise ParamsFileError(f"{source}: larger than {max_bytes} bytes: refused")
        try:
            data = data.decode("utf-8")
        except UnicodeDecodeError as err:
            raise ParamsFileError(f"{source}: not UTF-8 text (byte {err.start})") from None
    elif len(data) > max_bytes:
        raise ParamsFileError(f"{source}: larger than {max_bytes} characters: refused")
    loader = None
    try:
        _check_events(data, source, max_nodes, max_depth)
        # Compose (nodes only, nothing constructed), check the expanded graph, then construct
        # from the same loader: exactly yaml.safe_load split in two so the checks come first.
        loader = _SafeLoader(data)
        node = loader.get_single_node()
        if node is None:
            raise ParamsFileError(f"{source}: empty document (a mapping is expected)")
        if not isinstance(node, yaml.MappingNode):
            raise ParamsFileError(f"{_where(source, node)}: the document must be a mapping,"
                                  f" not a {_kind(node)}")
        _check_tree(node, source, max_nodes, max_depth)
        result = loader.construct_document(node)
    except yaml.MarkedYAMLError as err:
        mark = err.problem_mark or err.context_mark
        line = f":{mark.line + 1}" if mark is not None else ""
        raise ParamsFileError(f"{source}{line}: malformed YAML:"
                              f" {_one_line(err.problem or err.context)}") from None
    except yaml.YAMLError as err:
        raise ParamsFileError(f"{source}: malformed YAML: {_one_line(err)}") from None
    except (ValueError, TypeError, OverflowError) as err:
        if isinstance(err, ParamsFileError):
            raise
        # The safe constructor's own conversions (e.g. an invalid timestamp or base64).
        raise ParamsFileError(f"{source}: invalid value: {_one_line(err)}") from None
    finally:
        if loader is not None:
            loader.dispose()
    _check_values(result, source)
    return result


def _one_line(text) -> str:
    """A library's message (which may quote the input) as one bounded line."""
    return " ".join(str(text).split())[:200]


def _kind(node: yaml.Node) -> str:
    return "sequence" if isinstance(node, yaml.SequenceNode) else "scalar"


def load_yaml_file(path, **limits) -> dict:
    """Read and parse an untrusted YAML file (see :func:`load_yaml` for limits and errors)."""
    path = Path(path)
    max_bytes = limits.get("max_bytes", MAX_BYTES)
    try:
        with path.open("rb") as f:
            data = f.read(max_bytes + 1)  # never read more than needed to refuse it
    except OSError as err:
        raise ParamsFileError(f"{path}: cannot read ({err.strerror or err})") from None
    return load_yaml(data, str(path), **limits)


def _flatten(params: Mapping, source: str, node: str, prefix: str = "") -> dict[str, Any]:
    """ROS 2 nested parameter namespaces (``a: {b: 1}``) as dotted names (``a.b``)."""
    flat: dict[str, Any] = {}
    for key, value in params.items():
        name = f"{prefix}{key}"
        if isinstance(value, dict):
            flat.update(_flatten(value, source, node, name + "."))
            continue
        if isinstance(value, list):
            types = {type(v) for v in value}
            if any(isinstance(v, (dict, list)) or v is None for v in value) or len(types) > 1:
                raise ParamsFileError(f"{source}: {node}: parameter {name!r}: a list must hold"
                                      " values of one scalar type")
        elif value is None or not isinstance(value, _ROS_SCALARS):
            raise ParamsFileError(f"{source}: {node}: parameter {name!r} has no value")
        flat[name] = value
    return flat


def load_params_file(path, **limits) -> dict[str, dict[str, Any]]:
    """Read a ROS 2 ``--params-file`` (``<node>: ros__parameters: {...}``) defensively.

    Returns
    -------
    dict
        ``{node name without leading '/': {dotted parameter name: value}}``; values are bool,
        int, float (finite), str or homogeneous lists of those, as ROS 2 accepts.

    Raises
    ------
    ParamsFileError
        Including a section without a ``ros__parameters`` mapping.
    """
    data = load_yaml_file(path, **limits)
    out = {}
    for node, body in data.items():
        if not isinstance(body, dict) or not isinstance(body.get("ros__parameters"), dict):
            raise ParamsFileError(f"{path}: section {node!r} has no 'ros__parameters' mapping")
        out[node.strip("/") or "/"] = _flatten(body["ros__parameters"], str(path), node)
    return out


def numeric_array(data: Mapping, key: str, shape: tuple[int, ...], source: str = "<data>"
                  ) -> np.ndarray:
    """``data[key]`` as a float array of exactly ``shape`` with finite entries.

    For calibration files (e.g. a 3x3 misalignment matrix, a 3-vector of biases): the value must
    be a (nested) list of numbers; booleans are refused even though Python counts them as ints.

    Raises
    ------
    ParamsFileError
        Naming ``source`` and ``key``.
    """
    if key not in data:
        raise ParamsFileError(f"{source}: missing {key!r}")
    value = data[key]

    def numbers_only(v) -> bool:
        if isinstance(v, list):
            return all(numbers_only(x) for x in v)
        return isinstance(v, (int, float)) and not isinstance(v, bool)

    if not numbers_only(value):
        raise ParamsFileError(f"{source}: {key!r} must be numbers, got {_short(value)}")
    try:
        arr = np.asarray(value, dtype=float)
    except (ValueError, OverflowError):  # ragged nesting
        raise ParamsFileError(f"{source}: {key!r} must have shape {shape}") from None
    if arr.shape != tuple(shape):
        raise ParamsFileError(f"{source}: {key!r} must have shape {tuple(shape)}, got {arr.shape}")
    if not np.all(np.isfinite(arr)):
        raise ParamsFileError(f"{source}: {key!r} has non-finite entries")
    return arr


def _short(value: Any) -> str:
    text = repr(value)
    return text if len(text) <= 60 else text[:57] + "..."


def check_files(paths: Iterable, kind: str = "yaml") -> list[str]:
    """Load each file as ``kind`` (``yaml`` or ``params``); return one error line per bad file."""
    load = load_params_file if kind == "params" else load_yaml_file
    errors = []
    for path in paths:
        try:
            load(path)
        except ParamsFileError as err:
            errors.append(str(err))
    return errors


def main(argv: list[str] | None = None) -> int:
    """``python -m ins_gnss_ros.params_io [--params] FILE...``: 0 if all load, else 2."""
    parser = argparse.ArgumentParser(description="check untrusted YAML params/calibration files")
    parser.add_argument("files", nargs="+", type=Path)
    parser.add_argument("--params", action="store_true", help="check the ROS 2 params layout")
    args = parser.parse_args(argv)
    errors = check_files(args.files, "params" if args.params else "yaml")
    for line in errors:
        print(f"error: {line}", file=sys.stderr)
    return 2 if errors else 0


if __name__ == "__main__":
    sys.exit(main())
