"""``trial evaluate``: the accuracy of a replay against the truth of its bag, as tables, plots and
a Markdown report.

The estimate is ``ins/state`` of the replay's output bag (position, ENU velocity, attitude); when
the filter also published ``nav/odom``, the NEES and sigma bounds are of the solution it
published with its covariances (:func:`published_solution`): the position of ``nav/fix``, the
attitude and velocity of the ``nav/odom`` of the same stamp, its pose covariance (x, y, z in the
ENU ``map`` frame, rotations about its fixed axes = the ENU rotation vector) and its twist
covariance (base_link, REP-147 child frame) rotated into ENU, C P C^T. Truth is ``truth/state``
of the input bag (named in ``OUT/replay.json``, or given). Components the truth lacks (NaN, e.g.
attitude of an RTK-only truth) are not evaluated. The statistics themselves are
:mod:`ins_gnss_ros.trial.evaluate`'s.
"""
from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ins_gnss_ros import io as bagio
from ins_gnss_ros.nav.lever_arm import lever_arm_position
from ins_gnss_ros.nav.rotations import quat_normalize, quat_to_dcm
from ins_gnss_ros.trial.evaluate import Trajectory, _subset, evaluate, markdown_table
from ins_gnss_ros.trial.inputs import iter_topic

#: Output-bag topics.
STATE_TOPIC, ODOM_TOPIC, FIX_TOPIC, TRUTH_TOPIC = \
    "/ins/state", "/nav/odom", "/nav/fix", "/truth/state"


def trajectory_from_states(messages, t0_ns: int) -> Trajectory | None:
    """Trajectory of InsState messages (times in s after ``t0_ns``); NaN-only velocity or
    attitude become None, duplicate stamps keep the last message. None for no messages."""
    rows = {}
    for m in messages:
        msg = m.msg
        rows[bagio.msg_stamp_ns(msg)] = (msg.latitude, msg.longitude, msg.altitude,
                                     msg.velocity.x, msg.velocity.y, msg.velocity.z,
                                     msg.orientation.w, msg.orientation.x, msg.orientation.y,
                                     msg.orientation.z)
    if not rows:
        return None
    stamps = np.array(sorted(rows), np.int64)
    a = np.array([rows[s] for s in stamps], float)
    ok = np.all(np.isfinite(a[:, :3]), axis=1)
    a, stamps = a[ok], stamps[ok]
    if len(a) == 0:
        return None
    vel = a[:, 3:6] if np.all(np.isfinite(a[:, 3:6])) else None
    q = quat_normalize(a[:, 6:10]) if np.all(np.isfinite(a[:, 6:10])) else None
    return Trajectory(time=(stamps - t0_ns) * 1e-9, lat=a[:, 0], lon=a[:, 1], height=a[:, 2],
                      vel_enu=vel, q_nb=q)


def published_solution(messages, t0_ns: int) -> Trajectory | None:
    """The solution the ekf published with its covariances (times in s after ``t0_ns``): at
    each ``nav/odom`` with a ``nav/fix`` of the same stamp (both of base_link, published
    together), the fix's position, the odometry's attitude and velocity (the twist turned into
    ENU) and covariances. None without both."""
    fixes = {bagio.msg_stamp_ns(m.msg): m.msg for m in messages if m.topic == FIX_TOPIC}
    odom = sorted((bagio.msg_stamp_ns(m.msg), m.msg) for m in messages
                  if m.topic == ODOM_TOPIC and bagio.msg_stamp_ns(m.msg) in fixes)
    if len(odom) < 2:
        return None
    stamps = np.array([stamp for stamp, _ in odom], np.int64)
    fix = [fixes[stamp] for stamp in stamps.tolist()]
    pose = np.array([np.reshape(msg.pose.covariance, (6, 6)) for _, msg in odom])
    twist = np.array([np.reshape(msg.twist.covariance, (6, 6)) for _, msg in odom])
    q_nb = quat_normalize(np.array([(o.w, o.x, o.y, o.z) for o in
                                    (msg.pose.pose.orientation for _, msg in odom)]))
    v_body = np.array([(v.x, v.y, v.z) for v in (msg.twist.twist.linear for _, msg in odom)])
    c_nb = quat_to_dcm(q_nb)
    return Trajectory(time=(stamps - t0_ns) * 1e-9,
                      lat=np.radians([f.latitude for f in fix]),
                      lon=np.radians([f.longitude for f in fix]),
                      height=np.array([f.altitude for f in fix]),
                      vel_enu=np.einsum("nij,nj->ni", c_nb, v_body), q_nb=q_nb,
                      pos_cov_enu=pose[:, :3, :3], att_cov=pose[:, 3:, 3:],
                      vel_cov_enu=c_nb @ twist[:, :3, :3] @ np.swapaxes(c_nb, 1, 2))


