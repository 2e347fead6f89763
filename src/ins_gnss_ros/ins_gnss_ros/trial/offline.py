"""``trial replay --offline``: the offline filter path, no ROS graph.

The :class:`~ins_gnss_ros.nav.navigator.Navigator` (the ``ekf`` node's filter code without ROS)
runs over the bag, configured by the profile's ``navigator`` section (:data:`OFFLINE_PARAMS`);
it writes ``ins/state`` and ``nav/odom`` (with the filter's covariances) like the graph would.
Deterministic like :func:`ins_gnss_ros.trial.replay.replay`.
"""
from __future__ import annotations

from collections import Counter

import numpy as np

from ins_gnss_ros import io as bagio
from ins_gnss_ros.trial.inputs import check_inputs, input_rows
from ins_gnss_ros.trial.outages import GNSS_PREFIX, gnss_windows, in_outage
from ins_gnss_ros.trial.profile import Profile, ProfileError, load_profile
from ins_gnss_ros.trial.run_folder import MessageCounts, new_run_folder, write_summary


#: Parameters of the profile's ``navigator`` section (offline path) and their defaults.
OFFLINE_PARAMS = {
    "imu_grade": "tactical",        # nav.sensor_errors.GRADES key: the filter's IMU noise model
    "bias_model": "rw",             # "rw" (one random-walk bias state) or "gm" (exact model)
    "layout": "15",                 # nav.error_model.LAYOUTS key
    "lever_arm": [0.0, 0.0, 0.0],   # GNSS antenna relative to the IMU, base_link FLU, m
    "mounting_rpy_deg": [0.0, 0.0, 0.0],  # imu/data_raw sensor axes -> base_link (ROS Euler)
    "gnss_sigma_m": 1.0,            # fix standard deviation when the fix has no covariance, m
    "heading": True,                # use gnss/heading (Heading messages)
}


def offline_config(profile: Profile) -> dict:
    """The ``navigator`` section of a profile over :data:`OFFLINE_PARAMS` (unknown keys and
    grades are a :class:`ProfileError`)."""
    from ins_gnss_ros.nav.sensor_errors import GRADES

    section = profile.sections.get("navigator")
    if section is None:
        raise ProfileError(f"{profile.path}: the offline path needs a 'navigator' section")
    unknown = sorted(set(section) - set(OFFLINE_PARAMS))
    if unknown:
        raise ProfileError(f"{profile.path}: navigator: unknown parameter(s) {', '.join(unknown)}"
                           f" (known: {', '.join(OFFLINE_PARAMS)})")
    config = dict(OFFLINE_PARAMS, **section)
    if config["imu_grade"] not in GRADES:
        raise ProfileError(f"{profile.path}: navigator: imu_grade {config['imu_grade']!r} is not"
                           f" one of {', '.join(GRADES)}")
    for key in ("lever_arm", "mounting_rpy_deg"):
        if len(config[key]) != 3:
            raise ProfileError(f"{profile.path}: navigator: {key} needs 3 values")
    return config


