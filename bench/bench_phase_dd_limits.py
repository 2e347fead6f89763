"""What limits roll, pitch and heading with the direct carrier-phase update (issue 17): a
covariance analysis on the product path.

The bag is a ``trial simulate --antennas 4`` trial. Every run is ``trial replay`` of
config/sea_4ant.yaml (or ``--profile``) with some parameters changed, then ``trial evaluate``
(``--skip`` s left out). It prints the RMS errors against the truth and the filter's own 1-sigma
of roll, pitch and heading (RMS over the same epochs of the nav/odom covariance, through the
Euler-angle Jacobian of trial.evaluate). The covariance depends on the filter's model and the
measurement geometry, not on the data (to first order: the accepted updates are the same), so
in a run that changes only the model, e.g. the ekf's gyro noise ``noise.gyro_white`` or
phase_heading's DD noise model (``noise.phase_m``, ``multipath.phase_m``, which set the DD
covariance the ekf takes), the sigma is the attitude accuracy sensors of that quality would
reach on this trajectory and sky (a covariance analysis: Maybeck, "Stochastic Models,
Estimation and Control", vol. 1, ch. 6; Gelb, "Applied Optimal Estimation", ch. 7), while its
RMS error still carries the simulated sensors' errors and means nothing. The first run is the
profile as it is: there error and sigma must agree (the consistency check of the analysis).

Usage: ``.venv/bin/python bench/bench_phase_dd_limits.py BAG [--profile P] [--skip S]
[--variant "label:node.param=value,..."] ...`` (default variants: the gyro angle random walk
halved and quartered, the phase noise halved).
"""
from __future__ import annotations

import argparse
import sys
import tempfile
from pathlib import Path

import numpy as np
import yaml

from ins_gnss_ros.trial.evaluate import euler_error_jacobian
from ins_gnss_ros.trial.inputs import iter_topic
from ins_gnss_ros.trial.replay import replay
from ins_gnss_ros.trial.report import evaluate_run

REPO = Path(__file__).resolve().parents[1]
#: The simulated MEMS gyro white noise, rad/s/sqrt(Hz) (0.07 deg/s/sqrt(Hz), seed 004 section 2.5).
GYRO_WHITE = 1.2217e-3
DEFAULT_VARIANTS = (
    f"gyro ARW / 2:ekf.noise.gyro_white={GYRO_WHITE / 2}",
    f"gyro ARW / 4:ekf.noise.gyro_white={GYRO_WHITE / 4}",
    "phase noise / 2:phase_heading.noise.phase_m=0.001,phase_heading.multipath.phase_m=0.005",
)


def variant_profile(base: Path, changes: str, path: Path) -> Path:
    """A copy of profile ``base`` with ``node.param=value`` changes (comma-separated)."""
    data = yaml.safe_load(base.read_text())
    for item in filter(None, changes.split(",")):
        key, value = item.split("=", 1)
        node, param = key.split(".", 1)
        data[node]["ros__parameters"][param] = yaml.safe_load(value)
    path.write_text(yaml.safe_dump(data, sort_keys=False))
    return path


def filter_sigma(out_bag: Path, skip_s: float) -> np.ndarray:
    """RMS over the nav/odom epochs after ``skip_s`` of the filter's 1-sigma of (roll, pitch,
    azimuth), rad."""
    states = iter_topic(out_bag, "ins/state")
    t0 = next(states).t_ns
    var = []
    for m in iter_topic(out_bag, "nav/odom"):
        if m.t_ns - t0 < skip_s * 1e9:
            continue
        o = m.msg.pose.pose.orientation
        J = euler_error_jacobian(np.array([[o.w, o.x, o.y, o.z]]))[0]
        P = np.reshape(m.msg.pose.covariance, (6, 6))[3:, 3:]
        var.append(np.diag(J @ P @ J.T))
    return np.sqrt(np.mean(var, axis=0))


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("bag")
    ap.add_argument("--profile", type=Path, default=REPO / "config" / "sea_4ant.yaml")
    ap.add_argument("--skip", type=float, default=60.0, help="s")
    ap.add_argument("--variant", action="append", default=None, metavar="LABEL:CHANGES")
    args = ap.parse_args(argv)
    runs = [("as profiled", "")] + [tuple(v.split(":", 1)) for v in
                                    (args.variant or DEFAULT_VARIANTS)]
    print(f"{args.bag}, {args.profile.name}, after {args.skip:g} s; deg\n")
    print("| run | roll RMS | pitch RMS | heading RMS | roll sigma | pitch sigma "
          "| heading sigma |")
    print("|---|---|---|---|---|---|---|")
    with tempfile.TemporaryDirectory() as tmp:
        for i, (label, changes) in enumerate(runs):
            profile = variant_profile(args.profile, changes, Path(tmp) / f"p{i}.yaml")
            out = Path(tmp) / f"r{i}"
            replay(args.bag, profile, out)
            _, metrics = evaluate_run(out, plots=False, skip_s=args.skip)
            sigma = np.degrees(filter_sigma(out / "bag", args.skip))
            print(f"| {label} | {metrics['roll_rms_deg']:.3f} | {metrics['pitch_rms_deg']:.3f} "
                  f"| {metrics['heading_rms_deg']:.3f} | {sigma[0]:.3f} | {sigma[1]:.3f} "
                  f"| {sigma[2]:.3f} |", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