@dataclass(frozen=True)
class Run:
    """What a replay output folder is evaluated on (:func:`load_run`).

    Attributes
    ----------
    estimate, truth : Trajectory
        Times in s after the first truth epoch; the estimate without covariances.
    published : Trajectory or None
        The solution the ekf published with its covariances (:func:`published_solution`), on
        the same time scale; None without nav/odom (or for a smoothed run's ``/point/state``,
        nav/odom being of base_link).
    windows : ndarray, shape (k, 2)
        Outage windows on the same time scale.
    summary : dict
        ``replay.json`` (empty if absent).
    """

    estimate: Trajectory
    published: Trajectory | None
    truth: Trajectory
    windows: np.ndarray
    summary: dict


def load_run(out, truth_bag=None, state_topic=STATE_TOPIC) -> Run:
    """The estimate (``state_topic``, InsState: a smoothed run's ``/point/state`` or
    ``ins/state``), the published solution, truth and outage windows of a replay output
    folder."""
    out = Path(out)
    summary_path = out / "replay.json"
    summary = {}
    if summary_path.is_file():
        try:
            summary = json.loads(summary_path.read_text())
        except json.JSONDecodeError as err:
            raise ValueError(f"{summary_path}: malformed JSON ({err.msg})") from None
        if not isinstance(summary, dict):
            raise ValueError(f"{summary_path}: expected a JSON object")
    output_bag = out / "bag" if (out / "bag").is_dir() else out
    truth_bag = truth_bag or summary.get("input_bag")
    if truth_bag is None:
        raise ValueError(f"{out}: no replay.json naming the input bag: give --truth BAG")
    truth_msgs = list(iter_topic(truth_bag, TRUTH_TOPIC))
    if not truth_msgs:
        raise ValueError(f"{truth_bag}: no {TRUTH_TOPIC} messages to evaluate against")
    t0_ns = truth_msgs[0].t_ns
    truth = trajectory_from_states(truth_msgs, t0_ns)
    outputs = bagio.read_bag(output_bag, [state_topic] + [ODOM_TOPIC, FIX_TOPIC] * (
        state_topic == STATE_TOPIC))
    states = [m for m in outputs if m.topic == state_topic]
    # A strapdown state no filter has corrected yet (sequence 0) is its start-up parameters,
    # not a solution: left out when a filter ran (a strapdown-only run keeps them all).
    corrected = [m for m in states if m.msg.correction_sequence > 0]
    estimate = trajectory_from_states(corrected or states, t0_ns)
    if estimate is None or truth is None:
        raise ValueError(f"{output_bag}: no {state_topic} with finite positions to evaluate")
    # A satellite window (trial replay --satellites) is evaluated like an outage: the drift
    # within it is what the reduced constellation lets through.
    windows_ns = np.concatenate([np.asarray(summary.get(key, []), dtype=np.int64).reshape(-1, 2)
                                 for key in ("outage_windows_ns", "satellite_windows_ns")])
    windows_ns = windows_ns[np.argsort(windows_ns[:, 0])]
    return Run(estimate, published_solution(outputs, t0_ns), truth,
               (windows_ns - t0_ns) * 1e-9, summary)


def referred_to_truth(estimate: Trajectory, truth: Trajectory, truth_point=None,
                      truth_velocity_delay: float = 0.0) -> tuple[Trajectory, Trajectory]:
    """The estimate and the truth referred to the same point and time.

    Parameters
    ----------
    truth_point : (3,) array_like, optional
        The point of the body the truth positions refer to, base_link FLU, m (e.g. the GNSS
        antenna of an RTK truth): the estimate (base_link) is moved there with its own attitude.
    truth_velocity_delay : float
        Latency of the truth velocities, s: a truth velocity stamped t is the velocity of
        t - delay (RTKLIB's velocities of the car drive lag its positions by 0.125 s), so the
        truth velocities are taken at t + delay.
    """
    if truth_point is not None:
        if estimate.q_nb is None:
            raise ValueError("a truth point needs the estimate's attitude")
        lat, lon, h = lever_arm_position(estimate.lat, estimate.lon, estimate.height,
                                         estimate.q_nb, np.asarray(truth_point, float))
        estimate = Trajectory(**{**vars(estimate), "lat": lat, "lon": lon, "height": h})
    if truth_velocity_delay and truth.vel_enu is not None:
        vel = np.column_stack([np.interp(truth.time + truth_velocity_delay, truth.time, v,
                                         left=np.nan, right=np.nan) for v in truth.vel_enu.T])
        truth = Trajectory(**{**vars(truth), "vel_enu": vel})
    return estimate, truth