def replay_offline(bag_path, profile_path, out, outages=None, progress=False) -> dict:
    """Run the offline navigator over a bag and record ``ins/state`` and ``nav/odom``.

    IMU: ``imu/delta`` as is, or ``imu/data_raw`` rotated by ``mounting_rpy_deg`` into
    base_link and integrated over the stamp intervals (rate x dt, the interval-mean rates of a
    raw IMU message). Aiding: ``gnss/fix`` (its ENU covariance, or ``gnss_sigma_m``),
    ``gnss/vel`` and ``gnss/heading``; ``gnss/*`` is withheld in the outage windows.
    Deterministic like :func:`replay`.
    """
    from ins_gnss_ros.nav import navigator as navmod
    from ins_gnss_ros.nav.rotations import dcm_from_euler
    from ins_gnss_ros.nav.sensor_errors import GRADES, filter_noise

    profile = load_profile(profile_path)
    config = offline_config(profile)
    # Every input keeps its place (the time origin t0 is the first input of any topic), but
    # only what the navigator uses is decoded: the IMU topics in bulk, gnss/* one by one.
    check_inputs(bag_path, OFFLINE_IMU_TOPICS + OFFLINE_GNSS_TOPICS)
    rows = input_rows(bag_path)
    windows = gnss_windows(rows, outages)
    out = new_run_folder(out)
    nav = navmod.Navigator(navmod.NavigatorConfig(
        noise=filter_noise(GRADES[config["imu_grade"]], config["bias_model"]),
        layout=config["layout"], lever_arm_b=np.asarray(config["lever_arm"], float)))
    c_mount = dcm_from_euler(*np.radians(np.asarray(config["mounting_rpy_deg"], float)))
    t0 = rows[0].t_ns if rows else 0
    imu_at, imu_t, imu_th, imu_dv = _imu_increments(rows, t0, c_mount)
    gnss_at = [k for k, m in enumerate(rows) if m.topic.startswith(GNSS_PREFIX)]
    t_gnss = np.array([rows[k].t_ns for k in gnss_at], np.int64)
    inside = in_outage(t_gnss, windows)
    counts = MessageCounts(withheld=Counter(
        rows[k].topic for k, held in zip(gnss_at, inside) if held))
    counts.played = Counter(m.topic for m in rows) - counts.withheld
    used = [k for k, out_of_window in zip(gnss_at, ~inside)
            if out_of_window and rows[k].topic in OFFLINE_GNSS_TOPICS]
    measurements = _gnss_measurements(rows, used, t0, config)
    done = 0

    from tqdm import tqdm

    for k, measurement in tqdm(zip(used, measurements), disable=not progress, unit="msg",
                               desc="offline", total=len(used)):
        if measurement is not None:
            # The IMU samples before it in the stream go first, in one batch.
            end = int(np.searchsorted(imu_at, k))
            if end > done:
                nav.add_imu(imu_t[done:end], imu_th[done:end], imu_dv[done:end])
                done = end
            nav.add_measurement(measurement)
    if len(imu_t) > done:
        nav.add_imu(imu_t[done:], imu_th[done:], imu_dv[done:])
    nav.flush()
    result = nav.output()
    _write_navigator_output(out / "bag", result, t0)
    counts.recorded.update({"/ins/state": len(result.t), "/nav/odom": len(result.t)})
    return write_summary(out, bag_path, profile, outages, windows, counts, "offline", 0.0,
                         graph=["navigator"])


#: IMU topics the offline path reads (increments, or raw rates it integrates itself).
OFFLINE_IMU_TOPICS = ("/imu/delta", "/imu/data_raw")
#: GNSS topics it turns into measurements (:func:`_gnss_measurements`).
OFFLINE_GNSS_TOPICS = ("/gnss/fix", "/gnss/vel", "/gnss/heading")


def _imu_increments(rows, t0, c_mount):
    """IMU increments of the offline path from the bag rows, decoded in bulk.

    ``imu/delta`` as is; ``imu/data_raw`` rotated by ``c_mount`` into base_link and integrated
    over the stamp intervals (rate x dt; a sample not later than its predecessor is dropped).

    Returns
    -------
    at : (N,) int
        Position of each sample's message in ``rows``, increasing.
    t : (N,) s after ``t0`` (ns); dtheta, dv : (N, 3) rad, m/s
    """
    from ins_gnss_ros.io import cdr

    parts = []
    for topic in OFFLINE_IMU_TOPICS:
        at = np.array([k for k, m in enumerate(rows) if m.topic == topic], np.int64)
        if not len(at):
            continue
        try:
            cols = cdr.decode_columns(rows[at[0]].msgtype, [rows[k].data for k in at])
        except cdr.CdrLayoutError as err:
            raise bagio.BagError(f"{topic}: {err}") from None
        t = (np.array([rows[k].t_ns for k in at], np.int64) - t0) * 1e-9
        if topic == "/imu/delta":
            parts.append((at, t, _vectors(cols, "delta_angle"), _vectors(cols, "delta_velocity")))
            continue
        dt = np.diff(t)
        keep = np.flatnonzero(dt > 0.0) + 1
        dt = dt[keep - 1, None]
        parts.append((at[keep], t[keep],
                      _rotate(c_mount, _vectors(cols, "angular_velocity")[keep]) * dt,
                      _rotate(c_mount, _vectors(cols, "linear_acceleration")[keep]) * dt))
    if not parts:
        return np.zeros(0, np.int64), np.zeros(0), np.zeros((0, 3)), np.zeros((0, 3))
    order = np.argsort(np.concatenate([p[0] for p in parts]), kind="stable")
    return tuple(np.concatenate([p[i] for p in parts])[order] for i in range(4))


