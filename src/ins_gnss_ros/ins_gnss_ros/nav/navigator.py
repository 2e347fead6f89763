"""Offline navigator: the strapdown and the closed-loop error-state filter over a whole trial.

The same filter code as the ``ekf`` node, without ROS. Feed IMU increments (:meth:`add_imu`, at
the IMU rate, any batch size) and time-stamped measurements (:meth:`add_measurement`) in any
interleaving; :meth:`flush` at the end. The navigator

* compensates the increments with the running sensor-error estimates, applies the one-sample
  coning/sculling terms (:mod:`ins_gnss_ros.nav.coning`) and mechanises them in compiled batches
  between filter epochs (:func:`ins_gnss_ros.nav.strapdown.run`);
* propagates the covariance every `cov_interval` seconds and at every measurement epoch with F
  from the mean compensated rates of the segment (seed 004 section 2.5: Phi from F rebuilt at
  the propagation rate);
* applies each measurement at ITS epoch, never at arrival: a measurement older than the state is
  handled by restoring a snapshot taken before its epoch and re-running the buffered IMU data with
  it (exactly what the filter would have done had it arrived on time; seed 000 section A2.6 and
  seed 003 section B4 use the delayed measurement against the stored state of its epoch for the
  same purpose). With a "td" extra state the epoch of a GNSS measurement stamped t is t - td;
* closes the loop after every update (ekf.py), gates every measurement (gating.py), rejects a
  frozen receiver that repeats a fix while the INS moves, and forces a measurement kind through
  after `max_reject_time` seconds of continuous rejection (recovery after a divergence, see
  :meth:`Navigator._update` for how it stays honest when the measurement was the faulty one);
* adds the process noise of a gap in the IMU data that the caller bridged with held rates
  (:meth:`add_bridged_gap`);
* runs the modes ALIGNING (levelling at the first fix; heading from the first motion, by
  comparing the GNSS velocity with the velocity the INS computed in its yaw-free frame; GNSS used
  only while at rest), NAVIGATING, DEAD_RECKONING (no accepted aiding for `dr_timeout` s, or
  degraded: a kind was forced in and its noise floor has not yet decayed, see `floor_tau`);
* starts again from ALIGNING when the IMU time jumps backwards.

Per-epoch outputs (:class:`NavigatorOutput`) keep what the RTS smoother (smoother.py) needs.
"""
from __future__ import annotations

import bisect
from dataclasses import dataclass, field, replace

import numpy as np

from . import measurements as meas
from .alignment import level
from .coning import coning_sculling
from .earth import WGS84, radii
from .ekf import ErrorStateEKF, StateSpace
from .error_model import BLOCK_SIZES, make_layout
from .gating import DEFAULT_GATE_PROB, chi2_gate, normalised_innovation, rejected
from .lever_arm import lever_arm_position, lever_arm_velocity
from .rotations import quat_from_euler, quat_from_rotvec, quat_mul, quat_normalize, \
    quat_rotate, quat_to_dcm
from .strapdown import NavState, apply_correction, run

ALIGNING, NAVIGATING, DEAD_RECKONING = "ALIGNING", "NAVIGATING", "DEAD_RECKONING"
MODES = (ALIGNING, NAVIGATING, DEAD_RECKONING)

#: Earth rotation rate, rad/s.
EARTH_RATE = WGS84.omega

#: Sensor-error blocks the compensation applies (error_model.py names). "gs" is not supported.
_GYRO_BIAS, _ACCEL_BIAS = ("bg", "gmg"), ("ba", "gma")


# ------------------------------------------------------------------------------------------
# Measurements accepted by the navigator
# ------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class GnssFix:
    """Antenna position at GNSS time t (s): lat, lon (rad), h (m), covariance ENU (m^2)."""

    t: float
    lat: float
    lon: float
    h: float
    cov_enu: np.ndarray


@dataclass(frozen=True)
class GnssVelocity:
    """Antenna velocity ENU (m/s) at GNSS time t, covariance ((m/s)^2)."""

    t: float
    v_enu: np.ndarray
    cov_enu: np.ndarray


@dataclass(frozen=True)
class HeadingFix:
    """Azimuth of the body x axis (rad, clockwise from north) at time t; `magnetic` selects the
    compass model (declination already applied) with its optional bias state."""

    t: float
    azimuth: float
    variance: float
    magnetic: bool = False


@dataclass(frozen=True)
class SpeedLog:
    """Speed through the water along the body x axis (m/s) at time t, variance ((m/s)^2);
    with a "log" extra block the current and the log scale error are estimated."""

    t: float
    speed: float
    variance: float


@dataclass(frozen=True)
class ZeroVelocity:
    """The vehicle is known to be at rest at time t: ZUPT (sigma_v m/s) and, if sigma_w is set,
    ZARU (rad/s)."""

    t: float
    sigma_v: float = 0.01
    sigma_w: float | None = None


@dataclass(frozen=True)
class SatelliteRanges:
    """Tight coupling: per-satellite pseudoranges (and optionally range rates) at GNSS time t.

    Arrays of k satellites: sat_pos, sat_vel (ECEF, m, m/s), sat_clock (m), sat_clock_drift
    (m/s), pseudorange (m), pr_var (m^2), range_rate (m/s, or None), rr_var ((m/s)^2).
    """

    t: float
    sat_pos: np.ndarray
    sat_vel: np.ndarray
    sat_clock: np.ndarray
    sat_clock_drift: np.ndarray
    pseudorange: np.ndarray
    pr_var: float
    range_rate: np.ndarray | None = None
    rr_var: float = 0.01


_GNSS_TYPES = (GnssFix, GnssVelocity, SatelliteRanges)


