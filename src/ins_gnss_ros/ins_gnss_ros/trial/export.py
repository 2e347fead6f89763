"""``trial export``: the solutions of a run folder as CSV, KML and RTKLIB .pos files.

Solutions of ``OUT/bag`` (a replay, an offline replay or a smoothed run): ``ins/state`` (the
filter-corrected states) with the covariances of ``nav/odom`` interpolated to them
(attach_odometry_covariance); a smoothed run also has ``forward`` (``forward/ins/state``)
and, with ``--point``, ``point`` and ``forward_point`` (``point/state``: IMU rate, no
covariance). Each goes to ``OUT/export/<solution>.<format>``:

``csv``
    One header line of column names after ``#`` comment lines that document them: time
    (POSIX UTC s; GPS week and time of week), geodetic position (deg, deg, ellipsoidal m, 1e-10
    deg and 0.1 mm resolution), ENU velocity (m/s), ROS roll/pitch/yaw of q_nb (ENU, FLU, deg)
    and the azimuth (deg clockwise from true north), standard deviations of the ENU position
    and velocity and of the attitude error about the E, N, U axes (empty where unknown), and the
    filter mode.
``kml``
    One Placemark with a LineString (KML 2.2, OGC 07-147r2: "lon,lat,height" tuples) for Google
    Earth, clamped to the ground: KML heights are above the geoid, the solution's ellipsoidal
    (the tuples keep them).
``pos``
    RTKLIB's solution format (RTKLIB manual, appendix B "Solution file format", the llh form
    with velocities that RTKLIB 2.4.3 writes): ``%`` header lines, then per epoch GPST date and
    time, latitude, longitude (deg), ellipsoidal height (m), Q, ns, sdn, sde, sdu, sdne, sdeu,
    sdun (m), age (s), ratio, vn, ve, vu (m/s), sdvn, sdve, sdvu, sdvne, sdveu, sdvun, which
    rtkplot opens. Q is 5 (single) for the filter's NAVIGATING epochs and 0 otherwise (RTKLIB has
    no INS class); ns is 0; standard deviations are signed square roots of the covariances as
    RTKLIB writes them.
"""
from __future__ import annotations

import datetime as _dt
import json
from pathlib import Path

import numpy as np

from ins_gnss_ros import io as bagio
from ins_gnss_ros.nav.rotations import quat_to_dcm
from ins_gnss_ros.trial.evaluate import PUBLISHED_MAX_GAP_S, Trajectory

#: Export formats.
FORMATS = ("csv", "kml", "pos")

#: Solutions by name: (state topic, odometry topic or None).
SOLUTIONS = {"solution": ("/ins/state", "/nav/odom"),
             "forward": ("/forward/ins/state", "/forward/nav/odom"),
             "point": ("/point/state", None),
             "forward_point": ("/forward/point/state", None)}

#: Names of the solutions of a smoothed run (trial/smooth.py) whose topics are a replay's.
SMOOTHED_NAMES = {"solution": "smoothed", "point": "smoothed_point"}

#: The CSV columns, with their meaning (written as the file's comment header).
CSV_COLUMNS = (
    ("time_s", "POSIX time (UTC), s"), ("gps_week", "GPS week"),
    ("gps_tow_s", "GPS time of week, s"), ("lat_deg", "latitude WGS-84, deg"),
    ("lon_deg", "longitude, deg"), ("height_m", "ellipsoidal height, m"),
    ("vel_e_mps", "velocity east, m/s"), ("vel_n_mps", "velocity north, m/s"),
    ("vel_u_mps", "velocity up, m/s"), ("roll_deg", "roll (ROS, FLU in ENU), deg"),
    ("pitch_deg", "pitch (ROS: nose down positive), deg"),
    ("yaw_deg", "yaw (ROS: counter-clockwise from east), deg"),
    ("heading_deg", "azimuth, clockwise from true north, deg"),
    ("sigma_e_m", "position sigma east, m"), ("sigma_n_m", "position sigma north, m"),
    ("sigma_u_m", "position sigma up, m"), ("sigma_ve_mps", "velocity sigma east, m/s"),
    ("sigma_vn_mps", "velocity sigma north, m/s"), ("sigma_vu_mps", "velocity sigma up, m/s"),
    ("sigma_att_e_deg", "attitude error sigma about east, deg"),
    ("sigma_att_n_deg", "attitude error sigma about north, deg"),
    ("sigma_att_u_deg", "attitude error sigma about up (heading), deg"),
    ("mode", "filter mode: 0 aligning, 1 navigating, 2 dead reckoning"))


def check_formats(formats) -> tuple:
    """The formats asked for (``"csv,kml"`` or an iterable), checked against FORMATS."""
    if isinstance(formats, str):
        formats = [f for f in formats.split(",") if f]
    formats = tuple(formats or ())
    unknown = [f for f in formats if f not in FORMATS]
    if unknown:
        raise ValueError(f"unknown export format {', '.join(unknown)}; known: "
                         f"{', '.join(FORMATS)}")
    return formats


