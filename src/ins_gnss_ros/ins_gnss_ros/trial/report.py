"""``trial evaluate``: the accuracy of a replay against the truth of its bag, as tables, plots and
a Markdown report.

The estimate is ``ins/state`` of the replay's output bag (position, ENU velocity, attitude); when
the filter also published ``nav/odom``, its covariances are attached to the estimate so that the
evaluation gives NEES and sigma bounds: the pose covariance (x, y, z in the ENU ``map`` frame,
rotations about its fixed axes = the ENU rotation vector) and the twist covariance (base_link,
REP-147 child frame) rotated into ENU, C P C^T. Truth is ``truth/state`` of the input bag (named
in ``OUT/replay.json``, or given). Components the truth lacks (NaN, e.g. attitude of an RTK-only
truth) are not evaluated. The statistics themselves are :mod:`ins_gnss_ros.trial.evaluate`'s.
"""
from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from ins_gnss_ros import io as bagio
from ins_gnss_ros.nav.lever_arm import lever_arm_position
from ins_gnss_ros.nav.rotations import quat_normalize, quat_to_dcm
from ins_gnss_ros.trial.evaluate import Trajectory, _subset, evaluate, markdown_table
from ins_gnss_ros.trial.inputs import iter_topic

#: Output-bag topics.
STATE_TOPIC, ODOM_TOPIC, TRUTH_TOPIC = "/ins/state", "/nav/odom", "/truth/state"


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


#: Farthest an estimate epoch may lie from a nav/odom message and still be given its
#: covariance, s (five periods of the ekf's default 10 Hz output).
MAX_COVARIANCE_GAP_S = 0.5


def attach_odometry_covariance(estimate: Trajectory, messages, t0_ns: int) -> Trajectory:
    """``estimate`` with position, velocity and attitude covariances from nav/Odometry messages,
    interpolated linearly to its epochs. Epochs in a gap of the output longer than
    MAX_COVARIANCE_GAP_S, before the first message or after the last get NaN: their
    covariance is unknown, and holding or interpolating the covariances around it would judge
    a state no filter vouched for (the strapdown's start-up state before the first correction,
    its states out of step with the filter) against them (a drive with a lossy IMU link: the
    covariance from before a GNSS outage given to states at its end, position NEES 478)."""
    if not messages or estimate.q_nb is None:
        return estimate
    t = np.array([(bagio.msg_stamp_ns(m.msg) - t0_ns) * 1e-9 for m in messages])
    pose = np.array([np.reshape(m.msg.pose.covariance, (6, 6)) for m in messages])
    twist = np.array([np.reshape(m.msg.twist.covariance, (6, 6)) for m in messages])
    order = np.argsort(t, kind="stable")
    t, pose, twist = t[order], pose[order], twist[order]
    right = np.clip(np.searchsorted(t, estimate.time), 0, len(t) - 1)
    left = np.clip(right - 1, 0, len(t) - 1)
    in_gap = (t[right] - t[left] > MAX_COVARIANCE_GAP_S) & (t[right] != estimate.time)
    unknown = in_gap | (estimate.time < t[0]) | (estimate.time > t[-1])

    def at_estimate(cov):
        flat = cov.reshape(len(t), -1)
        out = np.column_stack([np.interp(estimate.time, t, c) for c in flat.T])
        out[unknown] = np.nan
        return out.reshape(-1, 3, 3)

    c_nb = quat_to_dcm(estimate.q_nb)
    vel_body = at_estimate(twist[:, :3, :3])
    return Trajectory(time=estimate.time, lat=estimate.lat, lon=estimate.lon,
                      height=estimate.height, vel_enu=estimate.vel_enu, q_nb=estimate.q_nb,
                      pos_cov_enu=at_estimate(pose[:, :3, :3]),
                      vel_cov_enu=c_nb @ vel_body @ np.swapaxes(c_nb, 1, 2),
                      att_cov=at_estimate(pose[:, 3:, 3:]))


def load_run(out, truth_bag=None, state_topic=STATE_TOPIC):
    """Estimate, truth and outage windows of a replay output folder.

    ``state_topic``: the estimate's InsState topic (a smoothed run's ``/point/state``: then
    without covariances, nav/odom being of base_link).

    Returns
    -------
    estimate, truth : Trajectory
        Times in s after the first truth epoch.
    windows : ndarray, shape (k, 2)
        Outage windows on the same time scale.
    summary : dict
        ``replay.json`` (empty if absent).
    """
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
    outputs = bagio.read_bag(output_bag, [state_topic] + [ODOM_TOPIC] * (
        state_topic == STATE_TOPIC))
    states = [m for m in outputs if m.topic == state_topic]
    # A strapdown state no filter has corrected yet (sequence 0) is its start-up parameters,
    # not a solution: left out when a filter ran (a strapdown-only run keeps them all).
    corrected = [m for m in states if m.msg.correction_sequence > 0]
    estimate = trajectory_from_states(corrected or states, t0_ns)
    if estimate is None or truth is None:
        raise ValueError(f"{output_bag}: no {state_topic} with finite positions to evaluate")
    estimate = attach_odometry_covariance(
        estimate, [m for m in outputs if m.topic == ODOM_TOPIC], t0_ns)
    # A satellite window (trial replay --satellites) is evaluated like an outage: the drift
    # within it is what the reduced constellation lets through.
    windows_ns = np.concatenate([np.asarray(summary.get(key, []), dtype=np.int64).reshape(-1, 2)
                                 for key in ("outage_windows_ns", "satellite_windows_ns")])
    windows_ns = windows_ns[np.argsort(windows_ns[:, 0])]
    return estimate, truth, (windows_ns - t0_ns) * 1e-9, summary


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
    estimate, truth, windows, summary = load_run(
        out, truth_bag, "/point/state" if recorded else STATE_TOPIC)
    estimate, truth = referred_to_truth(estimate, truth, truth_point, truth_velocity_delay)
    if point is not None:
        estimate, truth = at_point(estimate, truth, point, recorded)
    keep = truth.time >= estimate.time[0] + skip_s
    if not keep.any():
        raise ValueError(f"no truth epoch after the first {skip_s:g} s of the estimate")
    truth = _subset(truth, keep)
    evaluation = evaluate(estimate, truth, windows if len(windows) else None,
                          remove_offset=remove_offset)
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
