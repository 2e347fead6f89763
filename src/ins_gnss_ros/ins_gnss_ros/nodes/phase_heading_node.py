"""``phase_heading`` node: heading, pitch (and roll) from carrier-phase differences between 2-4
antennas (seed 004 §1.3b-c and §2.7, the ISON-1/ISON-2 interferometric attitude).

Per GNSS epoch the node

1. groups ``gnss/observations`` of all antennas by GNSS time (receiver week + time of week,
   within ``epoch_tolerance_s``): an epoch is solved once every antenna has reported, or
   skipped (said on /diagnostics) when a later epoch completes first or it is older than
   ``max_latency_s`` behind the newest observation; late and duplicated observations are dropped;
2. computes every satellite's line of sight (ENU) from the broadcast ephemeris
   (``gnss/ephemeris``, IS-GPS-200 Table 20-IV via :mod:`ins_gnss_ros.gnss.ephemeris`) at the
   master antenna's position: ``ins/state`` or ``gnss/fix`` when fresh, else the single-point
   solution of the master antenna's own pseudoranges (:mod:`ins_gnss_ros.gnss.spp`); a position
   error of 1 km tilts a line of sight by only 5e-5 rad, so any of them will do;
3. runs the phase-attitude core :class:`~ins_gnss_ros.gnss.attitude.AttitudeSolver` (cycle-slip
   detection, double differences, length-constrained LAMBDA with ratio test, held ambiguities),
   with the INS attitude as an a-priori baseline when ``ins/state`` is recent and navigating
   (seed 004's tightly-coupled phase processing: it shrinks the ambiguity search), or only its
   roll and pitch, as an a-priori up component of the baselines, while the INS heading is not
   known (``ins/state`` ALIGNING, the ekf's ``nav/status`` ALIGNING or its heading σ above
   ``ins_prior.sigma_deg``, or ``ins_prior.heading`` false): an INS levels itself from its
   accelerometers in seconds, and the up component removes the weak vertical of the GNSS
   geometry from the search, where wrong candidates from few double differences hide; with 2
   antennas a fix from scratch from fewer than 6 double differences is held once the same
   integers passed the ratio test at ``fix_confirm_epochs`` consecutive epochs, with 3-4
   antennas the fixed baselines must fit the antenna geometry under one attitude (the core's
   rigid-body test); a FIXED attitude with pitch or roll beyond ``max_tilt_deg`` is a wrong
   fix: the ambiguities are dropped and nothing usable is published;
4. publishes ``gnss/heading`` (ins_gnss_msgs/Heading, source PHASE_DIFFERENCE, reference TRUE):
   azimuth of the body x axis, pitch nose-up positive (the message's convention: the negative of
   the core's ROS pitch), roll (NaN with one baseline), their variances, the master→antenna-1
   baseline length, satellites used, the smallest ratio of the fixes in use and the status.
   The FIXED variances include the time-correlated multipath (``multipath.*``: σ(E) = σ0
   exp(-E/E0), correlation time τ), once by default (the variance of one epoch), or, with
   ``multipath.averaging_time_s`` T > 0, as many times as makes the average over T of epochs
   taken as independent honest (up to 2τ/Δt for T ≫ τ;
   :func:`~ins_gnss_ros.gnss.attitude.correlated_variance_factor`).
   FIXED always; FLOAT only with ``publish_float`` (with the float solution's own variance,
   degrees rather than tenths); otherwise, with ``publish_none``, a status-NONE message with NaN
   angles so that consumers see the node is alive.

Antenna positions are parameters in the frame of the antenna mount; ``mounting_rpy_deg`` rotates
that frame into base_link (a calibration such as
:func:`~ins_gnss_ros.gnss.attitude.estimate_mounting` gives), so the published angles are those of
base_link.
"""

from __future__ import annotations

import math
import sys
from collections import Counter
from dataclasses import dataclass

