"""Compile the numba kernels into their cache at set-up, so that the first run does not.

The kernels (``nav/_kernels.py``, ``gnss/lambda_search.py``) are ``cache=True``: numba keeps
their machine code in the ``__pycache__`` next to the source and compiles a kernel again only
for a new argument type or after its source changed. A fresh install has no cache, and the first
replay spent most of its start compiling (docs/results/live_cost.md). This runs what the product
paths call, with their own argument types: a short simulated car drive through the in-process
graph and the offline path of ``config/default.yaml`` (strapdown, coning/sculling, system matrix,
Picard series, Kalman update, lever arm, the strapdown's corrections and re-mechanisation), and
the two LAMBDA searches of the phase-difference heading, and a heading's model.
``scripts/setup.sh`` runs it when a kernel's source changed; test/nav/test_warm_numba.py checks
it covers the bundled trials.

Usage: ``.venv/bin/python scripts/warm_numba.py`` (a few seconds with the cache, about 15 s
without).
"""
from __future__ import annotations

import tempfile
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
PROFILE = ROOT / "config" / "default.yaml"


def warm() -> None:
    from ins_gnss_ros.gnss.lambda_search import enumerate_ellipsoid, integer_least_squares
    from ins_gnss_ros.nav.measurements import azimuth_of_axis
    from ins_gnss_ros.trial.offline import replay_offline
    from ins_gnss_ros.trial.replay import replay
    from ins_gnss_ros.trial.simulate import simulate

    with tempfile.TemporaryDirectory() as tmp:
        bag = Path(tmp) / "car"
        simulate("car", 12.0, 0, bag)
        replay(bag, PROFILE, Path(tmp) / "graph")
        replay_offline(bag, PROFILE, Path(tmp) / "offline")
    Q = np.array([[2.0, 0.5, 0.1], [0.5, 1.5, 0.2], [0.1, 0.2, 1.0]])
    a = np.array([0.3, -1.2, 2.6])
    integer_least_squares(a, Q, 2)
    enumerate_ellipsoid(a, Q, 4.0, 100)
    # A heading's model (the simulated drive has none; the vessel trial does).
    azimuth_of_axis(np.array([1.0, 0.0, 0.0, 0.0]))


if __name__ == "__main__":
    warm()
