"""The navigation solution and the filter's status as ROS messages (``nav/fix``, ``nav/odom``,
``nav/imu``, ``nav/status``, ``nav/datum``), for the ``ekf`` node and the offline replay alike.
The 10 Hz solution is packed straight into CDR payloads (:func:`~..io.cdr.field_writer`),
one epoch at a time for the node and in columns for the offline path, the same bytes."""
from __future__ import annotations

import numpy as np
from builtin_interfaces.msg import Time
from ins_gnss_msgs.msg import FilterStatus, MeasurementUpdate
from sensor_msgs.msg import NavSatFix, NavSatStatus

from ..io import NS, encode_columns, field_writer, new, sec_to_stamp
from ..nav.local_frame import to_map
from ..nav.rotations import quat_to_dcm
from ..nav.strapdown import NavState


class OutputSchedule:
    """Which of the strapdown's states (one per IMU increment, at whatever rate the IMU gives
    them) are published as the solution at ``rate_hz`` (nav/fix, nav/odom): the first state a
    period after the last one published, where a state half its own interval early counts.
    The output then comes every round(period / interval) states, as evenly as they come.

    Drivers' stamps jitter: "a whole period since the last one" skipped every other state of
    a 10 Hz IMU for a 10 Hz output (0.0999 s < 0.1 s) and stretched a 200 Hz IMU's output to
    105 ms."""

    def __init__(self, rate_hz: float):
        self.period = 1.0 / rate_hz
        self._last = -np.inf
        self._previous = None  # the stamp of the state before, s

    def due(self, t: float) -> bool:
        """Whether the state stamped t (s) is to be published; asked of every state, in the
        order they come."""
        if self._previous is not None and t < self._previous:
            self._last = -np.inf  # the strapdown restarted or the bag looped
        step = 0.0 if self._previous is None else t - self._previous
        self._previous = t
        return t - self._last >= self.period - 0.5 * step

    def published(self, t: float) -> None:
        """The state stamped t (s) was published."""
        self._last = t


def fix_status(navigating: bool, input_status: int) -> int:
    """nav/fix status (REP-145 readers take it as the solution's quality): NO_FIX unless the
    filter is NAVIGATING (aligning and dead reckoning are not fixes), else the augmentation of
    the GNSS input the filter navigates on (``input_status``: the NavSatStatus of the last
    gnss/fix it used, STATUS_FIX for pseudoranges): SBAS_FIX, GBAS_FIX (RTK fixed: the driver
    reports float as SBAS_FIX), otherwise FIX."""
    if not navigating:
        return NavSatStatus.STATUS_NO_FIX
    if input_status in (NavSatStatus.STATUS_SBAS_FIX, NavSatStatus.STATUS_GBAS_FIX):
        return input_status
    return NavSatStatus.STATUS_FIX


def fix_payload(stamp_ns: int, st: NavState, cov_pos: np.ndarray, status: int,
                service: int = 0, frame_id: str = "base_link") -> bytes:
    """nav/fix (CDR payload): the solution's position with its ENU covariance (m^2),
    NavSatStatus ``status`` (:func:`fix_status`) and ``service`` bits (the GNSS systems the
    filter uses)."""
    return field_writer("sensor_msgs/msg/NavSatFix", (frame_id,))(
        *divmod(stamp_ns, NS), status, service, float(np.degrees(st.lat)),
        float(np.degrees(st.lon)), float(st.h), *cov_pos.ravel().tolist(),
        NavSatFix.COVARIANCE_TYPE_KNOWN)


def fix_payloads(stamp_ns, lat, lon, h, cov_pos, status, frame_id: str = "base_link") -> list:
    """The CDR payloads of :func:`fix_payload` for k epochs at once (``service`` 0): stamps (ns),
    lat, lon (rad), h (m) (k,), ``cov_pos`` (k, 3, 3), ``status`` (k,) or one for all."""
    sec, nanosec = np.divmod(np.asarray(stamp_ns, np.int64), NS)
    return encode_columns("sensor_msgs/msg/NavSatFix", {
        "header.stamp.sec": sec, "header.stamp.nanosec": nanosec, "status.status": status,
        "status.service": 0, "latitude": np.degrees(lat), "longitude": np.degrees(lon),
        "altitude": h, "position_covariance": np.reshape(cov_pos, (-1, 9)),
        "position_covariance_type": NavSatFix.COVARIANCE_TYPE_KNOWN},
        {"header.frame_id": frame_id})


def datum_msg(stamp: Time, datum: tuple, frame_id: str) -> NavSatFix:
    """nav/datum: the origin of the map frame (lat rad, lon rad, h m) as a NavSatFix in it."""
    msg = new(NavSatFix)
    msg.header.stamp, msg.header.frame_id = stamp, frame_id
    msg.status.status = NavSatStatus.STATUS_FIX
    msg.latitude, msg.longitude, msg.altitude = \
        float(np.degrees(datum[0])), float(np.degrees(datum[1])), float(datum[2])
    msg.position_covariance_type = NavSatFix.COVARIANCE_TYPE_UNKNOWN
    return msg