import numpy as np
from diagnostic_msgs.msg import DiagnosticStatus
from ins_gnss_msgs.msg import FilterStatus, GnssEphemeris, GnssObservations, Heading, InsState
from sensor_msgs.msg import NavSatFix, NavSatStatus

from ..gnss.attitude import AttitudeSolution, AttitudeSolver
from ..gnss.constants import BEIDOU, C_LIGHT, GALILEO, GPS, SECONDS_PER_WEEK, UBX_GNSS_ID
from ..gnss.differences import AntennaEpoch, NoiseModel
from ..gnss.ephemeris import KeplerEphemeris, satellite_at_reception
from ..gnss.multipath import MultipathModel
from ..gnss.observations import RawEpoch
from ..gnss.spp import DEFAULT_SIGNALS, SppConfig, solve_position
from ..io import stamp_to_sec
from ..nav.earth import ecef_to_enu_matrix, ecef_to_geodetic, geodetic_to_ecef
from ..nav.rotations import dcm_from_euler, quat_normalize, quat_to_dcm
from .base import SENSOR_QOS, STATE_QOS, NavNode, Param, ParameterError, run
from .convert import quat
from .gnss_convert import kepler_from_msg, raw_epoch_from_msg

#: Half-width of the interval around toe in which a broadcast orbit is used [s]: the 4 h fit
#: interval of IS-GPS-200 §20.3.4.4 (a line of sight tolerates far worse orbits than ranging).
EPHEMERIS_HALF_WIDTH_S = 7200.0
#: Nominal signal travel time when the master antenna has no pseudorange for a satellite [s].
NOMINAL_TRAVEL_S = 0.075
#: Systems the node can use: their Keplerian ephemerides are supported (GLONASS FDMA signals form
#: no integer double differences across frequency slots, see gnss/differences.py).
SYSTEM_PARAMS = {"gps": GPS, "galileo": GALILEO, "beidou": BEIDOU}


@dataclass
class ParsedEpoch:
    """One antenna's observations of the used systems, as the core and the SPP take them."""

    antenna: AntennaEpoch
    raw: RawEpoch


def signal_id(sat_id: str, code: str) -> str:
    """Core signal id: the satellite id for the system's primary signal (the one the SPP uses),
    else satellite id + RINEX code ("G05", "G05_2L")."""
    return sat_id if code == DEFAULT_SIGNALS.get(sat_id[0], ("",))[0] else f"{sat_id}_{code}"


def parse_observations(msg: GnssObservations, systems) -> ParsedEpoch | None:
    """The signals of ``systems`` in a GnssObservations as the phase core's AntennaEpoch and the
    RawEpoch; None if its arrays are inconsistent (see :func:`.gnss_convert.raw_epoch_from_msg`)."""
    parsed = raw_epoch_from_msg(msg, systems)
    if parsed is None:
        return None
    raw, kept = parsed
    obs = raw.obs
    ids = [signal_id(f"{o.system}{o.prn:02d}", o.signal) for o in obs]
    return ParsedEpoch(AntennaEpoch(
        ids, np.array([o.carrier_cycles for o in obs]), np.array([o.pseudorange_m for o in obs]),
        np.array([C_LIGHT / o.frequency_hz for o in obs]), np.array([o.doppler_hz for o in obs]),
        np.array([bool(msg.loss_of_lock[i]) for i in kept], bool)), raw)


def lines_of_sight(master: ParsedEpoch, ephemerides: dict, t_gps: float, rx_xyz) -> dict:
    """Unit line of sight (ENU at ``rx_xyz``) to the satellite of every master signal with an
    ephemeris, keyed by signal id. The satellite is taken at transmission, in the ECEF frame of
    reception (Sagnac, Groves eq. 8.36), from the master's pseudorange."""
    rx = np.asarray(rx_xyz, float)
    lat, lon, _ = ecef_to_geodetic(rx)
    rot = ecef_to_enu_matrix(lat, lon)
    out, per_sat = {}, {}
    for sid, pr in zip(master.antenna.signal_ids, master.antenna.pseudorange):
        sat = sid[:3]
        eph = ephemerides.get(sat)
        if eph is None:
            continue
        if sat not in per_sat:
            rng = pr if np.isfinite(pr) else NOMINAL_TRAVEL_S * C_LIGHT
            xyz = satellite_at_reception(eph, t_gps, rng, rx)[0]
            e = rot @ (xyz - rx)
            per_sat[sat] = e / np.linalg.norm(e)
        out[sid] = per_sat[sat]
    return out