def _rotate(c, v):
    """c @ v[k] (or c[k] @ v[k] for a stack c of (n, 3, 3)) for every row of v (n, 3), as a
    stack of matrix-vector products: bit-identical to the per-row product."""
    return np.matmul(c, v[..., None])[..., 0]


def _vectors(columns, prefix):
    """(n, 3) array of the x, y, z columns of a Vector3 field from :func:`cdr.decode_columns`."""
    return np.stack([columns[f"{prefix}.{c}"] for c in "xyz"], -1)


def _gnss_measurements(rows, at, t0, config) -> list:
    """Navigator measurements of the gnss/* rows at positions ``at`` (None where the topic is
    not used or the message not valid), decoded in bulk per topic."""
    from ins_gnss_ros.io import cdr

    out = [None] * len(at)
    for topic, convert in (("/gnss/fix", _fixes), ("/gnss/vel", _velocities),
                           ("/gnss/heading", _headings)):
        sel = [i for i, k in enumerate(at) if rows[k].topic == topic]
        if not sel or (topic == "/gnss/heading" and not config["heading"]):
            continue
        try:
            cols = cdr.decode_columns(rows[at[sel[0]]].msgtype, [rows[at[i]].data for i in sel])
        except cdr.CdrLayoutError as err:
            raise bagio.BagError(f"{topic}: {err}") from None
        t = ((np.array([rows[at[i]].t_ns for i in sel], np.int64) - t0) * 1e-9).tolist()
        for i, measurement in zip(sel, convert(cols, t, config)):
            out[i] = measurement
    return out


def _fixes(c, t, config):
    """GnssFix of NavSatFix columns: its ENU covariance diagonal, or ``gnss_sigma_m``."""
    from ins_gnss_ros.nav.navigator import GnssFix

    position = np.stack([c["latitude"], c["longitude"], c["altitude"]], -1)
    valid = (c["status.status"] >= 0) & np.all(np.isfinite(position), axis=1)
    var = c["position_covariance"][:, [0, 4, 8]]
    given = (c["position_covariance_type"] != 0) & np.all(np.isfinite(var) & (var > 0), axis=1)
    var = np.where(given[:, None], var, config["gnss_sigma_m"] ** 2)
    lat, lon = np.radians(c["latitude"]).tolist(), np.radians(c["longitude"]).tolist()
    h = c["altitude"].tolist()
    return [GnssFix(t[k], lat[k], lon[k], h[k], np.diag(var[k])) if valid[k] else None
            for k in range(len(t))]


def _velocities(c, t, config):
    """GnssVelocity of TwistWithCovarianceStamped columns (valid: finite, positive variances)."""
    from ins_gnss_ros.nav.navigator import GnssVelocity

    v = np.stack([c[f"twist.twist.linear.{x}"] for x in "xyz"], -1)
    var = c["twist.covariance"][:, [0, 7, 14]]
    valid = np.all(np.isfinite(v), axis=1) & np.all(np.isfinite(var) & (var > 0), axis=1)
    return [GnssVelocity(t[k], v[k].copy(), np.diag(var[k])) if valid[k] else None
            for k in range(len(t))]


def _headings(c, t, config):
    """HeadingFix of Heading columns (valid: finite azimuth, positive variance)."""
    from ins_gnss_ros.nav.navigator import HeadingFix

    valid = np.isfinite(c["azimuth"]) & (c["azimuth_variance"] > 0)
    azimuth, variance = c["azimuth"].tolist(), c["azimuth_variance"].tolist()
    magnetic = (c["reference"] == REFERENCE_MAGNETIC).tolist()
    return [HeadingFix(t[k], azimuth[k], variance[k], magnetic=magnetic[k]) if valid[k]
            else None for k in range(len(t))]


