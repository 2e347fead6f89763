"""Accuracy of an estimated trajectory against truth: error series, statistics, outage drift, NEES.

The estimate is interpolated to the truth epochs (truth is the reference, and RTK truth has gaps
where it was not fixed that must not be bridged): positions linearly in ECEF, velocities and
covariances linearly, attitude by quaternion slerp. Errors are estimate minus truth, resolved in
the local ENU frame at the true position (Groves, "Principles of GNSS, Inertial and Multisensor
Integrated Navigation", 2nd ed., section 2.5 for the frames).

Attitude errors are reported two ways:

* roll, pitch and heading differences (heading = azimuth, clockwise from north, wrapped to
  [-pi, pi) so that 359.9 deg against 0.1 deg is a 0.2 deg error);
* the rotation vector phi of q_est ⊗ q_true* (resolved in ENU; R_est = exp([phi×]) R_true),
  which is what NEES tests against an attitude covariance.

NEES (normalised estimation error squared, Bar-Shalom, Li and Kirubarajan, "Estimation with
Applications to Tracking and Navigation", section 5.4.2) is e^T P^-1 e per epoch; a consistent
filter has mean NEES equal to the dimension (3).
"""
from dataclasses import dataclass, field, replace

import numpy as np
from scipy.spatial.transform import Rotation, Slerp

from ins_gnss_ros.nav.conventions import azimuth_from_yaw, wrap_pi
from ins_gnss_ros.nav.earth import ecef_to_enu_matrix, ecef_to_geodetic, geodetic_to_ecef
from ins_gnss_ros.nav.rotations import quat_conj, quat_mul, quat_normalize, quat_to_euler
from ins_gnss_ros.nav.rotations import quat_to_rotvec
from ins_gnss_ros.trial.outages import in_outage

#: Largest spacing, s, of estimate samples across which the estimate is interpolated; truth
#: epochs inside larger gaps of the estimate are not evaluated.
DEFAULT_MAX_GAP_S = 1.0
#: The same for a published solution's covariances, s (five periods of the ekf's default 10 Hz
#: output): held or interpolated across a longer gap, a covariance would vouch for states no
#: filter published (a drive with a lossy IMU link: the covariance from before a GNSS outage
#: given to states at its end, position NEES 478).
PUBLISHED_MAX_GAP_S = 0.5


@dataclass(frozen=True)
class Trajectory:
    """A navigation solution or truth, one row per epoch (any time scale shared by both).

    Attributes
    ----------
    time : ndarray, shape (n,)
        Strictly increasing epochs, s.
    lat, lon, height : ndarray, shape (n,)
        Geodetic latitude, longitude (rad) and ellipsoidal height (m).
    vel_enu : ndarray, shape (n, 3) or None
        Velocity in ENU, m/s.
    q_nb : ndarray, shape (n, 4) or None
        Attitude, Hamilton [w, x, y, z], rotating body (FLU) vectors into ENU.
    pos_cov_enu, vel_cov_enu : ndarray, shape (n, 3, 3) or None
        Covariances of position (m^2) and velocity ((m/s)^2) in ENU.
    att_cov : ndarray, shape (n, 3, 3) or None
        Covariance, rad^2, of the attitude error rotation vector resolved in ENU (the sign
        convention of the error vector does not matter for its covariance).
    """

    time: np.ndarray
    lat: np.ndarray
    lon: np.ndarray
    height: np.ndarray
    vel_enu: np.ndarray | None = None
    q_nb: np.ndarray | None = None
    pos_cov_enu: np.ndarray | None = None
    vel_cov_enu: np.ndarray | None = None
    att_cov: np.ndarray | None = None

    def __len__(self):
        return len(self.time)


