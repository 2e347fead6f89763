"""``phase_heading`` node: heading, pitch (and roll) from carrier-phase differences between 2-4
antennas (seed 004 §1.3b-c and §2.7), by :class:`~ins_gnss_ros.gnss.phase_heading.PhaseHeading`
(epoch grouping, lines of sight, single-point fallback, INS priors; the algorithm is described
there) around the core :class:`~ins_gnss_ros.gnss.attitude.AttitudeSolver` (cycle-slip
detection, double differences, length-constrained LAMBDA with ratio test, held ambiguities).

Inputs: ``gnss/observations`` of every antenna, ``gnss/ephemeris`` (GPS, Galileo, BeiDou
Keplerian orbits), ``gnss/fix`` and ``ins/state`` (the master antenna's position for the lines
of sight, while younger than ``position_max_age_s``), ``ins/state`` attitude as the prior of the
ambiguity search once a filter has corrected it (``correction_sequence`` > 0: levelled; the
whole attitude when neither it nor the ekf's ``nav/status`` is ALIGNING and the heading σ there
is not above ``ins_prior.sigma_deg``; roll and pitch only otherwise, or with
``ins_prior.heading`` false). With 2 antennas a fix from scratch from fewer than 6 double
differences is held once the same integers passed the ratio test at ``fix_confirm_epochs``
consecutive epochs; with 3-4 antennas the fixed baselines must fit the antenna geometry under
one attitude (the core's rigid-body test).

Publishes ``gnss/heading`` (ins_gnss_msgs/Heading, source PHASE_DIFFERENCE, reference TRUE):
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
angles so that consumers see the node is alive. Skipped epochs and dropped inputs are counted on
/diagnostics.

With ``publish_double_differences``, every FIXED epoch's fixed double differences go out on
``gnss/phase_dd`` (ins_gnss_msgs/PhaseDoubleDifferences, before the epoch's heading): value
λ (DD - N) in metres, the antenna pair and its base_link baseline, the difference of the unit
lines of sight and the full covariance (correlated through the reference satellite and the
master antenna; the multipath counted as for the heading), for an ekf that fuses them as
attitude measurements (seed 004 §2.2.2-2.2.3).

Antenna positions are parameters in the frame of the antenna mount; ``mounting_rpy_deg`` rotates
that frame into base_link (a calibration such as
:func:`~ins_gnss_ros.gnss.attitude.estimate_mounting` gives), so the published angles are those of
base_link.
"""

from __future__ import annotations

import math
import sys
from collections import Counter
from functools import partial

import numpy as np
from diagnostic_msgs.msg import DiagnosticStatus
from ins_gnss_msgs.msg import (FilterStatus, GnssEphemeris, GnssObservations, Heading, InsState,
                               PhaseDoubleDifferences)
from sensor_msgs.msg import NavSatFix, NavSatStatus

from ..gnss import (BEIDOU, GALILEO, GPS, UBX_GNSS_ID, AntennaObservations, AttitudeSolution,
                    AttitudeSolver, MultipathModel, NoiseModel, ParsedEpoch, PhaseHeading,
                    PhaseHeadingConfig, attitude_heading, gps_seconds, mounted_antennas,
                    parsed_epoch)
from ..io import stamp_to_sec
from .base import DRIVER_QOS, SENSOR_QOS, STATE_QOS, NavNode, Param, ParameterError, run
from .convert import quat
from .gnss_messages import (heading_msg, kepler_from_msg, kepler_msg_plausible, phase_dd_msg,
                            raw_epoch_from_msg)

#: Systems the node can use: their Keplerian ephemerides are supported (GLONASS FDMA signals form
#: no integer double differences across frequency slots, see gnss/differences.py).
SYSTEM_PARAMS = {"gps": GPS, "galileo": GALILEO, "beidou": BEIDOU}


