"""``gnss_simulator`` node: raw GNSS measurements from real orbits along a truth trajectory, on the
same topics as ``gnss_driver``.

The truth comes from ``sim/truth`` (ins_gnss_msgs/InsState, ``source: truth``) or from an internal
seed 004 scenario (``source: scenario``, :mod:`ins_gnss_ros.sim.scenarios`). Every
``1 / rate_hz`` s of truth time, :class:`~ins_gnss_ros.gnss.simulator.GnssSimulator` produces one
epoch per antenna and the node publishes

* ``gnss/observations``: one GnssObservations per antenna (``antenna_id`` = index in
  ``lever_arms``), GPS L1 C/A and Galileo E1-C (u-blox gnssId/sigId numbering);
* ``gnss/fix`` and ``gnss/vel``: the single-point solution of antenna 0's simulated pseudoranges
  and Dopplers (:func:`~ins_gnss_ros.gnss.simulator.solve_fix`, the project's SPP), not truth
  plus noise, so shading below 5 satellites leaves no fix, as on a real receiver;
* ``gnss/ephemeris``: the broadcast set in use, at the first epoch and every
  ``ephemeris_period_s``;
* ``gnss/time_reference``: the PPS of every whole GPS second (time_ref = GNSS time as UTC).

Stamps: with ``source: truth`` the truth's stamp of the epoch (the sensor time axis), and the GNSS
time of the first epoch is ``start_gps_time_s``; with ``source: scenario`` the GNSS time itself
on the ROS (UTC) axis. ``time_of_week`` is the receiver's time tag (true GNSS time plus its clock
offset), as a receiver reports it. A carrier phase whose half-cycle ambiguity is not yet resolved
(GPS L1 C/A, a data channel, for ``half_cycle_resolve_s`` after lock; the pilot-tracked Galileo
E1-C never, see :mod:`ins_gnss_ros.gnss.simulator`) is published as NaN (GnssObservations has no
half-cycle flag); the epoch it becomes valid is flagged ``loss_of_lock``. Epochs fall on a grid
of ``1 / rate_hz`` from the first truth; a truth stamp up to 1 ms before a grid point is taken
for it (float rounding of stamps).
"""

from __future__ import annotations

import dataclasses
import math
import sys

import numpy as np
from builtin_interfaces.msg import Time
from geometry_msgs.msg import TwistWithCovarianceStamped
from rclpy._rclpy_pybind11 import RCLError
from ins_gnss_msgs.msg import GnssEphemeris, GnssObservations, InsState
from sensor_msgs.msg import NavSatFix, NavSatStatus, TimeReference

from ..gnss import (GALILEO, GPS, OCXO, TCXO, GnssSimulator, HalfCycleTracker, MultipathModel,
                    NoiseModel, SimulatorConfig, antenna_positions, default_start, ephemeris_data,
                    gps_to_posix, gps_to_utc, leap_seconds, solve_fix, time_reference)
from ..gnss.broadcast_residuals import BroadcastResiduals
from ..io import sec_to_stamp, stamp_to_sec
from ..sim import scenarios
from .base import SENSOR_QOS, STATE_QOS, NavNode, Param, ParameterError, run
from .convert import quat, vec
from .gnss_messages import (ephemeris_msg, fix_msg, observations_msg, service_bits,
                            time_reference_msg, twist_msg)

NS = 1_000_000_000
#: A truth stamp this close before the next epoch of the grid is taken as that epoch [ns]: stamps
#: computed in float seconds land up to a few hundred ns either side of the grid (a double holds
#: POSIX seconds to 0.24 µs), and without it an epoch would wait for the next truth sample or,
#: with truth at the epoch rate, be lost.
EPOCH_TOLERANCE_NS = 1_000_000