def heading_msg(sol: AttitudeSolution, stamp, publish_float: bool) -> Heading:
    """ins_gnss_msgs/Heading of a core solution (NaN angles unless FIXED, or FLOAT allowed)."""
    msg = Heading(reference=Heading.REFERENCE_TRUE, source=Heading.SOURCE_PHASE_DIFFERENCE,
                  azimuth=math.nan, pitch=math.nan, roll=math.nan, azimuth_variance=math.nan,
                  pitch_variance=math.nan, roll_variance=math.nan, declination=0.0,
                  baseline_length=math.nan, status=Heading.STATUS_NONE,
                  satellites_used=len({s[:3] for s in sol.satellites}),
                  ambiguity_ratio=float(sol.ratio))
    msg.header.stamp = stamp
    msg.header.frame_id = "base_link"
    usable = sol.status == "FIXED" or (sol.status == "FLOAT" and publish_float)
    if usable and np.isfinite(sol.azimuth):
        msg.status = Heading.STATUS_FIXED if sol.status == "FIXED" else Heading.STATUS_FLOAT
        msg.azimuth = float(sol.azimuth)
        # Heading.pitch is nose-up positive; the core's (ROS) pitch is nose-down positive.
        msg.pitch = -float(sol.pitch)
        msg.roll = float(sol.roll)      # both right side down positive
        msg.azimuth_variance = float(sol.var_azimuth)
        msg.pitch_variance = float(sol.var_pitch)
        msg.roll_variance = float(sol.var_roll)
        msg.baseline_length = float(np.linalg.norm(sol.baselines[0]))
    return msg


