"""``trial smooth``: post-processing of a bag, the forward filter and then the RTS smoother.

The forward pass is the offline path's (trial/offline.py :func:`forward_pass`: the profile's
imu_preprocessor and ekf cores, the aiding front end the ekf node uses), recorded with its
covariances; :func:`~ins_gnss_ros.nav.smoother.rts_smooth` runs backwards over it. ``OUT/bag``
holds

* ``ins/state``, ``nav/fix``, ``nav/odom`` (with covariance), ``nav/status``: the smoothed
  solution at the filter's epochs, ``ins/state`` with the smoothed sensor errors; what
  ``trial evaluate OUT`` reads, as from a replay;
* ``forward/ins/state``, ``forward/nav/fix``, ``forward/nav/odom``, ``forward/nav/status``: the
  forward pass, message for message what ``trial replay --offline`` records;
* with a ``point`` (base_link FLU lever arm): ``point/state`` and ``forward/point/state``,
  InsState of that body point (position, velocity, attitude, compensated rates) at every IMU
  sample (the smoothed: :func:`~ins_gnss_ros.nav.smoother.imu_rate_track`; the forward: its
  own states there, :func:`~ins_gnss_ros.nav.smoother.sample_rate_track`, those of
  ``forward/ins/state``).

The forward record is what bounds the memory: P, P- and Phi per epoch (3 n^2 doubles, 10 Hz or
faster), kept once (the navigator's output is a view of its record); the bag is read and the
outputs written as streams (docs/results/postprocessing.md).
"""
from __future__ import annotations

import dataclasses
import heapq
import json
import time
from operator import itemgetter
from pathlib import Path
from typing import Iterator

import numpy as np

from ins_gnss_ros import io as bagio
from ins_gnss_ros.nav import Navigator
from ins_gnss_ros.trial.offline import forward_pass, output_messages, write_ordered

#: Topic prefix of the forward pass in a smoothed run's bag.
FORWARD_PREFIX = "forward/"
#: Topic of the IMU-rate solution at the ``--point``.
POINT_TOPIC = "point/state"


class _Increments:
    """The increments a navigator was given, in growing arrays (one sample per call is the
    usual case: a list of arrays would cost 100 bytes of overhead a sample)."""

    def __init__(self):
        self.n = 0
        self.t, self.dtheta, self.dv = np.empty(0), np.empty((0, 3)), np.empty((0, 3))

    def add(self, t, dtheta, dv):
        t = np.atleast_1d(np.asarray(t, float))
        m = len(t)
        if self.n + m > len(self.t):
            size = max(65536, 2 * (self.n + m))
            self.t = np.resize(self.t, size)
            self.dtheta = np.resize(self.dtheta, (size, 3))
            self.dv = np.resize(self.dv, (size, 3))
        self.t[self.n:self.n + m] = t
        self.dtheta[self.n:self.n + m] = dtheta
        self.dv[self.n:self.n + m] = dv
        self.n += m

    def arrays(self):
        return self.t[:self.n], self.dtheta[:self.n], self.dv[:self.n]


class _KeepingNavigator(Navigator):
    """A Navigator that keeps every increment it is given (for the IMU-rate output)."""

    def __init__(self, config):
        self.increments = _Increments()
        super().__init__(config)

    def add_imu(self, t, dtheta, dv):
        self.increments.add(t, dtheta, dv)
        super().add_imu(t, dtheta, dv)