def export_run(out, formats=FORMATS) -> list:
    """Write every solution of the run folder `out` in every format; returns the paths."""
    formats = check_formats(formats)
    out = Path(out)
    bag = out / "bag" if (out / "bag").is_dir() else out
    topics = {bagio.resolve(t) for t in bagio.bag_topics(bag)}
    smoothed = _mode(out) == "smooth"
    paths = []
    for name, (state_topic, odom_topic) in SOLUTIONS.items():
        if state_topic not in topics:
            continue
        solution = load_solution(bag, state_topic, odom_topic if odom_topic in topics else None)
        if solution is None:
            continue
        stem = SMOOTHED_NAMES.get(name, name) if smoothed else name
        folder = out / "export"
        folder.mkdir(exist_ok=True)
        for fmt in formats:
            path = folder / f"{stem}.{fmt}"
            WRITERS[fmt](path, solution, f"{stem} of {out.resolve()}")
            paths.append(path)
    if not paths:
        raise ValueError(f"{bag}: no {', '.join(s for s, _ in SOLUTIONS.values())} to export")
    return paths


def _mode(out) -> str | None:
    try:
        return json.loads((out / "replay.json").read_text()).get("mode")
    except (OSError, ValueError, AttributeError):
        return None


def attach_odometry_covariance(estimate: Trajectory, messages, t0_ns: int) -> Trajectory:
    """``estimate`` with position, velocity and attitude covariances from nav/Odometry messages,
    interpolated linearly to its epochs. Epochs in a gap of the output longer than
    PUBLISHED_MAX_GAP_S, before the first message or after the last get NaN: their
    covariance is unknown, and holding or interpolating the covariances around it would give
    them to states no filter vouched for (the strapdown's start-up state before the first
    correction, its states out of step with the filter)."""
    if not messages or estimate.q_nb is None:
        return estimate
    t = np.array([(bagio.msg_stamp_ns(m.msg) - t0_ns) * 1e-9 for m in messages])
    pose = np.array([np.reshape(m.msg.pose.covariance, (6, 6)) for m in messages])
    twist = np.array([np.reshape(m.msg.twist.covariance, (6, 6)) for m in messages])
    order = np.argsort(t, kind="stable")
    t, pose, twist = t[order], pose[order], twist[order]
    right = np.clip(np.searchsorted(t, estimate.time), 0, len(t) - 1)
    left = np.clip(right - 1, 0, len(t) - 1)
    in_gap = (t[right] - t[left] > PUBLISHED_MAX_GAP_S) & (t[right] != estimate.time)
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


def load_solution(bag, state_topic, odom_topic=None):
    """(Trajectory with POSIX times and covariances where known, mode per epoch) of the
    corrected states of a topic; None when there are none."""
    from ins_gnss_ros.trial.report import trajectory_from_states

    messages = bagio.read_bag(bag, [state_topic] + ([odom_topic] if odom_topic else []))
    states = [m for m in messages if m.topic == state_topic]
    states = [m for m in states if m.msg.correction_sequence > 0] or states
    trajectory = trajectory_from_states(states, 0)
    if trajectory is None:
        return None
    if odom_topic:
        trajectory = attach_odometry_covariance(
            trajectory, [m for m in messages if m.topic == odom_topic], 0)
    # The trajectory's float POSIX times are within a microsecond of their stamps.
    modes = dict(sorted((bagio.msg_stamp_ns(m.msg), m.msg.mode) for m in states))
    stamps = np.fromiter(modes, np.int64, len(modes))
    k = np.clip(np.searchsorted(stamps, trajectory.time * 1e9 - 1e4), 0, len(stamps) - 1)
    return trajectory, np.array(list(modes.values()))[k]


def _sigmas(cov, n):
    """Square roots of the diagonal of (n, 3, 3) covariances, NaN where unknown."""
    if cov is None:
        return np.full((n, 3), np.nan)
    return np.sqrt(np.diagonal(cov, axis1=1, axis2=2))


def _gps_time(t_posix):
    """(GPST calendar time to the millisecond, week, time of week) of POSIX times (UTC)."""
    from ins_gnss_ros.gnss.time import GPS_EPOCH, GPS_EPOCH_POSIX, leap_seconds, week_tow

    out = []
    for t in t_posix:
        utc = _dt.datetime(1970, 1, 1) + _dt.timedelta(seconds=float(t))
        t_gps = float(t) - GPS_EPOCH_POSIX + leap_seconds(utc)
        out.append((GPS_EPOCH + _dt.timedelta(milliseconds=round(t_gps * 1e3)),
                    *week_tow(t_gps)))
    return out