@dataclass(frozen=True)
class ErrorSeries:
    """Estimate-minus-truth errors at the evaluated epochs (m of them).

    Attributes
    ----------
    time : ndarray, shape (m,)
    pos_enu : ndarray, shape (m, 3)
        Position error east/north/up at the true position, m.
    vel_enu : ndarray, shape (m, 3) or None
        Velocity error, m/s.
    euler : ndarray, shape (m, 3) or None
        Roll, pitch and heading (azimuth) errors, rad, wrapped to [-pi, pi).
    att_rotvec : ndarray, shape (m, 3) or None
        Rotation vector of q_est ⊗ q_true*, rad, resolved in ENU.
    pos_sigma, vel_sigma, euler_sigma : ndarray, shape (m, 3) or None
        One-sigma bounds of the components above, from the estimate's covariances.
    nees_pos, nees_vel, nees_att : ndarray, shape (m,) or None
        Per-epoch NEES of position, velocity and attitude (rotation vector).
    """

    time: np.ndarray
    pos_enu: np.ndarray
    vel_enu: np.ndarray | None
    euler: np.ndarray | None
    att_rotvec: np.ndarray | None
    pos_sigma: np.ndarray | None
    vel_sigma: np.ndarray | None
    euler_sigma: np.ndarray | None
    nees_pos: np.ndarray | None
    nees_vel: np.ndarray | None
    nees_att: np.ndarray | None

    @property
    def horizontal(self):
        """Horizontal position error magnitude, m."""
        return np.hypot(self.pos_enu[:, 0], self.pos_enu[:, 1])


@dataclass(frozen=True)
class Statistic:
    """RMS, 95th percentile and maximum of the absolute value of an error (its own unit)."""

    rms: float
    p95: float
    max: float

    @classmethod
    def of(cls, values):
        values = np.abs(np.asarray(values, float))
        values = values[np.isfinite(values)]
        if values.size == 0:
            return cls(np.nan, np.nan, np.nan)
        return cls(float(np.sqrt(np.mean(values ** 2))), float(np.percentile(values, 95.0)),
                   float(values.max()))


@dataclass(frozen=True)
class OutageDrift:
    """Horizontal drift during one GNSS outage window [start, end), s and m.

    `max_horizontal_m` is the largest horizontal error at evaluated epochs inside the window,
    `end_horizontal_m` the error at the last evaluated epoch inside it (NaN without epochs),
    `distance_m` the path length of the truth over those epochs (dead-reckoning drift is
    quoted per distance driven), `max_change_m` the largest horizontal distance of the error
    from its value at the window's first evaluated epoch (what the window adds to an error
    that was not zero when it began, e.g. an absolute solution against a relative truth).
    """

    start: float
    end: float
    max_horizontal_m: float
    end_horizontal_m: float
    distance_m: float = np.nan
    max_change_m: float = np.nan