def parse_observations(msg: GnssObservations, systems) -> ParsedEpoch | None:
    """The signals of ``systems`` in a GnssObservations as the phase pipeline takes them; None if
    its arrays are inconsistent (see :func:`.gnss_messages.raw_epoch_from_msg`)."""
    parsed = raw_epoch_from_msg(msg, systems)
    if parsed is None:
        return None
    raw, kept = parsed
    return parsed_epoch(raw, [bool(msg.loss_of_lock[i]) for i in kept])


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
        Param("publish_double_differences", False,
              "also publish the fixed double differences of every FIXED epoch on gnss/phase_dd "
              "(PhaseDoubleDifferences: the ekf's direct phase update, ekf use_phase_dd)"),
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
        try:
            antennas = mounted_antennas(p["antenna_positions"], np.radians(p["mounting_rpy_deg"]))
        except ValueError as err:
            raise ParameterError(f"parameter 'antenna_positions': {err}") from None
        self.systems = {s for name, s in SYSTEM_PARAMS.items() if p[name]}
        if not self.systems:
            raise ParameterError("parameters 'gps', 'galileo', 'beidou': enable at least one")
        multipath = (MultipathModel(0.0, p["multipath.phase_m"],
                                    math.radians(p["multipath.elevation_scale_deg"]),
                                    phase_tau=p["multipath.tau_s"])
                     if p["multipath.phase_m"] > 0.0 else None)
        solver = AttitudeSolver(
            antennas, NoiseModel(p["noise.phase_m"], p["noise.phase_m"], p["noise.code_m"],
                                 p["noise.code_m"]),
            ratio_threshold=p["ratio_threshold"], sigma_length=p["baseline_length_sigma_m"],
            elevation_mask=math.radians(p["elevation_mask_deg"]),
            slip_threshold=p["slip_threshold_cycles"], max_gap=p["max_gap_s"],
            window=p["float_window"], confirm_epochs=p["fix_confirm_epochs"],
            multipath=multipath, averaging_time=p["multipath.averaging_time_s"])
        config = PhaseHeadingConfig(
            epoch_tolerance=p["epoch_tolerance_s"], max_latency=p["max_latency_s"],
            position_max_age=p["position_max_age_s"],
            elevation_mask=math.radians(p["elevation_mask_deg"]),
            max_tilt=math.radians(p["max_tilt_deg"]), prior=p["ins_prior.enabled"],
            prior_sigma=math.radians(p["ins_prior.sigma_deg"]),
            prior_heading=p["ins_prior.heading"],
            prior_tilt_sigma=math.radians(p["ins_prior.tilt_sigma_deg"]),
            prior_max_age=p["ins_prior.max_age_s"])
        self.pipeline = PhaseHeading(solver, len(antennas), config, report=self.diag.count)
        self.status_counts: Counter[str] = Counter()
        self.pub = self.publisher(Heading, "gnss/heading", SENSOR_QOS)
        self.pub_dd = (self.publisher(PhaseDoubleDifferences, "gnss/phase_dd", SENSOR_QOS)
                       if p["publish_double_differences"] else None)
        self.subscribe(GnssObservations, "gnss/observations", self.on_observations, SENSOR_QOS)
        self.subscribe(GnssEphemeris, "gnss/ephemeris", self.on_ephemeris, STATE_QOS)
        self.subscribe(NavSatFix, "gnss/fix", self.on_fix, DRIVER_QOS)
        # Read per GNSS epoch (and fix), not decoded at the navigation rate; on DDS subscribed
        # from the first gnss/observations on: a set-up without raw observations has no use
        # for the navigation-rate stream.
        self.ins_state = self.subscribe_latest(InsState, "ins/state", SENSOR_QOS,
                                               self.on_ins_state, start=False)
        self.subscribe(FilterStatus, "nav/status", self.on_filter_status, STATE_QOS)

    # -- inputs ---------------------------------------------------------------------------------
    def on_ephemeris(self, msg: GnssEphemeris) -> None:
        system = UBX_GNSS_ID.get(int(msg.system))
        if system not in self.systems:
            return
        if not kepler_msg_plausible(msg):
            self.diag.count("invalid ephemeris ignored")
            return
        self.pipeline.add_ephemeris(f"{system}{int(msg.prn):02d}", partial(kepler_from_msg, msg))

    def on_fix(self, msg: NavSatFix) -> None:
        self.ins_state.handle()  # as if it had been handled when it came: before the fix
        if msg.status.status >= NavSatStatus.STATUS_FIX:
            self.pipeline.fix(stamp_to_sec(msg.header.stamp), math.radians(msg.latitude),
                              math.radians(msg.longitude), msg.altitude)

    def on_ins_state(self, msg: InsState) -> None:
        # Levelled once a filter has corrected it (sequence 0: a strapdown integrating from its
        # initial attitude parameters; the filter corrects only after levelling); the heading
        # found unless ALIGNING (DEAD_RECKONING: found, drifting; nav/status's sigma says how
        # far).
        mode = msg.mode
        if mode == InsState.MODE_INVALID or not self.pipeline.ins_state(
                stamp_to_sec(msg.header.stamp), msg.latitude, msg.longitude, msg.altitude,
                quat(msg.orientation), levelled=msg.correction_sequence > 0,
                heading_known=mode != InsState.MODE_ALIGNING):
            self.diag.count("invalid ins/state ignored")

    def on_filter_status(self, msg: FilterStatus) -> None:
        """The ekf's mode and attitude σ (ENU error angles ``att[0..2]`` of its state)."""
        std = dict(zip(msg.state_names, msg.state_std))
        self.pipeline.filter_status(msg.mode == FilterStatus.MODE_ALIGNING,
                                    [std.get(f"att[{i}]", math.nan) for i in range(3)])

    def on_observations(self, msg: GnssObservations) -> None:
        self.ins_state.start()
        self.ins_state.handle()
        obs = AntennaObservations(
            msg.antenna_id, gps_seconds(msg.gps_week, msg.time_of_week),
            stamp_to_sec(msg.header.stamp), parse_observations(msg, self.systems),
            msg.clock_reset, msg.header.stamp)
        for epoch in self.pipeline.add(obs):
            self._publish(epoch.t_gnss, self.pipeline.solve(epoch), epoch.tag)

    # -- output ---------------------------------------------------------------------------------
    def _publish(self, t_gps: float, sol: AttitudeSolution, stamp) -> None:
        for s in sorted(sol.slipped):
            self.diag.count("cycle slip detected (ambiguity re-fixed)", DiagnosticStatus.OK,
                            log=False)
            self.diag.set_value("last cycle slip", f"{s} at GNSS time {t_gps:.3f}")
        self.status_counts[sol.status] += 1
        for status, n in self.status_counts.items():
            self.diag.set_value(f"epochs {status}", n)
        if self.pub_dd is not None and sol.double_differences is not None:
            # Before the heading: an ekf that fuses the differences takes the heading only to
            # align, and the epoch's differences then find the heading known.
            self.pub_dd.publish(phase_dd_msg(sol.double_differences, sol.ratio, stamp,
                                             "base_link"))
        heading = attitude_heading(sol, self.p["publish_float"])
        if heading.status != "NONE" or self.p["publish_none"]:
            self.pub.publish(heading_msg(heading, stamp, "base_link",
                                         Heading.SOURCE_PHASE_DIFFERENCE))


def main(args=None) -> int:
    return run(PhaseHeadingNode, args)


if __name__ == "__main__":
    sys.exit(main())
