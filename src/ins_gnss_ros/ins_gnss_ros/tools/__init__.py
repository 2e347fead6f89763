"""Command-line tools (calibration and characterisation); each module exposes ``main(argv)``."""

from __future__ import annotations

import sys

import yaml


def write_yaml(data: dict, path: str | None) -> None:
    """Write ``data`` as YAML to ``path``, or to standard output when ``path`` is None."""
    text = yaml.safe_dump(data, sort_keys=False)
    if path:
        with open(path, "w") as f:
            f.write(text)
    else:
        sys.stdout.write(text)