@dataclass(frozen=True)
class Evaluation:
    """Result of `evaluate`: how far the estimate is from the truth, over the whole run and in
    each GNSS outage, and whether its covariances cover that.

    Attributes
    ----------
    errors : ErrorSeries
    stats : dict of str to Statistic
        Keys ``horizontal_m``, ``vertical_m``, ``velocity_horizontal_mps``,
        ``velocity_vertical_mps``, ``roll_deg``, ``pitch_deg``, ``heading_deg`` (attitude in
        degrees); entries whose inputs are missing hold NaN.
    outages : tuple of OutageDrift
    nees : dict of str to float
        Mean NEES of ``position``, ``velocity``, ``attitude`` (NaN without covariances).
    offset_enu : ndarray, shape (3,) or None
        The mean position error taken out of `errors` (``remove_offset``), m.
    nees_by_aiding : dict of str to dict
        With outage windows: the mean NEES as `nees` over the epochs ``inside`` the outages and
        ``outside`` them. They test different things: inside, the truth is independent of
        everything the filter took; outside, a truth from the same receiver as the aiding (an
        RTK solution both as gnss/fix and as truth/state) shares its errors.
    """

    errors: ErrorSeries
    stats: dict
    outages: tuple
    nees: dict
    offset_enu: np.ndarray | None = None
    nees_by_aiding: dict = field(default_factory=dict)

    def outage_drift(self):
        """(RMS, max) over outages of the maximum horizontal error within each window, m."""
        return _rms_max([o.max_horizontal_m for o in self.outages])

    def outage_drift_percent(self):
        """RMS over outages of the maximum horizontal error within each window per distance
        driven in it, %."""
        return _rms_max([100.0 * o.max_horizontal_m / o.distance_m if o.distance_m > 0.0
                         else np.nan for o in self.outages])[0]

    def outage_end_drift(self):
        """(RMS, max) over outages of the horizontal error at the end of each window, m."""
        return _rms_max([o.end_horizontal_m for o in self.outages])

    def outage_change(self):
        """(RMS, max) over outages of the largest change of the error within each window, m."""
        return _rms_max([o.max_change_m for o in self.outages])

    def to_json(self):
        """Flat dict of the statistics for ``trial evaluate --json`` (CONTRACT.md).

        Keys ``<stat>_rms_<unit>``, ``<stat>_p95_<unit>``, ``<stat>_max_<unit>`` for every
        entry of `stats` (so ``horizontal_rms_m``, ``vertical_rms_m``, ``roll_rms_deg``,
        ``pitch_rms_deg``, ``heading_rms_deg`` ...), ``nees_<name>_mean``, ``epochs``; with
        outage windows also ``outage_drift_rms_m`` / ``outage_drift_max_m`` (maximum error
        within each window), ``nees_<name>_inside_outages_mean`` and
        ``nees_<name>_outside_outages_mean``, ``outage_end_rms_m`` / ``outage_end_max_m``,
        ``outage_change_rms_m`` / ``outage_change_max_m`` (largest change of the error within
        each window) and the list ``outages``; with a removed offset ``removed_offset_enu_m``.
        Values that cannot be computed are None (JSON null).
        """
        out = {"epochs": int(len(self.errors.time))}
        if self.offset_enu is not None:
            out["removed_offset_enu_m"] = [float(x) for x in self.offset_enu]
        for key, stat in self.stats.items():
            name, unit = key.rsplit("_", 1)
            for field in ("rms", "p95", "max"):
                out[f"{name}_{field}_{unit}"] = _finite_or_none(getattr(stat, field))
        for name, value in self.nees.items():
            out[f"nees_{name}_mean"] = _finite_or_none(value)
        for where, nees in self.nees_by_aiding.items():
            for name, value in nees.items():
                out[f"nees_{name}_{where}_outages_mean"] = _finite_or_none(value)
        if self.outages:
            for prefix, (rms, peak) in (("outage_drift", self.outage_drift()),
                                        ("outage_end", self.outage_end_drift()),
                                        ("outage_change", self.outage_change())):
                out[f"{prefix}_rms_m"] = _finite_or_none(rms)
                out[f"{prefix}_max_m"] = _finite_or_none(peak)
            out["outage_drift_rms_percent"] = _finite_or_none(self.outage_drift_percent())
            out["outages"] = [{"start": o.start, "end": o.end,
                               "max_horizontal_m": _finite_or_none(o.max_horizontal_m),
                               "end_horizontal_m": _finite_or_none(o.end_horizontal_m),
                               "distance_m": _finite_or_none(o.distance_m),
                               "max_change_m": _finite_or_none(o.max_change_m)}
                              for o in self.outages]
        return out


def interpolate(trajectory, t):
    """Trajectory sampled at times `t` inside its span.

    Positions are interpolated linearly in ECEF (no trouble at the +-180 deg meridian), attitude
    by slerp between the neighbouring samples, velocity and covariances linearly (a convex
    combination of covariance matrices stays positive semi-definite).

    Parameters
    ----------
    trajectory : Trajectory
    t : ndarray, shape (m,)
        Times within [trajectory.time[0], trajectory.time[-1]], s.

    Returns
    -------
    Trajectory
    """
    t = np.asarray(t, float)
    src = trajectory.time

    def linear(values):
        if values is None:
            return None
        flat = values.reshape(len(src), -1)
        out = np.column_stack([np.interp(t, src, column) for column in flat.T])
        return out.reshape((len(t),) + values.shape[1:])

    lat, lon, height = ecef_to_geodetic(linear(geodetic_to_ecef(
        trajectory.lat, trajectory.lon, trajectory.height)))
    q_nb = None
    if trajectory.q_nb is not None:
        # scipy stores quaternions scalar-last.
        rotations = Rotation.from_quat(np.asarray(trajectory.q_nb)[:, [1, 2, 3, 0]])
        q_nb = quat_normalize(Slerp(src, rotations)(t).as_quat()[:, [3, 0, 1, 2]])
    return Trajectory(time=t, lat=lat, lon=lon, height=height,
                      vel_enu=linear(trajectory.vel_enu), q_nb=q_nb,
                      pos_cov_enu=linear(trajectory.pos_cov_enu),
                      vel_cov_enu=linear(trajectory.vel_cov_enu),
                      att_cov=linear(trajectory.att_cov))