class PhaseHeadingNode(NavNode):
    PARAMS = (
        Param("antenna_positions", [0.75, 0.0, 1.0, -0.75, 0.0, 1.0],
              "antenna phase centres in the mount frame (FLU), m, 3 values per antenna, 2-4 "
              "antennas; antenna_id = index, antenna 0 is the master", -100.0, 100.0),
        Param("mounting_rpy_deg", [0.0, 0.0, 0.0],
              "rotation of the antenna mount frame in base_link, ROS roll, pitch, yaw (baseline "
              "mounting offsets), deg", -180.0, 180.0, length=3),
        Param("noise.phase_m", 0.002,
              "undifferenced carrier-phase noise a = b in sigma^2 = a^2 + b^2/sin^2(E), m",
              1e-4, 0.05),
        Param("noise.code_m", 0.3, "undifferenced pseudorange noise a = b, m", 0.01, 100.0),
        Param("multipath.phase_m", 0.01,
              "time-correlated (multipath) phase error sigma at 0 deg elevation, m; it "
              "falls by e every multipath.elevation_scale_deg; 0: none (white variances)",
              0.0, 0.05),
        Param("multipath.elevation_scale_deg", 20.0,
              "elevation over which the multipath sigma falls by e, deg", 1.0, 90.0),
        Param("multipath.tau_s", 30.0, "multipath correlation time, s", 0.1, 3600.0),
        Param("multipath.averaging_time_s", 0.0,
              "time over which the heading consumer (a filter taking every epoch as independent) "
              "averages it, s: the multipath variance is counted so that this average is "
              "honest; 0: once (per-epoch variance, for a MEMS-class ekf); for a FOG-class ekf "
              "that holds the heading for minutes, 10 tau or more", 0.0, 1.0e6),
        Param("ratio_threshold", 3.0,
              "ratio test threshold to accept a fix (5 with fewer than ~7 double differences "
              "per baseline or time-correlated multipath)", 1.0, 100.0),
        Param("baseline_length_sigma_m", 0.002,
              "uncertainty of the known baseline lengths, m", 1e-4, 0.1),
        Param("elevation_mask_deg", 10.0, "elevation mask, deg", 0.0, 60.0),
        Param("gps", True, "use GPS"),
        Param("galileo", True, "use Galileo"),
        Param("beidou", False, "use BeiDou (MEO/IGSO)"),
        Param("float_window", 5,
              "epochs accumulated in the float solution before the first fix (1: single epoch)",
              1, 100),
        Param("fix_confirm_epochs", 2,
              "with 2 antennas, a fix from scratch from fewer than 6 double differences is held "
              "(and published) once the same integers have passed the ratio test at this many "
              "consecutive epochs (1: at once)", 1, 50),
        Param("slip_threshold_cycles", 1.0,
              "phase minus integrated Doppler threshold of the slip test, cycles", 0.1, 100.0),
        Param("max_gap_s", 5.0, "longest epoch gap over which slips are tested and ambiguities "
              "held, s", 0.1, 600.0),
        Param("max_tilt_deg", 40.0,
              "largest pitch and roll the platform can have, deg: a FIXED solution beyond is a "
              "wrong fix (ambiguities dropped)", 1.0, 90.0),
        Param("publish_float", False,
              "publish FLOAT solutions (status FLOAT, with the float variance); false: not used"),
        Param("publish_none", True,
              "publish a status-NONE Heading (NaN angles) for epochs without a usable solution"),
        Param("epoch_tolerance_s", 0.005,
              "observations of different antennas within this of each other are one epoch, s",
              1e-6, 0.5),
        Param("max_latency_s", 0.5,
              "an epoch still missing an antenna this long after the newest observation is "
              "skipped, s", 0.0, 60.0),
        Param("position_max_age_s", 30.0,
              "ins/state or gnss/fix older than this is not used for the lines of sight (own "
              "single-point solution instead), s", 0.0, 3600.0),
        Param("ins_prior.enabled", True,
              "use the ins/state attitude as an a-priori baseline for the ambiguity search"),
        Param("ins_prior.sigma_deg", 2.0, "1-sigma attitude error assumed for ins/state, deg",
              0.01, 90.0),
        Param("ins_prior.heading", True,
              "use the ins/state heading too (the whole attitude, ins_prior.sigma_deg) when it "
              "is known; false: roll and pitch only (ins_prior.tilt_sigma_deg)"),
        Param("ins_prior.tilt_sigma_deg", 0.5,
              "1-sigma roll and pitch error assumed for ins/state when only its tilt is used "
              "(a larger one from the ekf's nav/status is taken instead), deg", 0.01, 10.0),
        Param("ins_prior.max_age_s", 0.2,
              "largest stamp difference between an epoch and the ins/state used, s", 0.0, 10.0),
    )

    def __init__(self, **kwargs):
        super().__init__("phase_heading", **kwargs)
        p = self.p
        pos = p["antenna_positions"]
        if len(pos) % 3 or not 2 <= len(pos) // 3 <= 4:
            raise ParameterError("parameter 'antenna_positions': 6, 9 or 12 values (2-4 "
                                 f"antennas) expected, got {len(pos)}")
        mount = dcm_from_euler(*np.radians(p["mounting_rpy_deg"]))
        self.antennas = np.asarray(pos, float).reshape(-1, 3) @ mount.T
        if np.min(np.linalg.norm(self.antennas[1:] - self.antennas[0], axis=1)) < 0.05:
            raise ParameterError("parameter 'antenna_positions': every antenna must be at least "
                                 "5 cm from the master")
        self._check_geometry(self.antennas)
        self.systems = {s for name, s in SYSTEM_PARAMS.items() if p[name]}
        if not self.systems:
            raise ParameterError("parameters 'gps', 'galileo', 'beidou': enable at least one")
        noise = NoiseModel(p["noise.phase_m"], p["noise.phase_m"], p["noise.code_m"],
                           p["noise.code_m"])
        multipath = (MultipathModel(0.0, p["multipath.phase_m"],
                                    math.radians(p["multipath.elevation_scale_deg"]),
                                    phase_tau=p["multipath.tau_s"])
                     if p["multipath.phase_m"] > 0.0 else None)
        self.solver = AttitudeSolver(
            self.antennas, noise,
            ratio_threshold=p["ratio_threshold"], sigma_length=p["baseline_length_sigma_m"],
            elevation_mask=math.radians(p["elevation_mask_deg"]),
            slip_threshold=p["slip_threshold_cycles"], max_gap=p["max_gap_s"],
            window=p["float_window"], confirm_epochs=p["fix_confirm_epochs"],
            multipath=multipath,
            averaging_time=p["multipath.averaging_time_s"])
        self.pending: dict[float, dict] = {}     # epoch GNSS time -> {antenna_id: msg}
        self.last_epoch = -math.inf               # GNSS time of the last epoch handled
        self.newest = -math.inf
        self.eph_msgs: dict[str, GnssEphemeris] = {}
        self.eph_cache: dict[str, KeplerEphemeris] = {}
        self.position = None                      # (stamp s, ECEF xyz) of the latest position
        self.spp_x0 = None
        self.ins = None             # (stamp s, C_nb, heading known) of the latest ins/state
        self.filter = None          # (heading known, tilt 1-sigma rad) from the latest nav/status
        self.last_solution: AttitudeSolution | None = None
        self.status_counts: Counter[str] = Counter()
        self.pub = self.publisher(Heading, "gnss/heading", SENSOR_QOS)
        self.subscribe(GnssObservations, "gnss/observations", self.on_observations, SENSOR_QOS)
        self.subscribe(GnssEphemeris, "gnss/ephemeris", self.on_ephemeris, STATE_QOS)
        self.subscribe(NavSatFix, "gnss/fix", self.on_fix, SENSOR_QOS)
        self.subscribe(InsState, "ins/state", self.on_ins_state, SENSOR_QOS)
        self.subscribe(FilterStatus, "nav/status", self.on_filter_status, STATE_QOS)

    @staticmethod
    def _check_geometry(antennas) -> None:
        """With one baseline the core solves heading and pitch with roll = 0 in closed form, which
        needs the baseline mostly fore-aft (across the ship it would see heading only through an
        assumed roll of zero)."""
        b = antennas[1] - antennas[0]
        if len(antennas) == 2 and abs(b[0]) < abs(b[1]):
            raise ParameterError("parameter 'antenna_positions': with 2 antennas the baseline "
                                 "must be mostly fore-aft (|x| >= |y| in base_link)")

    # -- inputs ---------------------------------------------------------------------------------
    def on_ephemeris(self, msg: GnssEphemeris) -> None:
        system = UBX_GNSS_ID.get(int(msg.system))
        if system not in self.systems:
            return
        values = [msg.toe, msg.toc, msg.sqrt_a, msg.eccentricity, msg.m0, msg.omega0, msg.i0,
                  msg.omega, msg.af0]
        if not all(math.isfinite(v) for v in values) or msg.sqrt_a < 1000.0 \
                or not 0.0 <= msg.eccentricity < 1.0:
            self.diag.count("invalid ephemeris ignored")
            return
        sat = f"{system}{int(msg.prn):02d}"
        self.eph_msgs[sat] = msg
        self.eph_cache.pop(sat, None)

    def on_fix(self, msg: NavSatFix) -> None:
        if msg.status.status < NavSatStatus.STATUS_FIX or not all(
                math.isfinite(v) for v in (msg.latitude, msg.longitude, msg.altitude)):
            return
        self.position = (stamp_to_sec(msg.header.stamp),
                         geodetic_to_ecef(math.radians(msg.latitude),
                                          math.radians(msg.longitude), msg.altitude))

    def on_ins_state(self, msg: InsState) -> None:
        q = quat(msg.orientation)
        values = [msg.latitude, msg.longitude, msg.altitude, *q]
        if not all(math.isfinite(v) for v in values) or np.linalg.norm(q) < 0.5 \
                or msg.mode == InsState.MODE_INVALID:
            self.diag.count("invalid ins/state ignored")
            return
        t = stamp_to_sec(msg.header.stamp)
        self.position = (t, geodetic_to_ecef(msg.latitude, msg.longitude, msg.altitude))
        # ALIGNING: levelled, heading unknown; DEAD_RECKONING: maybe never levelled (a strapdown
        # without any correction integrates from its initial attitude parameters).
        if msg.mode in (InsState.MODE_NAVIGATING, InsState.MODE_ALIGNING):
            self.ins = (t, quat_to_dcm(quat_normalize(q)), msg.mode == InsState.MODE_NAVIGATING)

    def on_filter_status(self, msg: FilterStatus) -> None:
        """The ekf's view of the attitude the strapdown's ins/state carries: the strapdown says
        NAVIGATING whenever it is corrected, also while the filter, levelled at rest, has yet
        to find the heading (ALIGNING); and the filter's attitude σ (ENU error angles)."""
        std = dict(zip(msg.state_names, msg.state_std))
        att = [std.get(f"att[{i}]", math.nan) for i in range(3)]
        tilt = max(att[0], att[1]) if all(math.isfinite(a) for a in att[:2]) else 0.0
        # A heading σ larger than the full prior assumes makes that prior overconfident (no σ
        # reported, NaN: trust the mode).
        too_wide = att[2] > math.radians(self.p["ins_prior.sigma_deg"])
        known = msg.mode != FilterStatus.MODE_ALIGNING and not too_wide
        self.filter = (known, tilt)

    def on_observations(self, msg: GnssObservations) -> None:
        t = msg.gps_week * SECONDS_PER_WEEK + msg.time_of_week
        if not math.isfinite(t) or msg.antenna_id >= len(self.antennas):
            self.diag.count("observations with an unknown antenna_id or time dropped")
            return
        if t <= self.last_epoch + self.p["epoch_tolerance_s"]:
            self.diag.count("late observations (epoch already handled) dropped")
            return
        key = next((k for k in self.pending if abs(k - t) <= self.p["epoch_tolerance_s"]), t)
        group = self.pending.setdefault(key, {})
        if msg.antenna_id in group:
            self.diag.count("duplicate observations of an antenna in one epoch dropped")
            return
        group[msg.antenna_id] = msg
        self.newest = max(self.newest, t)
        complete = [k for k, g in self.pending.items() if len(g) == len(self.antennas)]
        horizon = max(max(complete, default=-math.inf), self.newest - self.p["max_latency_s"])
        for k in sorted(k for k in self.pending if k <= horizon):
            self._handle_epoch(k, self.pending.pop(k))

    # -- one epoch ------------------------------------------------------------------------------
    def _handle_epoch(self, t_gps: float, group: dict) -> None:
        self.last_epoch = t_gps
        master = group.get(0) or next(iter(group.values()))
        stamp = master.header.stamp
        sol = self._solve(t_gps, group)
        if sol is None:
            sol = AttitudeSolution("NONE")
        self.last_solution = sol
        for s in sorted(sol.slipped):
            self.diag.count("cycle slip detected (ambiguity re-fixed)", DiagnosticStatus.OK,
                            log=False)
            self.diag.set_value("last cycle slip", f"{s} at GNSS time {t_gps:.3f}")
        self.status_counts[sol.status] += 1
        for status, n in self.status_counts.items():
            self.diag.set_value(f"epochs {status}", n)
        out = heading_msg(sol, stamp, self.p["publish_float"])
        if out.status != Heading.STATUS_NONE or self.p["publish_none"]:
            self.pub.publish(out)

    def _solve(self, t_gps: float, group: dict) -> AttitudeSolution | None:
        if len(group) < len(self.antennas):
            self.diag.count("epoch without every antenna skipped")
            return None
        parsed = [parse_observations(group[a], self.systems) for a in range(len(self.antennas))]
        if any(p is None for p in parsed):
            self.diag.count("observations with arrays of unequal length: epoch skipped")
            return None
        if any(group[a].clock_reset for a in group):
            self.diag.count("receiver clock reset: ambiguities dropped")
            self.solver.reset()
        ephemerides = self._ephemerides(t_gps)
        if not ephemerides:
            self.diag.count("no ephemeris yet: epoch skipped")
            return None
        t = stamp_to_sec(group[0].header.stamp)
        rx = self._receiver_position(t, parsed[0], ephemerides)
        if rx is None:
            self.diag.count("no receiver position for the lines of sight: epoch skipped")
            return None
        los = lines_of_sight(parsed[0], ephemerides, t_gps, rx)
        try:
            sol = self.solver.process([p.antenna for p in parsed], los, t_gps, **self._priors(t))
        except (ValueError, np.linalg.LinAlgError, FloatingPointError) as err:
            # A degenerate geometry the core could not handle: start the ambiguities afresh.
            self.diag.count(f"attitude solver failed: {type(err).__name__}")
            self.solver.reset()
            return None
        tilt = np.nanmax(np.abs([sol.pitch, sol.roll])) if sol.status == "FIXED" else 0.0
        if tilt > math.radians(self.p["max_tilt_deg"]):
            # With few double differences a wrong integer set can pass the ratio, residual and
            # length tests and rotate the baseline out of the plane the platform can reach.
            self.diag.count("FIXED attitude beyond max_tilt_deg: wrong fix, ambiguities dropped")
            self.solver.reset()
            return AttitudeSolution("NONE", satellites=sol.satellites, slipped=sol.slipped)
        return sol

    def _ephemerides(self, t_gps: float) -> dict:
        out = {}
        for sat, msg in self.eph_msgs.items():
            eph = self.eph_cache.get(sat)
            if eph is None or abs(eph.toe - t_gps) > SECONDS_PER_WEEK / 2:
                eph = self.eph_cache[sat] = kepler_from_msg(msg, t_gps)
            if not eph.health and abs(t_gps - eph.toe) <= EPHEMERIS_HALF_WIDTH_S:
                out[sat] = eph
        return out

    def _receiver_position(self, t: float, master: ParsedEpoch, ephemerides: dict):
        """ECEF position of the master antenna (m), or None."""
        fresh = self.position is not None and \
            abs(t - self.position[0]) <= self.p["position_max_age_s"]
        if fresh:
            return self.position[1]
        config = SppConfig(elevation_mask=math.radians(self.p["elevation_mask_deg"]),
                           iono_free=False)
        sol = solve_position(master.raw, ephemerides, config, self.spp_x0)
        if sol is None:
            return None
        self.spp_x0 = sol.xyz
        self.position = (t, sol.xyz)
        return sol.xyz

    def _priors(self, t: float) -> dict:
        """Keyword arguments of the core's ``process``: ``attitude_prior`` when the ins/state
        heading is known and wanted, else ``tilt_prior``; none without a recent ins/state."""
        p = self.p
        if not p["ins_prior.enabled"] or self.ins is None or \
                abs(t - self.ins[0]) > p["ins_prior.max_age_s"]:
            return {}
        _, C_nb, heading_known = self.ins
        filter_known, filter_tilt = self.filter or (True, 0.0)
        if p["ins_prior.heading"] and heading_known and filter_known:
            return {"attitude_prior": (C_nb, np.eye(3) * math.radians(p["ins_prior.sigma_deg"])
                                       ** 2)}
        return {"tilt_prior": (C_nb, max(math.radians(p["ins_prior.tilt_sigma_deg"]),
                                         filter_tilt))}


def main(args=None) -> int:
    return run(PhaseHeadingNode, args)


if __name__ == "__main__":
    sys.exit(main())