class GnssSimulatorNode(NavNode):
    PARAMS = (
        Param("source", "truth", "truth input: 'truth' subscribes sim/truth (InsState), "
              "'scenario' runs an internal seed 004 scenario", choices=("truth", "scenario")),
        Param("scenario.name", "car", "internal scenario (source: scenario)",
              choices=tuple(scenarios.SCENARIOS)),
        Param("scenario.duration_s", 600.0, "internal scenario length, s", 1.0, 86400.0),
        Param("scenario.seed", 0, "internal scenario seed", 0, 2 ** 31 - 1),
        Param("scenario.realtime_factor", 1.0,
              "internal scenario: simulated seconds per wall-clock second", 0.01, 1000.0),
        Param("rate_hz", 5.0, "raw observation epoch rate, Hz (seed 004: 1-10 Hz)", 0.1, 20.0),
        Param("fix_every", 1, "publish gnss/fix and gnss/vel every n-th epoch", 1, 100),
        Param("lever_arms", [0.75, 0.0, 1.0, -0.75, 0.0, 1.0],
              "antenna phase centres in base_link FLU, m, 3 values per antenna, 1-4 antennas "
              "(antenna 0 gives gnss/fix)", -100.0, 100.0),
        Param("shared_clock", True, "antennas on one receiver (one clock); false: one each"),
        Param("gps", True, "simulate GPS L1 C/A"),
        Param("galileo", True, "simulate Galileo E1"),
        Param("elevation_mask_deg", 10.0, "elevation mask, deg", 0.0, 60.0),
        Param("noise.code_m", 0.3, "code white noise a = b in sigma^2 = a^2 + b^2/sin^2(E), m",
              0.0, 100.0),
        Param("noise.phase_m", 0.002, "carrier-phase white noise a = b, m", 0.0, 0.05),
        Param("noise.doppler_hz", 0.02, "Doppler white noise a = b, Hz", 0.0, 10.0),
        Param("multipath.enabled", True, "Gauss-Markov multipath on code and phase"),
        Param("multipath.code_m", 1.0, "code multipath sigma at 0 deg elevation, m", 0.0, 50.0),
        Param("multipath.phase_m", 0.01, "phase multipath sigma at 0 deg elevation, m", 0.0, 0.05),
        Param("multipath.elevation_scale_deg", 20.0,
              "elevation over which multipath sigma falls by e, deg", 1.0, 90.0),
        Param("multipath.tau_s", 30.0, "multipath correlation time, s", 0.1, 3600.0),
        Param("ionosphere", True, "apply the Klobuchar ionosphere"),
        Param("troposphere", True, "apply the Saastamoinen troposphere"),
        Param("broadcast_residuals", False, "simulate a truth apart from the broadcast models "
              "the receiver corrects with (gnss/broadcast_residuals.py: ionosphere 2x "
              "Klobuchar, 5 cm zenith troposphere, 1 m SISRE per satellite)"),
        Param("oscillator", "tcxo", "receiver oscillator class (Allan h0, h-2)",
              choices=("tcxo", "ocxo")),
        Param("slip_rate_per_s", 0.0, "random cycle slips per satellite and antenna, 1/s",
              0.0, 1.0),
        Param("half_cycle_resolve_s", 6.0,
              "lock time before the half-cycle ambiguity of GPS L1 C/A (a data channel) is "
              "resolved, phase NaN before (Galileo E1-C, a pilot, has none); 0: none, s",
              0.0, 600.0),
        Param("shading.enabled", False,
              "limit the satellites in view by the seed 004 Lab 1 schedule (times from the "
              "first epoch)"),
        Param("shading.first_s", 120.0, "first shading window start, s", 0.0, 86400.0),
        Param("shading.length_s", 45.0, "shading window length, s", 1.0, 86400.0),
        Param("shading.gap_s", 30.0, "open sky between windows, s", 0.0, 86400.0),
        Param("shading.counts", [6, 4, 3, 2], "satellites kept in successive windows", 0, 64),
        Param("start_gps_time_s", 0.0,
              "GNSS time of the first epoch, s since 1980-01-06 (0: one hour before the "
              "stored recording, inside the broadcast fit interval)", 0.0, 1.0e10),
        Param("rotate_orbits_to_site", True,
              "rotate the stored orbits about the Earth's axis so that the recorded sky "
              "appears at the first truth longitude"),
        Param("ephemeris_period_s", 30.0, "republish gnss/ephemeris every, s", 1.0, 86400.0),
        Param("pps_sigma_s", 20e-9, "time-pulse noise, s (seed 004: 20 ns static)", 0.0, 1e-3),
        Param("seed", 0, "random seed of the measurement errors", 0, 2 ** 31 - 1),
    )

    def __init__(self, **kwargs):
        super().__init__("gnss_simulator", **kwargs)
        p = self.p
        try:
            lever_arms = tuple(map(tuple, antenna_positions(p["lever_arms"], 1).tolist()))
        except ValueError as err:
            raise ParameterError(f"parameter 'lever_arms': {err}") from None
        systems = tuple(s for s, on in ((GPS, p["gps"]), (GALILEO, p["galileo"])) if on)
        if not systems:
            raise ParameterError("parameters 'gps' and 'galileo': enable at least one system")
        multipath = (MultipathModel(p["multipath.code_m"], p["multipath.phase_m"],
                                    math.radians(p["multipath.elevation_scale_deg"]),
                                    p["multipath.tau_s"], p["multipath.tau_s"])
                     if p["multipath.enabled"] else None)
        self.config = SimulatorConfig(
            lever_arms=lever_arms,
            shared_clock=p["shared_clock"], systems=systems,
            elevation_mask=math.radians(p["elevation_mask_deg"]),
            noise=NoiseModel(p["noise.phase_m"], p["noise.phase_m"], p["noise.code_m"],
                             p["noise.code_m"]),
            doppler_sigma=(p["noise.doppler_hz"], p["noise.doppler_hz"]), multipath=multipath,
            ionosphere=p["ionosphere"], troposphere=p["troposphere"],
            oscillator=TCXO if p["oscillator"] == "tcxo" else OCXO,
            slip_rate=p["slip_rate_per_s"], half_cycle_resolve_s=p["half_cycle_resolve_s"],
            seed=p["seed"],
            residuals=BroadcastResiduals() if p["broadcast_residuals"] else None)
        self.sim: GnssSimulator | None = None
        self.rng_pps = np.random.default_rng(np.random.SeedSequence(p["seed"]).spawn(5)[4])
        self.next_epoch_ns = None
        self.last_truth_ns = None
        self.last_ephemeris_t = -math.inf
        self.last_second = None
        self.epochs = 0
        self.x0 = None
        self.lock = HalfCycleTracker()
        self.pub_obs = self.publisher(GnssObservations, "gnss/observations", SENSOR_QOS)
        self.pub_fix = self.publisher(NavSatFix, "gnss/fix", SENSOR_QOS)
        self.pub_vel = self.publisher(TwistWithCovarianceStamped, "gnss/vel", SENSOR_QOS)
        self.pub_eph = self.publisher(GnssEphemeris, "gnss/ephemeris", STATE_QOS)
        self.pub_time = self.publisher(TimeReference, "gnss/time_reference", SENSOR_QOS)
        if p["source"] == "truth":
            self.subscribe(InsState, "sim/truth", self.on_truth, SENSOR_QOS)
        else:
            sc = scenarios.SCENARIOS[p["scenario.name"]](
                duration=p["scenario.duration_s"], seed=p["scenario.seed"],
                rate=2.0 * p["rate_hz"], oversample=2)
            self.scenario_traj = sc.trajectory
            self.scenario_k = 0
            self._start(sc.trajectory.lon[0], 0.0)
            if self.bus is None:
                self.timer = self.create_timer(
                    1.0 / (p["rate_hz"] * p["scenario.realtime_factor"]), self._on_timer)

    def _on_timer(self) -> None:
        if not self.step_scenario():
            self.get_logger().info("internal scenario ended")
            self.timer.cancel()

    # -- set-up -----------------------------------------------------------------------------
    def _start(self, lon: float, t0: float) -> None:
        """Create the simulator at the first truth: orbits for its longitude, time axis at t0."""
        p = self.p
        broadcast = ephemeris_data.load(lon if p["rotate_orbits_to_site"] else None)
        start = p["start_gps_time_s"] or default_start(broadcast)
        shading = ()
        if p["shading.enabled"]:
            windows = scenarios.shading_schedule(
                p["scenario.duration_s"] if p["source"] == "scenario" else 86400.0,
                counts=tuple(p["shading.counts"]), first=p["shading.first_s"],
                length=p["shading.length_s"], gap=p["shading.gap_s"])
            shading = tuple(scenarios.ShadingWindow(w.t_start + t0, w.t_end + t0,
                                                    w.max_satellites) for w in windows)
        config = dataclasses.replace(self.config, shading=shading)
        self.sim = GnssSimulator(broadcast, config, start_gps=start, t0=t0)
        self.validity = broadcast.validity()

    # -- inputs -----------------------------------------------------------------------------
    def on_truth(self, msg: InsState) -> None:
        t_ns = msg.header.stamp.sec * NS + msg.header.stamp.nanosec
        values = [msg.latitude, msg.longitude, msg.altitude, *vec(msg.velocity),
                  *quat(msg.orientation), *vec(msg.angular_velocity)]
        if not all(math.isfinite(v) for v in values) or np.linalg.norm(quat(msg.orientation)) < 0.5:
            self.diag.count("non-finite or invalid truth dropped")
            return
        if self.last_truth_ns is not None and t_ns <= self.last_truth_ns:
            self.diag.count("truth stamp not after the previous one: dropped")
            return
        self.last_truth_ns = t_ns
        if self.sim is None:
            self._start(msg.longitude, stamp_to_sec(msg.header.stamp))
            self.next_epoch_ns = t_ns
        if t_ns < self.next_epoch_ns - EPOCH_TOLERANCE_NS:
            return
        period_ns = int(round(NS / self.p["rate_hz"]))
        while self.next_epoch_ns <= t_ns + EPOCH_TOLERANCE_NS:
            self.next_epoch_ns += period_ns
        q = quat(msg.orientation)
        self.simulate(stamp_to_sec(msg.header.stamp), msg.latitude, msg.longitude, msg.altitude,
                      vec(msg.velocity), q / np.linalg.norm(q), vec(msg.angular_velocity),
                      msg.header.stamp)

    def step_scenario(self) -> bool:
        """Publish the next epoch of the internal scenario; False when it has ended."""
        traj = self.scenario_traj
        k = self.scenario_k
        if k >= len(traj):
            return False
        self.scenario_k += 2   # the trajectory runs at twice the epoch rate
        t_gps = self.sim.gps_time(traj.t[k])
        # GPST - UTC from the leap-second table at that date (18 s since 2017)
        stamp = sec_to_stamp(gps_to_posix(t_gps, leap_seconds(gps_to_utc(t_gps, 18))))
        self.simulate(traj.t[k], traj.lat[k], traj.lon[k], traj.h[k], traj.v_enu[k],
                      traj.q_nb[k], traj.omega_ib_b[k], stamp)
        return True

    # -- one epoch --------------------------------------------------------------------------
    def simulate(self, t, lat, lon, h, v_enu, q_nb, omega_ib_b, stamp: Time) -> None:
        """Simulate one epoch at truth time ``t`` [s] and publish it stamped ``stamp``."""
        try:
            epochs = self.sim.epoch(t, lat, lon, h, v_enu, q_nb, omega_ib_b)
        except (ValueError, FloatingPointError, np.linalg.LinAlgError) as err:
            self.diag.count(f"epoch not simulated: {err}")
            return
        try:
            self._publish_epoch(epochs, stamp)
        except RCLError:
            # An epoch takes tens of ms: a shutdown (SIGINT) can invalidate the context while
            # it is being published. Anything else is a real fault.
            if self.context.ok():
                raise

    def _publish_epoch(self, epochs, stamp: Time) -> None:
        t_gps = epochs[0].t_gps
        if not self.validity[0] <= t_gps <= self.validity[1]:
            self.diag.count("epoch outside the broadcast fit interval: orbits extrapolated",
                            log=False)
        if t_gps - self.last_ephemeris_t >= self.p["ephemeris_period_s"]:
            for eph in self.sim.ephemerides.values():
                self.pub_eph.publish(ephemeris_msg(eph, stamp, epochs[0].raw.leap_s))
            self.last_ephemeris_t = t_gps
        for epoch in epochs:
            self.pub_obs.publish(observations_msg(
                epoch.raw, epoch.antenna, stamp, f"gnss_antenna_{epoch.antenna}",
                self.lock.update(epoch.antenna, epoch.raw, epoch.loss_of_lock)))
        second = math.floor(t_gps + 1e-6)
        if second != self.last_second and abs(t_gps - second) < 1e-6:
            _, t_pulse = time_reference(epochs[0], self.p["pps_sigma_s"], self.rng_pps)
            leap = epochs[0].raw.leap_s
            self.pub_time.publish(time_reference_msg(
                stamp, sec_to_stamp(gps_to_posix(t_pulse, leap)), "gnss", "gps"))
        self.last_second = second
        if self.epochs % self.p["fix_every"] == 0:
            fix = solve_fix(epochs[0], self.sim, self.x0)
            if fix is None:
                self.diag.count("no fix: fewer satellites than unknowns", log=False)
                self.x0 = None
            else:
                self.x0 = fix.xyz   # the next solution starts from this one
                self.pub_fix.publish(fix_msg(
                    stamp, "gnss", fix.lat, fix.lon, fix.h, NavSatStatus.STATUS_FIX,
                    service_bits(self.config.systems), fix.covariance_enu,
                    NavSatFix.COVARIANCE_TYPE_KNOWN))
                if np.all(np.isfinite(fix.vel_enu)):
                    self.pub_vel.publish(twist_msg(fix.vel_enu, fix.vel_covariance_enu, stamp,
                                                   "gnss"))
        self.epochs += 1


def main(args=None) -> int:
    return run(GnssSimulatorNode, args)


if __name__ == "__main__":
    sys.exit(main())