#: ins_gnss_msgs/Heading.REFERENCE_MAGNETIC.
REFERENCE_MAGNETIC = 1
#: Navigator mode -> InsState mode.
_MODES = {"ALIGNING": 0, "NAVIGATING": 1, "DEAD_RECKONING": 2}


def _write_navigator_output(path, result, t0):
    """ins/state and nav/odom (map = ENU at the first epoch) of a NavigatorOutput, serialised
    in bulk (:mod:`ins_gnss_ros.io.cdr`; the fields of :func:`~ins_gnss_ros.trial.contract_messages.ins_state_msg`)."""
    from ins_gnss_ros.nav.earth import ecef_to_enu, geodetic_to_ecef
    from ins_gnss_ros.nav.rotations import quat_to_dcm
    from ins_gnss_ros.io import cdr

    writer = bagio.BagWriter(path)
    n = len(result.t)
    if n == 0:
        return writer.close()
    stamps = bagio.sec_to_ns(result.t, t0)
    enu = ecef_to_enu(geodetic_to_ecef(result.lat, result.lon, result.h),
                      result.lat[0], result.lon[0], result.h[0])
    q, c_nb = result.q_nb, quat_to_dcm(result.q_nb)
    c_bn = c_nb.transpose(0, 2, 1)
    sec, nanosec = np.divmod(stamps, 1_000_000_000)
    header = {"header.stamp.sec": sec, "header.stamp.nanosec": nanosec}
    orientation = {f"orientation.{c}": q[:, i] for i, c in enumerate("wxyz")}
    unknown = np.full((n, 3), np.nan)
    state = dict(header, latitude=result.lat, longitude=result.lon, altitude=result.h,
                 mode=[_MODES.get(str(mode), 3) for mode in result.mode],
                 correction_sequence=0, **_fields("velocity", result.v_enu), **orientation,
                 **_fields("angular_velocity", unknown), **_fields("specific_force", unknown),
                 **_fields("gyro_bias", unknown), **_fields("accel_bias", unknown),
                 **_fields("gyro_scale_factor", np.zeros((n, 3))),
                 **_fields("accel_scale_factor", np.zeros((n, 3))))
    pose, twist = np.zeros((n, 6, 6)), np.zeros((n, 6, 6))
    if result.P is not None:
        space = result.space
        pose[:, :3, :3] = result.P[:, space["pos"], space["pos"]]
        pose[:, 3:, 3:] = result.P[:, space["att"], space["att"]]
        twist[:, :3, :3] = c_bn @ result.P[:, space["vel"], space["vel"]] @ c_nb
        twist[:, 3:, 3:] = -np.eye(3)  # angular rate not estimated
    odom = dict(header, **_fields("pose.pose.position", enu),
                **{"pose.pose." + k: v for k, v in orientation.items()},
                **_fields("twist.twist.linear", _rotate(c_bn, result.v_enu)),
                **_fields("twist.twist.angular", np.zeros((n, 3))),
                **{"pose.covariance": pose.reshape(n, 36),
                   "twist.covariance": twist.reshape(n, 36)})
    states = cdr.encode_columns("ins_gnss_msgs/msg/InsState", state, {"header.frame_id": "map"})
    odoms = cdr.encode_columns("nav_msgs/msg/Odometry", odom,
                       {"header.frame_id": "map", "child_frame_id": "base_link"})
    for t, state_data, odom_data in zip(stamps.tolist(), states, odoms):
        writer.write_raw("ins/state", "ins_gnss_msgs/msg/InsState", t, state_data)
        writer.write_raw("nav/odom", "nav_msgs/msg/Odometry", t, odom_data)
    return writer.close()


def _fields(prefix, xyz):
    """x, y, z columns of a Vector3/Point field for :func:`cdr.encode_columns` from (n, 3) values."""
    return {f"{prefix}.{c}": xyz[:, i] for i, c in enumerate("xyz")}