def evaluate_run(out, truth_bag=None, plots=True, skip_s=0.0, truth_point=None,
                 truth_velocity_delay=0.0, remove_offset=False, point=None, apertures=()):
    """Evaluate a replay output folder; write ``report.md`` (and PNG plots) into it.

    Parameters
    ----------
    out : path
        Replay output folder.
    truth_bag : path, optional
        Bag with ``truth/state`` (default: the replay's input bag).
    plots : bool
        Write the PNG plots.
    skip_s : float
        Leave the first ``skip_s`` seconds of the estimate (initial alignment and convergence)
        out of the statistics; the report says so.
    truth_point, truth_velocity_delay
        Where and when the truth refers to (:func:`referred_to_truth`); the report says so.
    remove_offset : bool
        Take the truth's constant position offset (the mean error) out of the statistics
        (:func:`~ins_gnss_ros.trial.evaluate.evaluate`); the report gives it.
    point : (3,) array_like, optional
        Evaluate the trajectory of this body point (base_link FLU, m) instead (:func:`at_point`).
    apertures : iterable of float
        Also the relative position error over windows of these lengths, s (aperture.py);
        in the metrics as ``aperture``.

    Returns
    -------
    evaluation : Evaluation
    metrics : dict
        The ``--json`` object (:meth:`Evaluation.to_json` plus ``report``).
    """
    from ins_gnss_ros.trial.plots import write_plots

    out = Path(out)
    if not skip_s >= 0.0:
        raise ValueError(f"--skip must be >= 0 s, got {skip_s}")
    if point is not None and truth_point is not None:
        raise ValueError("give a truth point or an evaluation point, not both")
    recorded = point is not None and _recorded_point(out) == list(np.asarray(point, float))
    run = load_run(out, truth_bag, "/point/state" if recorded else STATE_TOPIC)
    windows, summary, published = run.windows, run.summary, run.published
    estimate, truth = referred_to_truth(run.estimate, run.truth, truth_point,
                                        truth_velocity_delay)
    if published is not None and truth_point is not None:
        published = referred_to_truth(published, truth, truth_point)[0]
    if point is not None:
        estimate, truth = at_point(estimate, truth, point, recorded)
        published = None  # its covariances are base_link's
    keep = truth.time >= estimate.time[0] + skip_s
    if not keep.any():
        raise ValueError(f"no truth epoch after the first {skip_s:g} s of the estimate")
    truth = _subset(truth, keep)
    evaluation = evaluate(estimate, truth, windows if len(windows) else None,
                          remove_offset=remove_offset, published=published)
    images = write_plots(evaluation, estimate, truth, out / "plots",
                         windows if len(windows) else None) if plots else []
    report = out / "report.md"
    referred = {"truth point (FLU, m)": None if truth_point is None else list(truth_point),
                "truth velocity delay (s)": truth_velocity_delay or None,
                "removed truth offset ENU (m)": None if evaluation.offset_enu is None
                else [round(float(x), 3) for x in evaluation.offset_enu]}
    from ins_gnss_ros.trial import aperture

    relative = [aperture.aperture_error(evaluation.errors.time, evaluation.errors.pos_enu, w)
                for w in apertures]
    referred["evaluated point (FLU, m)"] = None if point is None else list(point)
    text = markdown_report(evaluation, summary, truth_bag, images, out, skip_s, referred)
    if relative:
        text += "\n" + "\n".join(aperture.markdown_lines(relative)) + "\n"
    report.write_text(text)
    metrics = evaluation.to_json()
    if relative:
        metrics["aperture"] = [vars(a) for a in relative]
    metrics["report"] = str(report)
    return evaluation, metrics


def _recorded_point(out):
    """The ``--point`` of a smoothed run folder (``smooth.json``), or None."""
    try:
        return json.loads((Path(out) / "smooth.json").read_text()).get("point_m")
    except (OSError, ValueError, AttributeError):
        return None


def at_point(estimate: Trajectory, truth: Trajectory, point, recorded=False):
    """Estimate and truth at a body point (base_link FLU, m), each moved with its own attitude;
    ``recorded``: the estimate is already there (a smoothed run's ``point/state``). Velocities
    are left out (the truth lacks the body rates that move them) and so are the covariances
    (those of nav/odom are base_link's)."""
    if truth.q_nb is None or (estimate.q_nb is None and not recorded):
        raise ValueError("an evaluation point needs the attitudes of the truth and the estimate")
    point = np.asarray(point, float)

    def moved(tr, move):
        lat, lon, h = (lever_arm_position(tr.lat, tr.lon, tr.height, tr.q_nb, point) if move
                       else (tr.lat, tr.lon, tr.height))
        return Trajectory(time=tr.time, lat=lat, lon=lon, height=h, q_nb=tr.q_nb)

    return moved(estimate, not recorded), moved(truth, True)


def markdown_report(evaluation, summary, truth_bag, images, out, skip_s=0.0,
                    referred=None) -> str:
    """The report: what ran on what, the error tables, the plots."""
    lines = ["# Trial evaluation", ""]
    facts = [("input bag", summary.get("input_bag")), ("truth", truth_bag or
                                                        summary.get("input_bag")),
             ("profile", summary.get("profile")), ("graph", ", ".join(summary.get("graph", []))),
             ("replay", summary.get("mode")), ("outages", summary.get("outages")),
             ("not evaluated (alignment, convergence)", f"first {skip_s:g} s" if skip_s else None)]
    facts += list((referred or {}).items())
    lines += [f"- {name}: `{value}`" for name, value in facts if value]
    lines += ["", markdown_table(evaluation), ""]
    lines += [f"![{p.stem}]({p.relative_to(out)})" for p in images]
    return "\n".join(lines) + "\n"