def evaluate(estimate, truth, windows=None, max_gap=DEFAULT_MAX_GAP_S, remove_offset=False,
             published=None):
    """Compare an estimated trajectory with truth.

    Parameters
    ----------
    estimate, truth : Trajectory
        On the same time scale. Velocity and attitude errors are computed where both have them;
        covariances are taken from `estimate`, or from `published`.
    published : Trajectory, optional
        The solution a filter published with its covariances, at its own (lower) rate: the
        NEES and sigma bounds are of it, at the truth epochs its samples bracket within
        PUBLISHED_MAX_GAP_S (NaN elsewhere). A covariance judges the state it was published
        with: an estimate sampled between the filter's outputs need not hold every update
        that covariance follows (the strapdown's state at the sample before a fix's epoch,
        published before the filter had the fix, beside the filter's solution with it).
    windows : ndarray, shape (k, 2), optional
        GNSS outage windows [start, end), s (see :mod:`ins_gnss_ros.trial.outages`).
    max_gap : float
        Truth epochs are evaluated only where the neighbouring estimate samples are at most this
        far apart, s.
    remove_offset : bool
        Take the mean position error out of the errors (and their statistics and NEES): a
        truth with a constant offset of its own, such as an RTK solution against a base of
        unknown coordinates, compared with an absolute (single-point-like) estimate.

    Returns
    -------
    Evaluation
    """
    if len(estimate) < 2:
        raise ValueError("the estimate needs at least two epochs to be interpolated")
    keep = _bracketed(estimate.time, truth.time, max_gap)
    if not keep.any():
        raise ValueError("no truth epoch lies within the estimate's time span")
    true = _subset(truth, keep)
    est = interpolate(estimate, true.time)
    errors = _error_series(est, true)
    offset = None
    if remove_offset:
        offset = errors.pos_enu.mean(axis=0)
        pos = errors.pos_enu - offset
        errors = replace(errors, pos_enu=pos, nees_pos=_nees(pos, est.pos_cov_enu))
    if published is not None:
        errors = replace(errors, **_published_bounds(published, true, offset))
    stats = {
        "horizontal_m": Statistic.of(errors.horizontal),
        "vertical_m": Statistic.of(errors.pos_enu[:, 2]),
        "velocity_horizontal_mps": _maybe(errors.vel_enu, lambda e: np.hypot(e[:, 0], e[:, 1])),
        "velocity_vertical_mps": _maybe(errors.vel_enu, lambda e: e[:, 2]),
        "roll_deg": _maybe(errors.euler, lambda e: np.degrees(e[:, 0])),
        "pitch_deg": _maybe(errors.euler, lambda e: np.degrees(e[:, 1])),
        "heading_deg": _maybe(errors.euler, lambda e: np.degrees(e[:, 2])),
    }
    by_aiding = {}
    if windows is not None:
        inside = in_outage(errors.time, windows)
        by_aiding = {"inside": _mean_nees(errors, inside), "outside": _mean_nees(errors, ~inside)}
    return Evaluation(errors=errors, stats=stats, nees=_mean_nees(errors), offset_enu=offset,
                      outages=outage_drifts(errors, windows, true) if windows is not None else (),
                      nees_by_aiding=by_aiding)


#: The ErrorSeries fields a covariance gives.
_BOUNDS = ("pos_sigma", "vel_sigma", "euler_sigma", "nees_pos", "nees_vel", "nees_att")


def _published_bounds(published, true, offset):
    """The sigma and NEES fields of an ErrorSeries at the truth epochs `true`, of the
    published solution's errors and covariances (NaN where its samples do not bracket the
    epoch); `offset`: the estimate's mean position error taken out, or None."""
    n = len(true.time)
    keep = _bracketed(published.time, true.time, PUBLISHED_MAX_GAP_S) if len(published) > 1 \
        else np.zeros(n, bool)
    if not keep.any():
        return dict.fromkeys(_BOUNDS)
    pub = interpolate(published, true.time[keep])
    series = _error_series(pub, _subset(true, keep))
    if offset is not None:
        series = replace(series, nees_pos=_nees(series.pos_enu - offset, pub.pos_cov_enu))
    out = {}
    for name in _BOUNDS:
        values = getattr(series, name)
        if values is None:
            out[name] = None
            continue
        full = np.full((n,) + values.shape[1:], np.nan)
        full[keep] = values
        out[name] = full
    return out


def _mean_nees(errors, epochs=slice(None)):
    """Mean NEES of position, velocity and attitude over `epochs` with a known covariance."""
    def mean(values):
        values = None if values is None else values[epochs]
        return float(np.nanmean(values)) if values is not None and np.isfinite(values).any() \
            else np.nan
    return {"position": mean(errors.nees_pos), "velocity": mean(errors.nees_vel),
            "attitude": mean(errors.nees_att)}