def write_csv(path, solution, title):
    from ins_gnss_ros.nav.conventions import azimuth_from_yaw
    from ins_gnss_ros.nav.rotations import quat_to_euler

    tr, mode = solution
    n = len(tr.time)
    rpy = np.column_stack(quat_to_euler(tr.q_nb))
    heading = np.degrees(np.mod(azimuth_from_yaw(rpy[:, 2]), 2 * np.pi))
    v = tr.vel_enu if tr.vel_enu is not None else np.full((n, 3), np.nan)
    sig = [_sigmas(tr.pos_cov_enu, n), _sigmas(tr.vel_cov_enu, n),
           np.degrees(_sigmas(tr.att_cov, n))]
    with open(path, "w") as f:
        f.write(f"# {title}: ins_gnss_ros trial export\n")
        f.writelines(f"# {name}: {meaning}\n" for name, meaning in CSV_COLUMNS)
        f.write(",".join(name for name, _ in CSV_COLUMNS) + "\n")
        for k, (_, week, tow) in enumerate(_gps_time(tr.time)):
            s = [f"{x:.6f}" if np.isfinite(x) else "" for x in np.concatenate(
                [sig[0][k], sig[1][k], sig[2][k]])]
            f.write(f"{tr.time[k]:.6f},{week},{tow:.6f},{np.degrees(tr.lat[k]):.10f},"
                    f"{np.degrees(tr.lon[k]):.10f},{tr.height[k]:.4f},"
                    f"{v[k, 0]:.4f},{v[k, 1]:.4f},{v[k, 2]:.4f},"
                    + ",".join(f"{np.degrees(a):.6f}" for a in rpy[k]) + f",{heading[k]:.6f},"
                    + ",".join(s) + f",{mode[k]}\n")


def write_kml(path, solution, title):
    from xml.sax.saxutils import escape

    tr, _ = solution
    coordinates = "\n".join(f"{np.degrees(lo):.10f},{np.degrees(la):.10f},{h:.4f}"
                            for la, lo, h in zip(tr.lat, tr.lon, tr.height))
    path.write_text(
        '<?xml version="1.0" encoding="UTF-8"?>\n'
        '<kml xmlns="http://www.opengis.net/kml/2.2">\n<Document>\n'
        f"<name>{escape(title)}</name>\n"
        '<Style id="track"><LineStyle><color>ff00ffff</color><width>2</width></LineStyle>'
        "</Style>\n<Placemark>\n"
        f"<name>{escape(path.stem)}</name>\n<styleUrl>#track</styleUrl>\n"
        "<LineString>\n<tessellate>1</tessellate>\n<altitudeMode>clampToGround</altitudeMode>\n"
        f"<coordinates>\n{coordinates}\n</coordinates>\n"
        "</LineString>\n</Placemark>\n</Document>\n</kml>\n")


def write_pos(path, solution, title):
    tr, mode = solution
    n = len(tr.time)
    # RTKLIB's order: n, e, u and the cross terms ne, eu, un; ENU covariances index e=0, n=1.
    order = ((1, 1), (0, 0), (2, 2), (1, 0), (0, 2), (2, 1))

    def signed_roots(cov):
        if cov is None:
            return np.zeros((n, 6))
        c = np.stack([cov[:, i, j] for i, j in order], -1)
        c = np.nan_to_num(c)
        return np.sign(c) * np.sqrt(np.abs(c))

    sp, sv = signed_roots(tr.pos_cov_enu), signed_roots(tr.vel_cov_enu)
    v = tr.vel_enu if tr.vel_enu is not None else np.zeros((n, 3))
    with open(path, "w") as f:
        f.write(f"% program   : ins_gnss_ros trial export ({title})\n")
        f.write("% (lat/lon/height=WGS84/ellipsoidal,Q=1:fix,2:float,3:sbas,4:dgps,5:single,"
                "6:ppp,ns=# of satellites)\n")
        f.write("%  GPST                  latitude(deg) longitude(deg)  height(m)   Q  ns"
                "   sdn(m)   sde(m)   sdu(m)  sdne(m)  sdeu(m)  sdun(m) age(s)  ratio"
                "    vn(m/s)    ve(m/s)    vu(m/s)      sdvn     sdve     sdvu    sdvne"
                "    sdveu    sdvun\n")
        for k, (gpst, _, _) in enumerate(_gps_time(tr.time)):
            q = 5 if mode[k] == 1 else 0
            f.write(f"{gpst:%Y/%m/%d %H:%M:%S}.{gpst.microsecond // 1000:03d} "
                    f"{np.degrees(tr.lat[k]):14.10f} {np.degrees(tr.lon[k]):15.10f} "
                    f"{tr.height[k]:10.4f} {q:3d} {0:3d} "
                    + " ".join(f"{x:8.4f}" for x in sp[k]) + f" {0.0:6.2f} {0.0:6.1f} "
                    + f"{v[k, 1]:10.5f} {v[k, 0]:10.5f} {v[k, 2]:10.5f} "
                    + " ".join(f"{x:8.5f}" for x in sv[k]) + "\n")


WRITERS = {"csv": write_csv, "kml": write_kml, "pos": write_pos}