@dataclass
class NavigatorConfig:
    """Parameters of the offline navigator (all SI).

    Attributes
    ----------
    noise : FilterNoise
        IMU noise model (sensor_errors.filter_noise or hand-made).
    layout : str or tuple
        Error-model layout (error_model.LAYOUTS key or block names).
    extras : dict of str to ExtraState
        Extra filter blocks ("td", "mag").
    lever_arm_b : array_like, shape (3,)
        GNSS antenna relative to the IMU, FLU, m.
    cov_interval : float
        Covariance propagation interval, s.
    gate_prob : float or None
        Chi-square gate probability (None: no gating).
    max_reject_time : float
        After this long of continuous rejection of one measurement kind, force it in, s.
    floor_tau : float
        Time constant of the noise floor a forced kind keeps (:meth:`Navigator._update`): it
        decays by exp(-dt / floor_tau) over the time its measurements are accepted, s.
    degraded_ratio : float
        While a forced kind's floor exceeds degraded_ratio^2 times the measurement's own
        variance, the mode is DEAD_RECKONING (degraded: not confirmed by the aiding), -.
    suspect_time : float
        While an aiding kind has been rejected continuously for this long (and is still
        arriving), the mode is DEAD_RECKONING too: the INS or that aiding is wrong, s.
    gap_accel_sigma, gap_rate_sigma : float
        Over a bridged IMU gap (:meth:`Navigator.add_bridged_gap`): standard deviation of the
        difference between the held and the true specific force (m/s^2) and angular rate
        (rad/s), averaged over it.
    sigma_pos0, sigma_vel0, sigma_tilt0 : float
        Initial standard deviations at the first fix (m, m/s, rad).
    sigma_yaw_align : float
        Floor of the heading standard deviation after motion alignment, rad.
    static_speed : float
        GNSS horizontal speed below which the vehicle counts as at rest while aligning, m/s.
    align_speed : float
        GNSS horizontal speed at which the heading is taken from the motion, m/s.
    level_time : float
        Minimum IMU data before the first fix for levelling, s.
    dr_timeout : float
        Without accepted aiding for this long the mode becomes DEAD_RECKONING, s.
    nhc_sigma : tuple of 2 float or None
        Non-holonomic constraint noise (lateral, vertical), m/s, applied every epoch while
        navigating (wheeled vehicles only); None disables it.
    nhc_interval : float
        Least time between two constraint updates, s.
    nhc_rate_arm : float
        Uncertainty of the distance to the constraint point along x, m: the lateral noise
        becomes hypot(sigma_lateral, nhc_rate_arm * yaw rate).
    nhc_lever_b : array_like, shape (3,)
        Point where the constraint holds (rear-axle centre) relative to the IMU, FLU, m.
    zaru_sigma : float or None
        Zero-angular-rate update at every GNSS velocity epoch at rest: noise added to the
        averaged gyro white noise, rad/s (vibration, body sway); None disables it.
    frozen_speed : float
        A fix identical to the previous one is rejected as frozen above this INS speed, m/s.
    history : float
        How far back a delayed measurement can still be applied at its epoch, s.
    checkpoint_interval : float
        Spacing of the snapshots kept for delayed measurements, s.
    store_covariance : bool
        Keep the full P, P_prior and Phi per epoch (needed by the RTS smoother).
    record : bool
        Keep the per-epoch outputs and every update result (:meth:`Navigator.output`). The
        ``ekf`` node runs for hours and turns it off: then only the updates of the last
        `history` seconds are kept (:meth:`Navigator.updates_since`) and memory stays bounded.
    compensated_increments : bool
        The increments given to :meth:`Navigator.add_imu` are already coning/sculling/rotation
        compensated (``imu/delta``, as the imu_preprocessor makes them and the strapdown node
        integrates them): they are mechanised as they are. False: raw sensor increments, whose
        second-order terms the navigator adds (one-sample algorithm).
    """

    noise: object
    layout: object = "15"
    extras: dict = field(default_factory=dict)
    lever_arm_b: np.ndarray = field(default_factory=lambda: np.zeros(3))
    cov_interval: float = 0.1
    gate_prob: float | None = DEFAULT_GATE_PROB
    max_reject_time: float = 2.0
    floor_tau: float = 30.0
    degraded_ratio: float = 3.0
    suspect_time: float = 1.0
    gap_accel_sigma: float = 1.0
    gap_rate_sigma: float = np.deg2rad(5.0)
    sigma_pos0: float = 1.0
    sigma_vel0: float = 0.1
    sigma_tilt0: float = 0.02
    sigma_yaw_align: float = np.deg2rad(1.0)
    static_speed: float = 0.1
    align_speed: float = 0.5
    level_time: float = 1.0
    dr_timeout: float = 2.0
    nhc_sigma: tuple | None = None
    nhc_lever_b: np.ndarray = field(default_factory=lambda: np.zeros(3))
    nhc_interval: float = 0.1
    nhc_rate_arm: float = 0.0
    zaru_sigma: float | None = 1e-4
    frozen_speed: float = 0.5
    history: float = 3.0
    checkpoint_interval: float = 0.5
    store_covariance: bool = True
    record: bool = True
    compensated_increments: bool = False


@dataclass
class NavigatorOutput:
    """Per-epoch record of a forward pass (k epochs, n states).

    Attributes
    ----------
    t : (k,) s
    lat, lon, h : (k,) rad, rad, m (IMU position, after the updates of the epoch)
    v_enu : (k, 3) m/s
    q_nb : (k, 4)
    mode : (k,) str
    P : (k, n, n) or None
        Covariance after the updates of the epoch.
    P_prior : (k, n, n) or None
        Covariance before them.
    phi : (k, n, n) or None
        Transition matrix from the previous epoch (identity at the first).
    dx : (k, n)
        Sum of the corrections fed back at the epoch.
    estimates : dict of str to (k, size)
        Running sensor / clock / extra estimates after the epoch.
    space : StateSpace
    updates : list of UpdateResult
    """

    t: np.ndarray
    lat: np.ndarray
    lon: np.ndarray
    h: np.ndarray
    v_enu: np.ndarray
    q_nb: np.ndarray
    mode: np.ndarray
    P: np.ndarray | None
    P_prior: np.ndarray | None
    phi: np.ndarray | None
    dx: np.ndarray
    estimates: dict
    space: StateSpace
    updates: list

    def state(self, k):
        """NavState of epoch k."""
        return NavState(self.lat[k], self.lon[k], self.h[k], self.v_enu[k], self.q_nb[k],
                        self.t[k])

    def sigma(self, block):
        """Standard deviations of a block per epoch, (k, size)."""
        s = self.space[block]
        return np.sqrt(np.diagonal(self.P, axis1=1, axis2=2)[:, s])


def point_track(out, lever_b, lat=None, lon=None, h=None, q_nb=None):
    """Positions (lat, lon, h arrays) of the point at lever arm `lever_b` (FLU, m) along a track
    (by default the forward pass of `out`)."""
    lat = out.lat if lat is None else lat
    return lever_arm_position(lat, out.lon if lon is None else lon, out.h if h is None else h,
                              out.q_nb if q_nb is None else q_nb, np.asarray(lever_b, float))