def imu_payload(stamp_ns: int, st: NavState, P: np.ndarray, S, angular_velocity: tuple,
                specific_force: tuple, rate_variance: float, accel_variance: float,
                frame_id: str = "base_link") -> bytes:
    """nav/imu (CDR payload): sensor_msgs/Imu with the INS orientation (ENU <- base_link FLU,
    REP-103/145) and its covariance (small rotations about ENU axes from P), the compensated
    body rate and specific force (3 floats each) with the variances (rad^2/s^2, m^2/s^4) of
    one navigation-rate sample."""
    w, x, y, z = st.q_nb.tolist()
    return field_writer("sensor_msgs/msg/Imu", (frame_id,))(
        *divmod(stamp_ns, NS), x, y, z, w, *P[S["att"], S["att"]].ravel().tolist(),
        *angular_velocity, *(np.eye(3) * rate_variance).ravel().tolist(), *specific_force,
        *(np.eye(3) * accel_variance).ravel().tolist())


def odom_payload(stamp_ns: int, st: NavState, P: np.ndarray, S, datum: tuple,
                 angular_velocity: tuple, rate_variance: float,
                 frames: tuple[str, str] = ("map", "base_link")) -> bytes:
    """nav/odom (CDR payload): pose in the ENU map frame around ``datum`` (lat rad, lon rad,
    h m), twist in base_link, covariances from the filter's P (state space S); the angular
    rate (3 floats) is not a filter state: its variance (rad^2/s^2) is given. ``frames``:
    (map, base_link) names."""
    enu, linear, pose_cov, twist_cov = _odom_numbers(st.lat, st.lon, st.h, st.v_enu, st.q_nb,
                                                     P, S, datum, rate_variance)
    w, x, y, z = st.q_nb.tolist()
    return field_writer("nav_msgs/msg/Odometry", frames)(
        *divmod(stamp_ns, NS), *enu.tolist(), x, y, z, w, *pose_cov.ravel().tolist(),
        *linear.tolist(), *angular_velocity, *twist_cov.ravel().tolist())


def odom_payloads(stamp_ns, lat, lon, h, v_enu, q_nb, P, S, datum: tuple,
                  rate_variance: float, frames: tuple[str, str] = ("map", "base_link")) -> list:
    """The CDR payloads of :func:`odom_payload` for k epochs at once (angular velocity zero):
    stamps (ns), lat, lon, h (k,), v_enu (k, 3), q_nb (k, 4), P (k, n, n)."""
    enu, linear, pose_cov, twist_cov = _odom_numbers(lat, lon, h, v_enu, q_nb, P, S, datum,
                                                     rate_variance)
    sec, nanosec = np.divmod(np.asarray(stamp_ns, np.int64), NS)
    columns = {"header.stamp.sec": sec, "header.stamp.nanosec": nanosec,
               "pose.covariance": pose_cov.reshape(-1, 36),
               "twist.covariance": twist_cov.reshape(-1, 36)}
    for k, axis in enumerate("xyz"):
        columns["pose.pose.position." + axis] = enu[:, k]
        columns["twist.twist.linear." + axis] = linear[:, k]
        columns["twist.twist.angular." + axis] = 0.0
    for k, axis in enumerate("wxyz"):
        columns["pose.pose.orientation." + axis] = q_nb[:, k]
    return encode_columns("nav_msgs/msg/Odometry", columns,
                          {"header.frame_id": frames[0], "child_frame_id": frames[1]})


def _odom_numbers(lat, lon, h, v_enu, q_nb, P, S, datum, rate_variance) -> tuple:
    """nav/odom's map position, body-frame velocity and pose and twist covariances (6 x 6) of
    one epoch or of epochs stacked on the leading axes. Stacked products only: an epoch gets
    the same bits alone (the ekf node) and among many (the offline path)."""
    enu = to_map(datum, lat, lon, h)
    # Odometry twists are in the child frame (base_link).
    c_bn = np.swapaxes(quat_to_dcm(q_nb), -1, -2)
    linear = (c_bn @ np.asarray(v_enu, float)[..., None])[..., 0]
    pose_cov = np.zeros(np.shape(P)[:-2] + (6, 6))
    pose_cov[..., :3, :3] = P[..., S["pos"], S["pos"]]
    pose_cov[..., 3:, 3:] = P[..., S["att"], S["att"]]  # small-angle errors about ENU axes
    twist_cov = np.zeros_like(pose_cov)
    twist_cov[..., :3, :3] = c_bn @ P[..., S["vel"], S["vel"]] @ np.swapaxes(c_bn, -1, -2)
    twist_cov[..., 3:, 3:] = np.eye(3) * rate_variance
    return enu, linear, pose_cov, twist_cov


def status_msg(t: float, mode: int, tight: bool, updates, covariance, accepted: int,
               rejected: int) -> FilterStatus:
    """nav/status at t (s): FilterStatus mode, coupling, the updates since the last status
    (navigator update records), ``covariance`` = (state space, P) once the filter runs (else
    None) and the running accepted/rejected counts."""
    status = FilterStatus(mode=mode, coupling=FilterStatus.COUPLING_TIGHT
                          if tight else FilterStatus.COUPLING_LOOSE)
    status.header.stamp = sec_to_stamp(t)
    for u in updates:
        status.updates.append(MeasurementUpdate(
            name=u.name, stamp=sec_to_stamp(u.t),
            innovation=[float(x) for x in u.innovation],
            innovation_variance=[float(x) for x in u.s_diag], nis=float(u.nis),
            gate=float(u.gate), accepted=bool(u.accepted),
            reason="" if u.accepted else u.reason))
    if covariance is not None:
        space, P = covariance
        status.state_names = [f"{name}[{i}]" for name in space.blocks
                              for i in range(space[name].stop - space[name].start)]
        status.state_std = np.sqrt(np.diag(P)).tolist()
    status.accepted_count, status.rejected_count = accepted, rejected
    return status