def smooth(bag_path, profile_path, out, outages=None, point=None, exports=(),
           progress=False, remap=None) -> dict:
    """Forward filter and RTS smoother of a profile over a bag; record both.

    Parameters
    ----------
    bag_path, profile_path, out, outages, progress, remap
        As :func:`ins_gnss_ros.trial.offline.replay_offline`.
    point : (3,) array_like, optional
        Body point (base_link FLU, m) whose IMU-rate solution is recorded.
    exports : iterable of str
        Export formats written into ``OUT/export`` (trial/export.py).

    Returns
    -------
    dict
        The summary (``OUT/replay.json``, mode ``smooth``) with ``timing_s`` and ``exports``.
    """
    from tqdm import tqdm

    from ins_gnss_ros.nav.smoother import rts_smooth
    from ins_gnss_ros.trial.export import check_formats, export_run

    formats = check_formats(exports)
    tic = time.perf_counter()
    lever = None if point is None else np.asarray(point, float).reshape(3)
    run = forward_pass(bag_path, profile_path, outages, progress, out=out,
                       navigator_type=None if lever is None else _KeepingNavigator, remap=remap)
    out = Path(out)
    forward = run.navigator.output()
    config = run.navigator.config
    increments = None if lever is None else run.navigator.increments.arrays()
    # The output keeps the record (views of it); the rest of the navigator can go.
    run.navigator = None
    toc_forward = time.perf_counter()
    if forward.P is None:
        raise ValueError(f"{bag_path}: the filter never started (no GNSS fix to level on): "
                         "nothing to smooth")
    sm = rts_smooth(forward)
    # At the epochs: the forward pass's states between them are not smoothed.
    smoothed = dataclasses.replace(forward, lat=sm.lat, lon=sm.lon, h=sm.h, v_enu=sm.v_enu,
                                   q_nb=sm.q_nb, P=sm.P, estimates=sm.estimates, samples=None)
    del sm
    toc_smooth = time.perf_counter()
    # Both solutions (and their points) merged in stamp order, written as they are made.
    streams = []
    for prefix, result in (("", smoothed), (FORWARD_PREFIX, forward)):
        streams.append(output_messages(result, config, run.datum, run.frames, prefix))
        if lever is not None:
            streams.append(_point_messages(prefix + POINT_TOPIC, result, lever, *increments))
    with bagio.BagWriter(out / "bag", ordered=True) as writer:
        run.counts.recorded.update(write_ordered(writer, tqdm(
            heapq.merge(*streams, key=itemgetter(0)), disable=not progress, unit="msg",
            desc="writing")))
    toc_write = time.perf_counter()
    summary = run.summary(out, bag_path, outages, "smooth",
                          graph=run.graph + ("rts smoother",))
    summary["point_m"] = None if lever is None else lever.tolist()
    summary["exports"] = [str(p) for p in export_run(out, formats)] if formats else []
    summary["timing_s"] = {"forward": toc_forward - tic, "smoother": toc_smooth - toc_forward,
                           "write": toc_write - toc_smooth,
                           "export": time.perf_counter() - toc_write}
    (out / "smooth.json").write_text(json.dumps(
        {k: summary[k] for k in ("point_m", "exports", "timing_s")}, indent=2) + "\n")
    return summary


def _point_messages(topic, result, lever, t, dtheta, dv) -> Iterator:
    """InsState of the body point at `lever` at every IMU sample of a recorded pass, as
    (t_ns, topic, type name, CDR payload) in stamp order, encoded a block of samples at once
    (an IMU-rate track has millions)."""
    from ins_gnss_msgs.msg import InsState

    from ins_gnss_ros.nav.lever_arm import lever_arm_position, lever_arm_velocity
    from ins_gnss_ros.nav.smoother import imu_rate_track, sample_rate_track
    from ins_gnss_ros.nodes.convert import ins_state_payloads
    from ins_gnss_ros.trial.offline import OUTPUT_BLOCK

    # The forward pass's own (causal) states at the samples; the smoothed solution's between
    # its epochs
    dense = imu_rate_track(result, result.estimates, t, dtheta, dv) if result.samples is None \
        else sample_rate_track(result.samples, result.estimates, t, dtheta, dv)
    lat, lon, h = lever_arm_position(dense.lat, dense.lon, dense.h, dense.q_nb, lever)
    v = lever_arm_velocity(dense.v_enu, dense.q_nb, dense.omega_b, lever, dense.lat)
    stamps = bagio.sec_to_ns(dense.t)
    for first in range(0, len(dense.t), OUTPUT_BLOCK):
        k = slice(first, first + OUTPUT_BLOCK)
        payloads = ins_state_payloads(stamps[k], lat[k], lon[k], h[k], v[k], dense.q_nb[k],
                                      InsState.MODE_NAVIGATING, dense.omega_b[k])
        for t_ns, data in zip(stamps[k].tolist(), payloads):
            yield t_ns, topic, "ins_gnss_msgs/msg/InsState", data