def extrapolate(state, dt, a_enu):
    """State moved by dt (s; normally a fraction of one IMU sample, or the change of the
    time-offset estimate) at constant acceleration a_enu (m/s^2): the measurement epoch."""
    if dt == 0.0:
        return state
    rm, rn = radii(state.lat)
    d = state.v_enu * dt + 0.5 * a_enu * dt * dt
    return replace(state, lat=state.lat + d[1] / (rm + state.h),
                   lon=state.lon + d[0] / ((rn + state.h) * np.cos(state.lat)),
                   h=state.h + d[2], v_enu=state.v_enu + a_enu * dt, t=state.t + dt)


class Navigator:
    """Strapdown + closed-loop EKF over time-ordered IMU data and measurements.

    Parameters
    ----------
    config : NavigatorConfig
    """

    def __init__(self, config):
        self.config = config
        self.space = StateSpace(make_layout(config.layout, config.noise), dict(config.extras))
        if "gs" in self.space or "ng" in self.space or "na" in self.space:
            raise ValueError("the navigator compensates bias and scale-factor blocks only")
        self.lever = np.asarray(config.lever_arm_b, float)
        # Corrections of the solution so far, pseudo-measurements (NHC, ZARU) included: what a
        # follower of the solution (the strapdown node) must hear of. Monotonic, neither reset
        # nor rewound: a re-run after a delayed measurement changes the solution again.
        self.revision = 0
        self.reset()

    # --------------------------------------------------------------------------------------
    # public interface
    # --------------------------------------------------------------------------------------
    def reset(self):
        """Forget everything: back to ALIGNING with no data."""
        self._imu_t = np.empty(0)
        self._imu_th = np.empty((0, 3))
        self._imu_dv = np.empty((0, 3))
        self._imu_cth = np.empty((0, 3))
        self._imu_cdv = np.empty((0, 3))
        self._next = 0
        self._pending = []          # sorted list of (epoch, sequence, measurement)
        self._seq = 0
        self._applied = []          # measurements applied since the oldest snapshot, in order
        self._snapshots = []
        self._out = {k: [] for k in ("t", "lat", "lon", "h", "v", "q", "mode", "P", "Pp",
                                     "phi", "dx", "est")}
        self._updates = []
        self._updates_dropped = 0   # update results forgotten in streaming use (record=False)
        self.nav = None
        self.ekf = None
        self.mode = ALIGNING
        self.heading_known = False
        self.estimates = {name: np.zeros(size) for name, size in self._estimate_sizes()}
        self._t_epoch = -np.inf
        self._t_model = -np.inf
        self._t_nhc = -np.inf
        self._t_last_aid = -np.inf
        self._reject_since = {}
        self._floors = {}           # kind -> noise floor variances, epoch of its last decay, ...
        self._rejecting = {}        # aiding kind -> (first, last) epoch of its current rejection
        self._a_enu = np.zeros(3)
        self._omega = np.zeros(3)
        self._omega_time = 1.0
        self._rest_pos = None
        self._level_sum = np.zeros(3)
        self._level_time = 0.0
        self._last_fix = None
        self._gnss_speed = np.nan
        self._t_snapshot = -np.inf
        self._gaps = []             # (start, end) of the IMU gaps the caller bridged, s

    def add_imu(self, t, dtheta, dv):
        """Add IMU samples.

        Parameters
        ----------
        t : float or array_like, shape (N,)
            End time of each sample's interval (navigation time scale), s, increasing.
        dtheta, dv : array_like, shape (3,) or (N, 3)
            Gyro (rad) and accelerometer (m/s) increments over each interval, body FLU: raw,
            or compensated (``NavigatorConfig.compensated_increments``).
        """
        t = np.atleast_1d(np.asarray(t, float))
        dtheta = np.atleast_2d(np.asarray(dtheta, float))
        dv = np.atleast_2d(np.asarray(dv, float))
        if len(self._imu_t) and t[0] <= self._imu_t[-1]:
            self.reset()
        # Second-order coning/sculling/rotation terms of the raw samples, one batch at a time
        # (one-sample algorithm chained across batches). Computing them before the bias
        # compensation changes them by (bias dt) x (increment) ~ 1e-6 m/s per sample for a
        # 0.2 deg/s gyro bias at 100 Hz: far below the sensor noise, and it keeps the
        # per-segment work to a subtraction.
        # Each sample's predecessor (filled in place: np.vstack costs more than the copy in
        # the ekf node, which adds one sample per call).
        if self.config.compensated_increments:
            # Compensated once already: adding the terms again doubles them (a 2.5 mg-class
            # velocity error in turns on the car drive) and parts the filter from the strapdown
            # node it keeps in step.
            d_rot, d_dv = np.zeros_like(dtheta), np.zeros_like(dv)
        else:
            prev_th, prev_dv = np.zeros_like(dtheta), np.zeros_like(dv)
            if len(self._imu_t):
                prev_th[0], prev_dv[0] = self._imu_th[-1], self._imu_dv[-1]
            prev_th[1:], prev_dv[1:] = dtheta[:-1], dv[:-1]
            rot, dvn = coning_sculling(dtheta[:, None, :], dv[:, None, :], "one_sample",
                                       prev=(prev_th, prev_dv))
            d_rot, d_dv = rot - dtheta, dvn - dv
        self._trim()
        self._append_imu(t, dtheta, dv, d_rot, d_dv)
        self._advance()

    #: The per-sample IMU buffers: views of the first rows of preallocated arrays.
    _IMU_BUFFERS = ("_imu_t", "_imu_th", "_imu_dv", "_imu_cth", "_imu_cdv")

    def _append_imu(self, *columns):
        """Append samples to the IMU buffers (columns in :attr:`_IMU_BUFFERS` order).

        Each buffer is a view of the filled rows of a larger array whose capacity doubles
        when full, so that adding one sample at a time (the ekf node) costs a row copy, not a
        copy of the whole buffer as with np.concatenate. After :meth:`reset` (empty buffers)
        new arrays are allocated.
        """
        n, m = len(self._imu_t), len(columns[0])
        store = self._imu_store if n else None
        if store is None or n + m > len(store[0]):
            capacity = max(4096, 2 * (n + m))
            store = [np.empty((capacity,) + c.shape[1:]) for c in columns]
            for a, name in zip(store, self._IMU_BUFFERS):
                a[:n] = getattr(self, name)
            self._imu_store = store
        for a, c, name in zip(store, columns, self._IMU_BUFFERS):
            a[n:n + m] = c
            setattr(self, name, a[:n + m])

    def add_bridged_gap(self, t_start, t_end):
        """The IMU samples between t_start and t_end (s) were lost and the caller bridged the gap
        by holding the rates of the sample after it (in samples of the usual length, added with
        :meth:`add_imu` after this call): the covariance propagated over the gap gets the process
        noise of what holding the rates may miss (:meth:`_add_gap_noise`). Measurements with
        epochs inside the gap are applied there as usual."""
        # Older gaps lie before any snapshot a delayed measurement could re-run from.
        horizon = t_start - self.config.history - self.config.checkpoint_interval
        self._gaps = [g for g in self._gaps if g[1] > horizon] + [(t_start, t_end)]

    def add_measurement(self, m):
        """Add a time-stamped measurement (GnssFix, GnssVelocity, HeadingFix, SpeedLog,
        ZeroVelocity, SatelliteRanges); a measurement older than the current state is applied at its epoch by
        re-running the stored IMU data (within `history` seconds)."""
        epoch = self._epoch_of(m)
        if self.nav is not None and epoch < self.nav.t:
            snap = next((s for s in reversed(self._snapshots) if s["nav"].t < epoch), None)
            if snap is None:
                self._updates.append(rejected(type(m).__name__, epoch, np.zeros(0),
                                              np.zeros((0, 0)), "too old"))
                return
            self._restore(snap)
        self._queue(m)
        self._advance()

    def flush(self):
        """Process every buffered IMU sample (end of the data)."""
        self._advance(final=True)

    @property
    def updates(self):
        """UpdateResult of every measurement kept, in processing order (read-only view)."""
        return self._updates

    @property
    def update_count(self):
        """Number of update results produced so far, including forgotten ones. A delayed
        measurement that re-runs the filter can make it go back."""
        return self._updates_dropped + len(self._updates)

    def updates_since(self, count):
        """The update results after the first `count` (as counted by :attr:`update_count`)."""
        return self._updates[max(count - self._updates_dropped, 0):]

    def state_at(self, t):
        """The navigation solution moved to time t (s) at the current acceleration, or None
        before the first fix. Meant for t within a sample or two of the solution's time."""
        if self.nav is None:
            return None
        return extrapolate(self.nav, t - self.nav.t, self._a_enu)

    def output(self):
        """The forward pass so far, as a :class:`NavigatorOutput`."""
        o = self._out
        full = self.config.store_covariance and len(o["P"]) > 0
        est = {name: np.array([e[name] for e in o["est"]]).reshape(len(o["t"]), size)
               for name, size in self._estimate_sizes()}
        return NavigatorOutput(
            t=np.array(o["t"]), lat=np.array(o["lat"]), lon=np.array(o["lon"]),
            h=np.array(o["h"]), v_enu=np.array(o["v"]).reshape(-1, 3),
            q_nb=np.array(o["q"]).reshape(-1, 4), mode=np.array(o["mode"]),
            P=np.array(o["P"]) if full else None, P_prior=np.array(o["Pp"]) if full else None,
            phi=np.array(o["phi"]) if full else None,
            dx=np.array(o["dx"]).reshape(len(o["t"]), self.space.size), estimates=est,
            space=self.space, updates=list(self._updates))

    # --------------------------------------------------------------------------------------
    # bookkeeping
    # --------------------------------------------------------------------------------------
    def _estimate_sizes(self):
        for name in self.space.blocks[3:]:
            yield name, (BLOCK_SIZES[name] if name in BLOCK_SIZES
                         else self.space.extras[name].size)

    def _epoch_of(self, m):
        td = self.estimates["td"][0] if "td" in self.estimates else 0.0
        return m.t - td if isinstance(m, _GNSS_TYPES) else m.t

    def _queue(self, m):
        bisect.insort(self._pending, (self._epoch_of(m), self._seq, m))
        self._seq += 1

    def _snapshot(self):
        return {"nav": self.nav, "P": self.ekf.P.copy(), "x": self.ekf.x.copy(),
                "est": {k: v.copy() for k, v in self.estimates.items()}, "mode": self.mode,
                "heading_known": self.heading_known, "t_epoch": self._t_epoch,
                "t_model": self._t_model, "F": self.ekf.F_model, "t_nhc": self._t_nhc,
                "t_last_aid": self._t_last_aid, "reject": dict(self._reject_since),
                "a": self._a_enu, "omega": self._omega,
                "omega_time": self._omega_time, "rest": self._rest_pos,
                "last_fix": self._last_fix, "speed": self._gnss_speed, "next": self._next,
                "n_out": len(self._out["t"]), "n_upd": len(self._updates),
                "n_applied": len(self._applied)}

    def _restore(self, s):
        self.nav, self.ekf.P, self.ekf.x = s["nav"], s["P"].copy(), s["x"].copy()
        self.estimates = {k: v.copy() for k, v in s["est"].items()}
        self.mode, self.heading_known = s["mode"], s["heading_known"]
        self._t_epoch, self._t_last_aid = s["t_epoch"], s["t_last_aid"]
        self._t_model, self.ekf.F_model, self._t_nhc = s["t_model"], s["F"], s["t_nhc"]
        self._reject_since = dict(s["reject"])
        self._a_enu, self._omega = s["a"], s["omega"]
        self._omega_time, self._rest_pos = s["omega_time"], s["rest"]
        self._last_fix, self._gnss_speed, self._next = s["last_fix"], s["speed"], s["next"]
        for lst in self._out.values():
            del lst[s["n_out"]:]
        del self._updates[s["n_upd"]:]
        for m in self._applied[s["n_applied"]:]:
            self._queue(m)
        del self._applied[s["n_applied"]:]
        self._snapshots = [x for x in self._snapshots if x["nav"].t <= s["nav"].t]
        self._t_snapshot = s["nav"].t

    def _trim(self, keep_min=2000):
        """Drop IMU samples no snapshot can need any more (streaming memory stays bounded)."""
        first = min([s["next"] for s in self._snapshots] + [self._next])
        if first < keep_min:
            return
        n = len(self._imu_t)
        # Moved to the front of the preallocated arrays (_append_imu) which keep their size.
        for a, name in zip(self._imu_store, self._IMU_BUFFERS):
            a[:n - first] = a[first:n]
            setattr(self, name, a[:n - first])
        self._next -= first
        for s in self._snapshots:
            s["next"] -= first

    def _keep_snapshot(self):
        if self.nav.t - self._t_snapshot < self.config.checkpoint_interval:
            return
        self._snapshots.append(self._snapshot())
        self._t_snapshot = self.nav.t
        horizon = self.nav.t - self.config.history
        drop = 0
        while drop < len(self._snapshots) - 1 and self._snapshots[drop + 1]["nav"].t < horizon:
            drop += 1
        if drop:
            del self._snapshots[:drop]
            del self._applied[:self._snapshots[0]["n_applied"]]
            base = self._snapshots[0]["n_applied"]
            for s in self._snapshots:
                s["n_applied"] -= base
            if not self.config.record:
                first = self._snapshots[0]["n_upd"]
                del self._updates[:first]
                self._updates_dropped += first
                for s in self._snapshots:
                    s["n_upd"] -= first

    # --------------------------------------------------------------------------------------
    # main loop
    # --------------------------------------------------------------------------------------
    def _advance(self, final=False):
        if self.nav is None and not self._initialise():
            return
        cfg = self.config
        n = len(self._imu_t)
        while self._next < n:
            i = self._next
            t_cov = self._t_epoch + cfg.cov_interval
            t_meas = self._pending[0][0] if self._pending else np.inf
            t_stop = min(t_cov, t_meas)
            if not final and self._imu_t[n - 1] <= t_stop:
                return  # the segment's end is not yet known (no search: the ekf node's usual case)
            j = int(np.searchsorted(self._imu_t, t_stop, side="right"))
            if j > i:
                self._segment(i, j)
            elif t_meas <= t_cov:
                self._apply_pending(self._imu_t[i])
            else:
                self._segment(i, i + 1)
        if final:
            self._apply_pending(np.inf)

    def _initialise(self):
        """Level on the IMU data before the first fix, then start the filter there."""
        cfg = self.config
        while self._pending and self.nav is None:
            epoch, _, m = self._pending[0]
            if epoch > (self._imu_t[-1] if len(self._imu_t) else -np.inf):
                return False
            self._pending.pop(0)
            k = int(np.searchsorted(self._imu_t, epoch, side="right"))
            if k > self._next:
                self._level_sum += self._imu_dv[self._next:k].sum(axis=0)
                self._level_time += (k - self._next) * float(np.median(np.diff(self._imu_t[:k]))) \
                    if k > 1 else 0.0
                self._next = k
            if isinstance(m, GnssVelocity):
                self._gnss_speed = float(np.hypot(*m.v_enu[:2]))
            if not isinstance(m, GnssFix) or self._level_time < cfg.level_time or k == 0:
                continue
            roll, pitch = level(self._level_sum / self._level_time)
            q = quat_from_euler(roll, pitch, 0.0)
            lat, lon, h = lever_arm_position(m.lat, m.lon, m.h, q, -self.lever)
            v = np.zeros(3)
            if np.isfinite(self._gnss_speed) and self._gnss_speed > cfg.static_speed:
                # Started in motion: assume no side-slip in the yaw-free frame.
                v = quat_rotate(q, [self._gnss_speed, 0.0, 0.0])
            self.nav = NavState(lat, lon, h, v, q, float(self._imu_t[k - 1]))
            self._start_filter()
        if self.nav is None and not self._pending and len(self._imu_t):
            self._forget_unlevelled()
        return self.nav is not None

    def _forget_unlevelled(self):
        """Without a measurement to start on, keep only the samples of the last ``history``
        (at least ``level_time``) seconds: the first fix is levelled on the samples before it,
        and a receiver without a fix for hours (a ship at the pier) must not fill the memory
        with IMU data. Older samples are passed over and the levelling starts afresh after
        them; :meth:`_trim` then drops them."""
        cfg = self.config
        horizon = self._imu_t[-1] - max(cfg.history, cfg.level_time)
        k = int(np.searchsorted(self._imu_t, horizon, side="right"))
        if k > self._next:
            self._next = k
            self._level_sum = np.zeros(3)
            self._level_time = 0.0

    def _start_filter(self):
        cfg = self.config
        sig = np.zeros(self.space.size)
        S = self.space
        sig[S["pos"]] = cfg.sigma_pos0
        sig[S["vel"]] = cfg.sigma_vel0
        # The yaw is unknown until the first motion or heading fix: its variance is kept out
        # of the filter (set by the heading alignment) so that no update leans on it.
        sig[S["att"]] = [cfg.sigma_tilt0, cfg.sigma_tilt0, 0.0]
        for name in self.space.blocks[3:]:
            if name in self.space.extras:
                sig[S[name]] = self.space.extras[name].sigma0
            elif name == "clock":
                sig[S[name]] = (3e5, 100.0, 0.1)
            else:
                sig[S[name]] = cfg.noise.blocks[name].sigma0
        P0 = np.diag(sig ** 2)
        self.ekf = ErrorStateEKF(self.space, cfg.noise, P0)
        self.mode = ALIGNING
        self._t_epoch = self.nav.t
        self._record(np.eye(self.space.size), P0)

    def _compensate(self, th, dv, dts):
        est = self.estimates
        bg = sum(est[b] for b in _GYRO_BIAS if b in est)
        ba = sum(est[b] for b in _ACCEL_BIAS if b in est)
        th = th - np.multiply.outer(dts, bg) if np.ndim(bg) else th
        dv = dv - np.multiply.outer(dts, ba) if np.ndim(ba) else dv
        # measured = (I + S) true + bias  ->  true = (I + S)^-1 (measured - bias).
        if "sg" in est:
            th = th / (1.0 + est["sg"])
        if "sa" in est:
            dv = dv / (1.0 + est["sa"])
        return th, dv

    def _segment(self, i, j):
        """Mechanise samples i..j-1 and propagate the covariance to the end of the segment."""
        t = self._imu_t[i:j]
        # The state time is the end of the last processed sample (filled in place: np.diff
        # with prepend and np.clip cost more than the arithmetic here).
        dts = np.empty(j - i)
        dts[0] = t[0] - self.nav.t
        np.subtract(t[1:], t[:-1], out=dts[1:])
        np.maximum(dts, 1e-6, out=dts)
        th, dv = self._compensate(self._imu_th[i:j], self._imu_dv[i:j], dts)
        rot = th + self._imu_cth[i:j]
        dvn = dv + self._imu_cdv[i:j]
        T = float(dts.sum())
        start = self.nav
        r = run(start, rot, dvn, T / len(t))
        self.nav = NavState(r["lat"][-1], r["lon"][-1], r["h"][-1], r["v_enu"][-1],
                            r["q_nb"][-1], float(t[-1]))
        self._a_enu = (self.nav.v_enu - start.v_enu) / T
        self._omega = th.sum(axis=0) / T
        self._omega_time = T
        f_b = dv.sum(axis=0) / T
        # F is rebuilt every cov_interval; shorter segments (cut by measurement epochs) reuse it.
        refresh = start.t - self._t_model >= self.config.cov_interval - 1e-9
        if refresh:
            self._t_model = start.t
        phi = self.ekf.predict(start, f_b, self._omega, T, refresh)
        if self._gaps:
            self._add_gap_noise(start.t, self.nav.t)
        for name in ("gmg", "gma"):
            if name in self.estimates:
                self.estimates[name] *= np.exp(-T / self.config.noise.blocks[name].tau)
        if "clock" in self.estimates:
            # The receiver clock runs on between updates: offset, drift and drift rate follow
            # the same model as their errors (seed 004 section 2.4; error_model.system_matrix).
            c = self.estimates["clock"]
            self.estimates["clock"] = np.array([c[0] + c[1] * T + 0.5 * c[2] * T * T,
                                                c[1] + c[2] * T, c[2]])
        self._next = j
        self._t_epoch = self.nav.t
        P_prior = self.ekf.P.copy()
        self._record(phi, P_prior)
        if self.mode != ALIGNING:
            if self.config.nhc_sigma is not None \
                    and self.nav.t - self._t_nhc >= self.config.nhc_interval - 1e-9:
                self._t_nhc = self.nav.t
                # An unknown distance to the rear axle turns the yaw rate into lateral
                # velocity at the IMU: widen the lateral noise with the rate.
                sigma_lat = np.hypot(self.config.nhc_sigma[0],
                                     self.config.nhc_rate_arm * self._omega[2])
                self._update(meas.nonholonomic(self.space, self.nav, sigma_lat,
                                               self.config.nhc_sigma[1],
                                               self._omega, self.config.nhc_lever_b,
                                               self.estimates.get("nhc", np.zeros(2))),
                             self.nav.t, aiding=False)
            if self.nav.t - self._t_last_aid > self.config.dr_timeout:
                self.mode = DEAD_RECKONING
                if self.config.record:
                    self._out["mode"][-1] = self.mode
        self._keep_snapshot()

    def _record(self, phi, P_prior):
        if not self.config.record:
            return
        o = self._out
        o["t"].append(self.nav.t)
        o["lat"].append(self.nav.lat)
        o["lon"].append(self.nav.lon)
        o["h"].append(self.nav.h)
        o["v"].append(self.nav.v_enu)
        o["q"].append(self.nav.q_nb)
        o["mode"].append(self.mode)
        o["dx"].append(np.zeros(self.space.size))
        o["est"].append({k: v.copy() for k, v in self.estimates.items()})
        if self.config.store_covariance:
            o["P"].append(self.ekf.P.copy())
            o["Pp"].append(P_prior)
            o["phi"].append(phi)

    def _rerecord(self, dx):
        """Replace the current epoch's record by the corrected state (after an update)."""
        if not self.config.record:
            return
        o = self._out
        o["lat"][-1], o["lon"][-1], o["h"][-1] = self.nav.lat, self.nav.lon, self.nav.h
        o["v"][-1], o["q"][-1], o["mode"][-1] = self.nav.v_enu, self.nav.q_nb, self.mode
        o["dx"][-1] = o["dx"][-1] + dx
        o["est"][-1] = {k: v.copy() for k, v in self.estimates.items()}
        if self.config.store_covariance:
            o["P"][-1] = self.ekf.P.copy()

    # --------------------------------------------------------------------------------------
    # measurements
    # --------------------------------------------------------------------------------------
    def _apply_pending(self, t_next):
        """Apply every pending measurement whose epoch lies before the next sample's end."""
        while self._pending and self._pending[0][0] < t_next:
            _, _, m = self._pending.pop(0)
            self._applied.append(m)
            # The epoch with the latest time-offset estimate (it may have moved since the
            # measurement was queued; the difference is a fraction of a second).
            epoch = self._epoch_of(m)
            if epoch < self.nav.t - self.config.cov_interval - 0.5:
                # Queued before the filter started and older than its first epoch.
                self._updates.append(rejected(type(m).__name__, epoch, np.zeros(0),
                                              np.zeros((0, 0)), "too old"))
                continue
            self._measure(m, extrapolate(self.nav, epoch - self.nav.t, self._a_enu), epoch)

    def _measure(self, m, st, epoch):
        cfg, S = self.config, self.space
        if isinstance(m, GnssVelocity):
            self._gnss_speed = float(np.hypot(*np.asarray(m.v_enu)[:2]))
            if self.mode == ALIGNING and not self.heading_known \
                    and self._gnss_speed >= cfg.align_speed:
                self._align_to_motion(np.asarray(m.v_enu, float))
                st = extrapolate(self.nav, st.t - self.nav.t, self._a_enu)
        at_rest = self._gnss_speed <= cfg.static_speed
        if self.mode == ALIGNING and not self.heading_known and isinstance(m, _GNSS_TYPES) \
                and not at_rest:
            self._updates.append(rejected(type(m).__name__, epoch, np.zeros(0), np.zeros((0, 0)),
                                          "aligning"))
            return
        if isinstance(m, GnssFix):
            v_ant = lever_arm_velocity(st.v_enu, st.q_nb, self._omega, self.lever, st.lat)
            innov = meas.gnss_position(S, st, m.lat, m.lon, m.h, m.cov_enu, self.lever,
                                       dzdt=v_ant)
            if at_rest and not self.heading_known:
                self._rest_pos = (st.lat, st.lon, st.h)
            fix = (m.lat, m.lon, m.h)
            frozen = fix == self._last_fix and np.linalg.norm(v_ant) > cfg.frozen_speed
            self._last_fix = fix
            if frozen:
                self._updates.append(rejected("gnss_pos", epoch, innov.z, innov.R, "frozen"))
                return
        elif isinstance(m, GnssVelocity):
            innov = meas.gnss_velocity(S, st, m.v_enu, m.cov_enu, self._omega, self.lever,
                                       dzdt=self._a_enu)
            if at_rest and cfg.zaru_sigma is not None:
                # At rest the gyros see only the Earth rate: their biases become observable
                # (while aligning, the unknown yaw hides the horizontal Earth rate, hence the
                # added Omega cos(lat) term).
                T = self._omega_time
                sigma = np.sqrt(cfg.noise.gyro_psd / T + cfg.zaru_sigma ** 2)
                if not self.heading_known:
                    sigma = np.hypot(sigma, EARTH_RATE * np.cos(st.lat))
                self._update(meas.zero_angular_rate(S, st, self._omega, sigma), epoch,
                             aiding=False)
        elif isinstance(m, HeadingFix):
            if not self.heading_known:
                yaw = np.pi / 2.0 - m.azimuth
                x = quat_to_dcm(self.nav.q_nb)[:, 0]
                self._rotate_yaw(yaw - np.arctan2(x[1], x[0]), np.sqrt(m.variance))
                return
            if m.magnetic:
                bias = self.estimates["mag"][0] if "mag" in self.estimates else 0.0
                innov = meas.magnetic_heading(S, st, m.azimuth, m.variance, bias)
            else:
                innov = meas.heading(S, st, m.azimuth, m.variance)
        elif isinstance(m, SpeedLog):
            log = self.estimates.get("log", np.zeros(3))
            innov = meas.speed_log(S, st, m.speed, m.variance, log[:2], log[2])
        elif isinstance(m, ZeroVelocity):
            self._update(meas.zero_velocity(S, st, m.sigma_v), epoch)
            if m.sigma_w is not None:
                self._update(meas.zero_angular_rate(S, st, self._omega, m.sigma_w), epoch)
            return
        elif isinstance(m, SatelliteRanges):
            clock = self.estimates.get("clock", np.zeros(3))
            self._update(meas.pseudoranges(S, st, m.sat_pos, m.sat_clock, m.pseudorange,
                                           m.pr_var, clock[0], self.lever), epoch)
            if m.range_rate is not None:
                self._update(meas.range_rates(S, st, m.sat_pos, m.sat_vel, m.sat_clock_drift,
                                              m.range_rate, m.rr_var, self._omega, clock[1],
                                              self.lever), epoch)
            return
        else:
            raise TypeError(f"unknown measurement {type(m).__name__}")
        self._update(innov, epoch)

    def _update(self, innov, epoch, aiding=True):
        """Gate and apply one measurement; force its kind in after `max_reject_time` s of
        continuous rejection.

        With one source of each kind, a diverged filter and a measurement gone wrong (a GNSS
        step, a spoofed position, a clock jump) look the same: a sustained innovation nu beyond
        the gate. Forcing admits nu on both sides. The directly measured state blocks are
        widened by nu^2 before the update (the INS may be wrong: the update then follows the
        measurement), and the kind gets a noise floor F = nu^2 (the measurement may be wrong),
        treated like an unobserved constant bias of the measurement (a "consider" parameter):

        * :meth:`covariance`, the covariance to publish, adds F to the blocks the kind measures,
          and repeated measurements cannot average it away;
        * a measurement beyond the gate but within the gate of H P H^T + R + F is forced in
          at once, in the same way: a measurement that returns to the INS after a transient
          fault is followed again without a second 2 s wait;
        * the gain keeps the nominal R: when the INS was the one that diverged (the usual case,
          e.g. after a GNSS outage on a real drive) the filter's accuracy is that of the
          nominal filter (a first version that also inflated R in the gain and held P at F
          took the real car drive's smoothed outage error from 0.52 to 21.9 m at worst;
          docs/results/faults.md).

        The floors and the rejection times are not part of the snapshots for delayed
        measurements: a re-run keeps the current ones (a floor is only ever conservative).

        F decays by exp(-dt / floor_tau) over the time the kind is accepted (not while it is
        rejected); while it exceeds degraded_ratio^2 times the kind's own variance, the mode
        is DEAD_RECKONING (degraded: the solution is not confirmed by its aiding). So it is
        while an aiding kind keeps being rejected for `suspect_time` before it is forced: the
        other kinds may still be accepted (a GNSS clock jump shifts the velocities a little and
        the positions a lot), but the solution and the rejected kind disagree.
        """
        cfg = self.config
        since = self._reject_since.get(innov.name)
        force = since is not None and epoch - since > cfg.max_reject_time
        floor = self._floors.get(innov.name)
        if not force and floor is not None and cfg.gate_prob is not None:
            force = self._within_floor(innov, floor)
        if force:
            self._force_floor(innov, epoch)
            floor = self._floors[innov.name]
        res = self.ekf.update(innov.name, epoch, innov.z, innov.H, innov.R, cfg.gate_prob, force)
        if force:  # the widened covariance usually passes the gate: say why it was needed
            res = replace(res, reason="forced")
        if aiding:
            self._updates.append(res)
        if floor is not None:
            if res.accepted and not force:
                floor["var"] = floor["var"] * np.exp(-max(epoch - floor["t"], 0.0)
                                                     / cfg.floor_tau)
            floor["t"], floor["r"] = epoch, float(np.max(np.diag(innov.R)))
            if np.max(floor["var"]) < 1e-2 * floor["r"]:
                del self._floors[innov.name]  # negligible beside the measurement's own noise
        if not res.accepted:
            self._reject_since.setdefault(innov.name, epoch)
            if aiding:
                first = self._rejecting.get(innov.name, (epoch, epoch))[0]
                self._rejecting[innov.name] = (first, epoch)
                if self.mode == NAVIGATING and self._degraded(epoch):
                    self.mode = DEAD_RECKONING
            return res
        self._reject_since.pop(innov.name, None)
        self._rejecting.pop(innov.name, None)
        self._feedback()
        self.revision += 1
        if aiding:
            self._t_last_aid = epoch
            if self.mode != ALIGNING:
                self.mode = DEAD_RECKONING if self._degraded(epoch) else NAVIGATING
        return res

    def _within_floor(self, innov, floor):
        """Beyond the gate of H P H^T + R, but within that of H P H^T + R + F (the floor)."""
        nu = innov.z - innov.H @ self.ekf.x
        S = innov.H @ self.ekf.P @ innov.H.T + innov.R
        gate = chi2_gate(len(nu), self.config.gate_prob)
        if normalised_innovation(nu, 0.5 * (S + S.T)) <= gate:
            return False
        S = S + np.diag(self._floor_variance(floor, len(nu)))
        return normalised_innovation(nu, 0.5 * (S + S.T)) <= gate

    def covariance(self):
        """The covariance to publish: the filter's P plus, on the state blocks each forced
        measurement kind measures directly, the noise floor it keeps (see :meth:`_update`)."""
        P = self.ekf.P
        if not self._floors:
            return P
        P = P.copy()
        for floor in self._floors.values():
            for name in floor["blocks"]:
                s = self.space[name]
                P[s, s] += np.diag(self._floor_variance(floor, 3))
        return P

    def _degraded(self, epoch):
        """A forced kind's noise floor is still large, or an aiding kind is being rejected for
        `suspect_time` (see :meth:`_update`)."""
        cfg = self.config
        ratio2 = cfg.degraded_ratio ** 2
        return any(np.max(f["var"]) > ratio2 * f["r"] for f in self._floors.values()) or any(
            epoch - first >= cfg.suspect_time and epoch - last <= cfg.suspect_time
            for first, last in self._rejecting.values())

    def _force_floor(self, innov, epoch):
        """Widen the blocks `innov` measures directly by its innovation and set its kind's floor."""
        nu2 = (innov.z - innov.H @ self.ekf.x) ** 2
        blocks = []
        for name in ("pos", "vel"):
            block = innov.H[:, self.space[name]]
            if block.shape[0] == 3 and np.allclose(block, np.eye(3)):
                s = self.space[name]
                blocks.append(name)
                self.ekf.P[s, s] += np.diag(nu2)
                if self.config.store_covariance:
                    # Process noise of this epoch as far as the smoother is concerned.
                    self._out["Pp"][-1][s, s] += np.diag(nu2)
        old = self._floors.get(innov.name)
        if old is not None:
            nu2 = np.maximum(nu2, self._floor_variance(old, len(nu2)))
        self._floors[innov.name] = {"var": nu2, "t": epoch, "blocks": blocks,
                                    "r": float(np.max(np.diag(innov.R)))}

    @staticmethod
    def _floor_variance(floor, m):
        """The floor as m variances (a kind whose dimension varies, e.g. pseudoranges, gets the
        largest one on every component)."""
        var = floor["var"]
        return var if len(var) == m else np.full(m, np.max(var))

    def _add_gap_noise(self, t0, t1):
        """Process noise of the held-rate error over the part of [t0, t1] (s) that lies in a
        bridged gap (:meth:`add_bridged_gap`).

        Holding the rates of one increment over a gap of T s misses the true specific force and
        rate by up to gap_accel_sigma and gap_rate_sigma. The miss is modelled as white noise of
        PSD sigma^2 T over the gap: over the whole gap it adds the variance (sigma T)^2 of a
        constant miss to the velocity and attitude, and the propagation carries the velocity
        part into position (sigma^2 T^4 / 3). Unlike a constant miss, it grows with the time
        spent in the gap (GNSS epochs inside the gap are applied against the part accrued so
        far) and does not tie position to velocity exactly: with a constant miss (position =
        velocity T / 2) one velocity fix after a 1.9 s gap took the position sigma from 1.9 m to
        0.09 m while the real error was 0.6 m (docs/results/faults.md).
        """
        cfg, S, P = self.config, self.space, self.ekf.P
        for g0, g1 in self._gaps:
            inside = min(t1, g1) - max(t0, g0)
            if inside <= 0.0:
                continue
            T = g1 - g0
            qw = np.full(3, cfg.gap_rate_sigma ** 2 * T * inside)
            if not self.heading_known:
                qw[2] = 0.0  # the yaw stays out of the filter until the heading alignment
            P[S["vel"], S["vel"]] += cfg.gap_accel_sigma ** 2 * T * inside * np.eye(3)
            P[S["att"], S["att"]] += np.diag(qw)

    def _feedback(self):
        dx = self.ekf.take_correction()
        S = self.space
        self.nav = apply_correction(self.nav, dx[S["pos"]], dx[S["vel"]], dx[S["att"]])
        for name in self.estimates:
            self.estimates[name] = self.estimates[name] + dx[S[name]]
        self._rerecord(dx)

    def _align_to_motion(self, v_gnss):
        """Rotate the yaw-free solution about the vertical onto the GNSS course.

        The INS has run levelled but with an arbitrary yaw since the first fix, so its
        horizontal velocity is the true one rotated by minus the yaw error: the angle between the
        two velocity vectors is that error (no side-slip assumption). If the INS velocity is
        too small to compare (motion started before the filter), the course of the GNSS velocity
        is taken as the heading of the body x axis instead.
        """
        v_ins = self.nav.v_enu
        speed = np.hypot(*v_gnss[:2])
        if np.hypot(*v_ins[:2]) > 0.3 * speed:
            delta = np.arctan2(v_gnss[1], v_gnss[0]) - np.arctan2(v_ins[1], v_ins[0])
        else:
            x = quat_to_dcm(self.nav.q_nb)[:, 0]
            delta = np.arctan2(v_gnss[1], v_gnss[0]) - np.arctan2(x[1], x[0])
        sigma_v = np.sqrt(self.ekf.P[self.space["vel"].start, self.space["vel"].start])
        self._rotate_yaw(delta, 2.0 * sigma_v / speed)

    def _rotate_yaw(self, delta, sigma):
        """Turn attitude and velocity by delta (rad) about Up; the yaw variance becomes
        max(sigma, sigma_yaw_align)^2, uncorrelated; the mode becomes NAVIGATING."""
        rz = quat_from_rotvec([0.0, 0.0, delta])
        if self._rest_pos is not None:
            # The distance run since the vehicle left its rest position went the wrong way too.
            d = meas.position_residual_enu(self.nav.lat, self.nav.lon, self.nav.h,
                                           *self._rest_pos)
            self.nav = apply_correction(self.nav, d - quat_rotate(rz, d), np.zeros(3),
                                        np.zeros(3))
        self.nav = replace(self.nav, q_nb=quat_normalize(quat_mul(rz, self.nav.q_nb)),
                           v_enu=quat_rotate(rz, self.nav.v_enu))
        # The ENU-resolved errors turn with the solution (C' = Rz (I - [phi x]) C =
        # (I - [(Rz phi) x]) Rz C): rotate their covariance, including the correlations of the
        # tilt with the accelerometer biases that levelling built up.
        T = np.eye(self.space.size)
        R = quat_to_dcm(rz)
        for name in ("pos", "vel", "att"):
            T[self.space[name], self.space[name]] = R
        self.ekf.P = T @ self.ekf.P @ T.T
        k = self.space["att"].stop - 1
        P = self.ekf.P
        P[k, :] = 0.0
        P[:, k] = 0.0
        P[k, k] = max(self.config.sigma_yaw_align, sigma) ** 2
        if "bg" in self.space:
            # While the yaw was unknown the mechanisation removed the horizontal Earth rate in
            # the wrong direction and the filter took the difference for gyro bias: widen the
            # bias uncertainty by that rate (up to Omega cos(lat) on any axis).
            s = self.space["bg"]
            P[s, s] += (EARTH_RATE * np.cos(self.nav.lat)) ** 2 * np.eye(3)
        self.heading_known = True
        self.mode = NAVIGATING
        self._t_last_aid = self.nav.t
        self._rerecord(np.zeros(self.space.size))