def outage_drifts(errors, windows, truth=None):
    """Horizontal drift within and at the end of each outage window.

    Parameters
    ----------
    errors : ErrorSeries
    windows : ndarray, shape (k, 2)
        [start, end) of each outage, s.
    truth : Trajectory, optional
        The truth at the epochs of `errors`, for the distance driven in each window.

    Returns
    -------
    tuple of OutageDrift
    """
    horizontal = errors.horizontal
    drifts = []
    for start, end in np.asarray(windows, float).reshape(-1, 2):
        inside = (errors.time >= start) & (errors.time < end)
        if inside.any():
            distance = np.nan
            if truth is not None:
                r = geodetic_to_ecef(truth.lat[inside], truth.lon[inside], truth.height[inside])
                distance = float(np.sum(np.linalg.norm(np.diff(np.reshape(r, (-1, 3)), axis=0),
                                                       axis=1)))
            change = errors.pos_enu[inside, :2] - errors.pos_enu[inside][0, :2]
            drifts.append(OutageDrift(float(start), float(end), float(horizontal[inside].max()),
                                      float(horizontal[inside][-1]), distance,
                                      float(np.hypot(change[:, 0], change[:, 1]).max())))
        else:
            drifts.append(OutageDrift(float(start), float(end), np.nan, np.nan))
    return tuple(drifts)


def markdown_table(evaluation):
    """The statistics (and outage drifts, NEES) of an `Evaluation` as Markdown tables."""
    units = {"m": "m", "mps": "m/s", "deg": "deg"}
    lines = [f"Evaluated epochs: {len(evaluation.errors.time)}", "",
             "| error | RMS | 95 % | max | unit |", "|---|---:|---:|---:|---|"]
    for key, stat in evaluation.stats.items():
        name, unit = key.rsplit("_", 1)
        if np.isfinite(stat.rms):
            lines.append(f"| {name.replace('_', ' ')} | {stat.rms:.3f} | {stat.p95:.3f} | "
                         f"{stat.max:.3f} | {units[unit]} |")
    nees = {name: value for name, value in evaluation.nees.items() if np.isfinite(value)}
    if nees:
        lines += ["", "| NEES (mean, expect 3) | " + " | ".join(nees) + " |",
                  "|---|" + "---:|" * len(nees),
                  "| all epochs | " + " | ".join(f"{value:.2f}" for value in nees.values()) + " |"]
        lines += [f"| {where} the outages | " + " | ".join(
                      f"{values[name]:.2f}" for name in nees) + " |"
                  for where, values in evaluation.nees_by_aiding.items()]
    if evaluation.outages:
        t0 = evaluation.errors.time[0]
        lines += ["", "| outage | start (s from first epoch) | length (s) | max horizontal (m) "
                  "| at end (m) | distance (m) | largest change (m) |",
                  "|---:|---:|---:|---:|---:|---:|---:|"]
        for number, o in enumerate(evaluation.outages, start=1):
            lines.append(f"| {number} | {o.start - t0:.1f} | {o.end - o.start:.1f} | "
                         f"{o.max_horizontal_m:.3f} | {o.end_horizontal_m:.3f} | "
                         f"{o.distance_m:.1f} | {o.max_change_m:.3f} |")
        (rms, peak), (end_rms, end_peak) = evaluation.outage_drift(), evaluation.outage_end_drift()
        change_rms, change_peak = evaluation.outage_change()
        lines.append(f"| RMS / max | | | {rms:.3f} / {peak:.3f} | {end_rms:.3f} / {end_peak:.3f} "
                     f"| max per distance RMS {evaluation.outage_drift_percent():.2f} % "
                     f"| {change_rms:.3f} / {change_peak:.3f} |")
    return "\n".join(lines)


def euler_error_jacobian(q_nb):
    """Matrix J with d(roll, pitch, azimuth) = J phi for a small ENU rotation vector phi.

    With R = Rz(yaw) Ry(pitch) Rx(roll), a perturbation exp([phi×]) R changes the Euler angles
    by d such that phi = M [d_yaw, d_pitch, d_roll], M = [e_z, Rz e_y, Rz Ry e_x] (the axes of
    the three elementary rotations, resolved in ENU; Savage, "Strapdown Analytics", section
    3.2.3). The azimuth changes by -d_yaw.

    Parameters
    ----------
    q_nb : ndarray, shape (m, 4)

    Returns
    -------
    ndarray, shape (m, 3, 3)
    """
    _, pitch, yaw = quat_to_euler(q_nb)
    cy, sy, cp, sp = np.cos(yaw), np.sin(yaw), np.cos(pitch), np.sin(pitch)
    m = np.zeros((len(yaw), 3, 3))
    m[:, 2, 0] = 1.0                                        # yaw axis e_z
    m[:, 0, 1], m[:, 1, 1] = -sy, cy                        # pitch axis Rz e_y
    m[:, 0, 2], m[:, 1, 2], m[:, 2, 2] = cy * cp, sy * cp, -sp  # roll axis Rz Ry e_x
    # Rows of inv(M) give (d_yaw, d_pitch, d_roll); reorder to (roll, pitch, azimuth).
    return np.linalg.inv(m)[:, [2, 1, 0]] * np.array([1.0, 1.0, -1.0])[:, None]


def _error_series(est, true):
    ecef_error = geodetic_to_ecef(est.lat, est.lon, est.height) - geodetic_to_ecef(
        true.lat, true.lon, true.height)
    c_en = np.stack([ecef_to_enu_matrix(lat, lon) for lat, lon in zip(true.lat, true.lon)])
    pos = np.einsum("nij,nj->ni", c_en, ecef_error)
    vel = est.vel_enu - true.vel_enu if est.vel_enu is not None and true.vel_enu is not None \
        else None
    euler = rotvec = euler_sigma = nees_att = None
    if est.q_nb is not None and true.q_nb is not None:
        euler = _euler_errors(est.q_nb, true.q_nb)
        rotvec = quat_to_rotvec(quat_mul(est.q_nb, quat_conj(true.q_nb)))
        if est.att_cov is not None:
            jac = euler_error_jacobian(true.q_nb)
            euler_sigma = _sigma(jac @ est.att_cov @ np.swapaxes(jac, 1, 2))
            nees_att = _nees(rotvec, est.att_cov)
    return ErrorSeries(
        time=true.time, pos_enu=pos, vel_enu=vel, euler=euler, att_rotvec=rotvec,
        pos_sigma=_sigma(est.pos_cov_enu),
        vel_sigma=_sigma(est.vel_cov_enu) if vel is not None else None,
        euler_sigma=euler_sigma,
        nees_pos=_nees(pos, est.pos_cov_enu),
        nees_vel=_nees(vel, est.vel_cov_enu) if vel is not None else None,
        nees_att=nees_att)


def _euler_errors(q_est, q_true):
    """Roll, pitch, azimuth differences estimate - truth, wrapped to [-pi, pi)."""
    roll_e, pitch_e, yaw_e = quat_to_euler(q_est)
    roll_t, pitch_t, yaw_t = quat_to_euler(q_true)
    return np.column_stack([wrap_pi(roll_e - roll_t), pitch_e - pitch_t,
                            wrap_pi(azimuth_from_yaw(yaw_e) - azimuth_from_yaw(yaw_t))])


def _sigma(cov):
    return None if cov is None else np.sqrt(np.diagonal(cov, axis1=1, axis2=2))


def _nees(error, cov):
    """Per-epoch NEES; NaN where the covariance is unknown (not finite)."""
    if cov is None:
        return None
    nees = np.full(len(error), np.nan)
    known = np.isfinite(cov).all(axis=(1, 2))
    nees[known] = np.einsum("ni,ni->n", error[known],
                            np.linalg.solve(cov[known], error[known][..., None])[..., 0])
    return nees


def _bracketed(t_est, t_truth, max_gap):
    """Truth epochs inside the estimate's span whose neighbouring estimate samples are close."""
    inside = (t_truth >= t_est[0]) & (t_truth <= t_est[-1])
    right = np.clip(np.searchsorted(t_est, t_truth), 1, len(t_est) - 1)
    return inside & (t_est[right] - t_est[right - 1] <= max_gap)


def _subset(trajectory, mask):
    return Trajectory(**{name: None if value is None else value[mask]
                         for name, value in vars(trajectory).items()})


def _maybe(errors, select):
    return Statistic(np.nan, np.nan, np.nan) if errors is None else Statistic.of(select(errors))


def _rms_max(values):
    values = np.asarray(values, float)
    values = values[np.isfinite(values)]
    if values.size == 0:
        return np.nan, np.nan
    return float(np.sqrt(np.mean(values ** 2))), float(values.max())


def _finite_or_none(value):
    return float(value) if np.isfinite(value) else None
