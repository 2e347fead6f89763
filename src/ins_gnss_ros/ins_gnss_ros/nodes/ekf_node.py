"""``ekf`` node: the closed-loop error-state filter around the strapdown, on the live topics.

The node runs :class:`ins_gnss_ros.nav.navigator.Navigator` (the same code as the offline path
and the replay benchmarks) on ``imu/delta`` and the aiding topics, and keeps the ``strapdown``
node on the filter's solution by state synchronisation: whenever the filter has updated, it
compares the strapdown's ``ins/state`` of a common epoch with its own solution and sends the
difference as an ``ins/correction`` referred to that epoch (errors "computed minus true", the
strapdown re-mechanises from there). A correction that was lost, a strapdown restarted from its
parameters or a state published before the last correction arrived are all handled the same way:
the next comparison sees the difference and removes it.

Coupling: ``loose`` uses ``gnss/fix`` and ``gnss/vel``; ``tight`` uses the pseudoranges and
Dopplers of ``gnss/observations`` with the broadcast orbits of ``gnss/ephemeris`` (receiver clock
states, usable with fewer than four satellites, seed 004 section 2.1) once the filter has aligned
on fix and velocity; ``auto`` switches to tight whenever an epoch has fewer than
``auto.min_satellites`` usable satellites, as seed 004 describes. Fix/velocity and ranges of the
same epochs are never both used (the same data would count twice).

Outputs: ``nav/odom`` (ENU ``map`` frame around a datum, covariance from the filter),
``nav/fix``, ``nav/status`` (mode, coupling, every update with innovation, NIS and verdict).

Integrity: a measurement kind rejected at the gate for 2 s is forced in with its innovation
admitted on both sides (the navigator's ``_update``); until the noise floor this leaves decays
(``forced.*``), ``nav/status`` says ``MODE_DEAD_RECKONING`` (degraded: the solution is not
confirmed by its aiding), the published covariances include the floor, and /diagnostics
counts ``<kind> forced in: degraded until confirmed``.
A gap in ``imu/delta`` of up to ``max_imu_gap_s`` is bridged by holding the rates of the
increment after it, in increments of its length (as the ``strapdown`` node bridges it), with
the process noise of ``imu_gap.*`` over the gap; GNSS epochs inside the gap are applied there.
A longer gap loses the IMU and the filter aligns again. After either, ``nav/fix`` is withheld
until the filter has re-synchronised the strapdown.
"""

from __future__ import annotations

import bisect
import sys
from collections import deque

import numpy as np
from geometry_msgs.msg import TwistWithCovarianceStamped
from ins_gnss_msgs.msg import FilterStatus, GnssEphemeris, GnssObservations, Heading, ImuDelta, \
    InsCorrection, InsState, MeasurementUpdate
from nav_msgs.msg import Odometry
from sensor_msgs.msg import NavSatFix, NavSatStatus

from ..gnss.constants import GALILEO, GPS, UBX_GNSS_ID
from ..gnss.ranges import RangeConfig, ephemeris_valid, satellite_ranges
from ..io import new, sec_to_stamp, stamp_to_ns, stamp_to_sec
from ..nav.earth import ecef_to_enu, geodetic_to_ecef
from ..nav.ekf import ExtraState
from ..nav.error_model import LAYOUTS, nav_error
from ..nav import (ALIGNING, DEAD_RECKONING, NAVIGATING, GnssFix, GnssVelocity, HeadingFix,
                   Navigator, NavigatorConfig, SpeedLog)
from ..nav.rotations import quat_to_dcm
from ..nav.strapdown import NavState
from ..nav.sensor_errors import GRADES, BlockNoise, FilterNoise, filter_noise
from .base import DRIVER_QOS, SENSOR_QOS, STATE_QOS, NavNode, Param, ParameterError, run
from .convert import (held_increments, increment_problem, nav_state_from_msg, to_quaternion,
                      to_vector3, vec)
from .gnss_messages import kepler_from_msg, raw_epoch_from_msg

MODES = {ALIGNING: FilterStatus.MODE_ALIGNING, NAVIGATING: FilterStatus.MODE_NAVIGATING,
         DEAD_RECKONING: FilterStatus.MODE_DEAD_RECKONING}
#: InsCorrection sensor fields and the filter blocks whose running estimates add up to them.
SENSOR_FIELDS = {"gyro_bias": ("bg", "gmg"), "accel_bias": ("ba", "gma"),
                 "gyro_scale_factor": ("sg",), "accel_scale_factor": ("sa",)}


class EkfNode(NavNode):
    PARAMS = (
        Param("layout", "15", "error-state layout (error_model.LAYOUTS key)", choices=tuple(LAYOUTS)),
        Param("imu_grade", "mems_adis16405", "IMU noise model preset (sensor_errors.GRADES)",
              choices=tuple(GRADES)),
        Param("bias_model", "gm", "bias process: gm (constant + Gauss-Markov) or rw (random walk)",
              choices=("gm", "rw")),
        Param("noise.gyro_white", 0.0, "gyro white noise, rad/s/sqrt(Hz) (0: the grade's)", 0.0, 1.0),
        Param("noise.accel_white", 0.0, "accelerometer white noise, m/s^2/sqrt(Hz) (0: the grade's)",
              0.0, 10.0),
        Param("noise.gyro_bias_sigma", 0.0, "initial gyro bias sigma, rad/s (0: the grade's)",
              0.0, 1.0),
        Param("noise.gyro_bias_walk", 0.0, "gyro bias random walk, rad/s/sqrt(s) (0: the grade's)",
              0.0, 1.0),
        Param("noise.accel_bias_sigma", 0.0, "initial accelerometer bias sigma, m/s^2 (0: the "
              "grade's)", 0.0, 10.0),
        Param("noise.accel_bias_walk", 0.0, "accelerometer bias random walk, m/s^2/sqrt(s) (0: the "
              "grade's)", 0.0, 10.0),
        Param("lever_arm", [0.0, 0.0, 0.0], "GNSS antenna position in base_link (FLU), m",
              -100.0, 100.0, length=3),
        Param("gate_probability", 0.9999, "chi-square gate probability of every update", 0.5, 1.0),
        Param("covariance_interval_s", 0.1, "covariance propagation interval, s", 0.005, 1.0),
        Param("gnss.position_sigma_floor_m", 0.02, "floor of the GNSS position sigma per axis, m",
              0.0, 100.0),
        Param("gnss.velocity_sigma_floor_mps", 0.02, "floor of the GNSS velocity sigma, m/s",
              0.0, 10.0),
        Param("gnss.velocity_delay_s", 0.0, "latency of the receiver's velocity solution: a "
              "gnss/vel stamped t is applied at t - delay, s", 0.0, 2.0),
        Param("coupling", "loose", "GNSS aiding: loose (fix + velocity), tight (pseudorange + "
              "Doppler; needs a layout with the clock block, e.g. 24) or auto (tight below "
              "auto.min_satellites)", choices=("loose", "tight", "auto")),
        Param("auto.min_satellites", 5, "auto coupling: fewer usable satellites than this in an "
              "epoch switch to tight", 1, 64),
        Param("tight.gps", True, "tight coupling uses GPS L1 C/A"),
        Param("tight.galileo", True, "tight coupling uses Galileo E1 (one receiver clock with GPS)"),
        Param("tight.code_sigma_m", [0.5, 0.5], "pseudorange sigma a, b of a^2 + b^2/sin^2(el), m",
              0.0, 100.0, length=2),
        Param("tight.doppler_sigma_hz", [0.05, 0.05], "Doppler sigma a, b, Hz", 0.0, 100.0,
              length=2),
        Param("tight.klobuchar", [0.0] * 8, "broadcast ionosphere alpha0-3, beta0-3 (IS-GPS-200 "
              "units: s, s/semicircle^n); all zero: no ionosphere correction", -1e7, 1e7, length=8),
        Param("tight.elevation_mask_deg", 10.0, "satellites below this elevation are not used, deg",
              0.0, 60.0),
        Param("use_heading", True, "use gnss/heading (phase-difference or receiver azimuth)"),
        Param("use_magnetic_heading", False, "use mag/heading as backup heading aiding"),
        Param("magnetic_bias_sigma_deg", 2.0,
              "initial sigma of the magnetic-heading bias state, deg (0: no bias state)", 0.0, 30.0),
        Param("use_speed_log", False,
              "use log/speed (water speed along body x) with water-current and log-scale states"),
        Param("speed_log.current_sigma_mps", 0.3, "initial sigma of the water current, m/s",
              0.0, 10.0),
        Param("speed_log.scale_sigma", 0.02, "initial sigma of the log scale error, -", 0.0, 1.0),
        Param("time_offset_sigma_s", 0.0,
              "initial sigma of the IMU-GNSS time-offset state, s (0: no state)", 0.0, 1.0),
        Param("nonholonomic_sigma_mps", [0.0, 0.0],
              "wheeled-vehicle constraint noise (lateral, vertical), m/s; 0 disables", 0.0, 10.0,
              length=2),
        Param("init.position_sigma_m", 1.0, "initial position sigma at the first fix, m", 0.0, 1e4),
        Param("init.velocity_sigma_mps", 0.1, "initial velocity sigma, m/s", 0.0, 100.0),
        Param("init.tilt_sigma_deg", 1.0, "initial roll/pitch sigma, deg", 0.0, 90.0),
        Param("align.speed_mps", 0.5, "GNSS speed at which the heading is taken from motion, m/s",
              0.0, 50.0),
        Param("align.static_speed_mps", 0.1, "GNSS speed below which the vehicle is at rest, m/s",
              0.0, 10.0),
        Param("dead_reckoning_after_s", 2.0, "no accepted aiding for this long: DEAD_RECKONING, s",
              0.1, 3600.0),
        Param("history_s", 3.0, "how late a measurement may arrive and still be used, s", 0.1, 60.0),
        Param("forced.floor_tau_s", 30.0, "time constant of the noise floor a measurement kind "
              "keeps after it was forced in (decays while the kind is accepted), s", 0.1, 3600.0),
        Param("forced.degraded_ratio", 3.0, "the mode is DEAD_RECKONING (degraded) while a forced "
              "kind's floor exceeds this many times its own standard deviation, -", 0.0, 1000.0),
        Param("max_imu_gap_s", 2.5, "longest gap in imu/delta bridged by holding the rates of the "
              "increment after it; a longer one loses the IMU and the filter aligns again, s",
              0.0, 60.0),
        Param("imu_gap.accel_sigma_mps2", 1.0, "over a bridged imu/delta gap: sigma of the "
              "difference between the held and the true specific force, m/s^2", 0.0, 100.0),
        Param("imu_gap.rate_sigma_dps", 5.0, "over a bridged imu/delta gap: sigma of the "
              "difference between the held and the true angular rate, deg/s", 0.0, 1000.0),
        Param("sync.min_interval_s", 0.1, "shortest interval between two corrections, s", 0.0, 10.0),
        Param("sync.resend_after_s", 1.0,
              "send a correction against the newest ins/state if none matched for this long, s",
              0.1, 60.0),
        Param("output_rate_hz", 10.0, "rate of nav/odom and nav/fix (from the synchronised "
              "ins/state), Hz", 0.1, 1000.0),
        Param("datum.from_first_fix", True, "map-frame origin at the first fix (else datum.*)"),
        Param("datum.latitude_deg", 0.0, "map-frame origin latitude, deg", -90.0, 90.0),
        Param("datum.longitude_deg", 0.0, "map-frame origin longitude, deg", -180.0, 360.0),
        Param("datum.altitude_m", 0.0, "map-frame origin ellipsoidal height, m", -1000.0, 1e5),
    )

    def __init__(self, **kwargs):
        super().__init__("ekf", **kwargs)
        p = self.p
        extras = {}
        if p["time_offset_sigma_s"] > 0.0:
            extras["td"] = ExtraState(1, p["time_offset_sigma_s"])
        if p["use_magnetic_heading"] and p["magnetic_bias_sigma_deg"] > 0.0:
            extras["mag"] = ExtraState(1, np.radians(p["magnetic_bias_sigma_deg"]))
        if p["coupling"] != "loose" and "clock" not in LAYOUTS[p["layout"]]:
            raise ParameterError(f"parameter 'layout' = {p['layout']!r} has no receiver clock "
                                 f"states: coupling {p['coupling']!r} needs one (e.g. '24')")
        self.ranges = RangeConfig(
            signals={sys_: "1C" for sys_, on in ((GPS, p["tight.gps"]), (GALILEO, p["tight.galileo"]))
                     if on},
            elevation_mask=np.radians(p["tight.elevation_mask_deg"]),
            code_sigma=tuple(p["tight.code_sigma_m"]),
            doppler_sigma=tuple(p["tight.doppler_sigma_hz"]),
            klobuchar=(tuple(p["tight.klobuchar"][:4]), tuple(p["tight.klobuchar"][4:]))
            if any(p["tight.klobuchar"]) else None)
        self.ephemeris_msgs: dict[str, GnssEphemeris] = {}
        self.use_ranges = False  # the last observation epoch chose tight coupling
        if p["use_speed_log"]:
            # water current east, north (m/s) and log scale error (-), slowly varying
            sigma_current = p["speed_log.current_sigma_mps"]
            extras["log"] = ExtraState(3, np.array([sigma_current, sigma_current,
                                                    p["speed_log.scale_sigma"]]), psd=1e-6)
        nhc = tuple(p["nonholonomic_sigma_mps"])
        self.config = NavigatorConfig(
            noise=self.noise_model(),
            layout=p["layout"], extras=extras, lever_arm_b=np.array(p["lever_arm"], float),
            cov_interval=p["covariance_interval_s"], gate_prob=p["gate_probability"],
            sigma_pos0=p["init.position_sigma_m"], sigma_vel0=p["init.velocity_sigma_mps"],
            sigma_tilt0=np.radians(p["init.tilt_sigma_deg"]), align_speed=p["align.speed_mps"],
            static_speed=p["align.static_speed_mps"], dr_timeout=p["dead_reckoning_after_s"],
            nhc_sigma=nhc if min(nhc) > 0.0 else None, history=p["history_s"],
            floor_tau=p["forced.floor_tau_s"], degraded_ratio=p["forced.degraded_ratio"],
            gap_accel_sigma=p["imu_gap.accel_sigma_mps2"],
            gap_rate_sigma=np.radians(p["imu_gap.rate_sigma_dps"]),
            store_covariance=False, record=False)
        self.navigator = Navigator(self.config)
        self.datum = None
        if not p["datum.from_first_fix"]:
            self.datum = (np.radians(p["datum.latitude_deg"]), np.radians(p["datum.longitude_deg"]),
                          p["datum.altitude_m"])
        self.sequence = 0
        self.last_delta_t = np.inf  # stamp of the last imu/delta, s
        self.last_sync_t = -np.inf
        self.last_match_t = -np.inf
        self.synced_updates = 0
        self.reported_updates = 0
        self.accepted = 0
        self.rejected = 0
        self.last_output_t = -np.inf
        self.last_status_t = -np.inf
        # strapdown states by stamp (ns) for the comparison at a common epoch
        self.ins_states: deque[tuple[int, InsState]] = deque()

        self.pub_correction = self.publisher(InsCorrection, "ins/correction", STATE_QOS)
        self.pub_odom = self.publisher(Odometry, "nav/odom", SENSOR_QOS)
        self.pub_fix = self.publisher(NavSatFix, "nav/fix", SENSOR_QOS)
        self.pub_status = self.publisher(FilterStatus, "nav/status", STATE_QOS)
        self.subscribe(ImuDelta, "imu/delta", self.on_delta, SENSOR_QOS)
        self.subscribe(InsState, "ins/state", self.on_ins_state, SENSOR_QOS)
        self.subscribe(NavSatFix, "gnss/fix", self.on_fix, DRIVER_QOS)
        if p["coupling"] != "loose":
            self.subscribe(GnssObservations, "gnss/observations", self.on_observations, SENSOR_QOS)
            self.subscribe(GnssEphemeris, "gnss/ephemeris", self.on_ephemeris, STATE_QOS)
        self.subscribe(TwistWithCovarianceStamped, "gnss/vel", self.on_vel, DRIVER_QOS)
        if p["use_heading"]:
            self.subscribe(Heading, "gnss/heading", self.on_heading, SENSOR_QOS)
        if p["use_magnetic_heading"]:
            self.subscribe(Heading, "mag/heading", self.on_heading, SENSOR_QOS)
        if p["use_speed_log"]:
            self.subscribe(TwistWithCovarianceStamped, "log/speed", self.on_log, DRIVER_QOS)

    def noise_model(self) -> FilterNoise:
        """The grade's filter noise with the noise.* parameters that are set put in its place."""
        p = self.p
        noise = filter_noise(GRADES[p["imu_grade"]], p["bias_model"])
        blocks = dict(noise.blocks)
        for block, sigma, walk in (("bg", "noise.gyro_bias_sigma", "noise.gyro_bias_walk"),
                                   ("ba", "noise.accel_bias_sigma", "noise.accel_bias_walk")):
            b = blocks[block]
            blocks[block] = BlockNoise(p[sigma] or b.sigma0, b.tau,
                                       p[walk] ** 2 if p[walk] else b.psd)
        return FilterNoise(p["noise.gyro_white"] ** 2 or noise.gyro_psd,
                           p["noise.accel_white"] ** 2 or noise.accel_psd, blocks)

    # -- inputs --------------------------------------------------------------------------------
    def on_delta(self, msg: ImuDelta) -> None:
        problem = increment_problem(msg)
        if problem is not None:
            self.diag.count(problem)
            return
        dtheta, dv = vec(msg.delta_angle), vec(msg.delta_velocity)
        t = stamp_to_sec(msg.header.stamp)
        interval = t - self.last_delta_t
        self.last_delta_t = t
        if msg.dt > 0.0 and interval - msg.dt > 0.5 * msg.dt:
            # The strapdown publishes its state after the gap before this filter has applied
            # the measurements of the gap: nav/fix waits for the next synchronisation.
            self.sequence += 1
            if interval > self.p["max_imu_gap_s"] + msg.dt:
                self.diag.count("imu lost: gap in increments beyond max_imu_gap_s, aligning again")
                self.navigator.reset()
            else:
                # The increment covers only its dt: hold its rates over the whole gap (free
                # fall otherwise), with the process noise of what holding them may miss.
                self.diag.count("gap in increments: bridged by holding the rates")
                self.navigator.add_bridged_gap(t - interval, t)
                self.navigator.add_imu(*held_increments(t, dtheta, dv, msg.dt, interval))
                self.after_filter()
                return
        self.navigator.add_imu(t, dtheta, dv)
        self.after_filter()

    def on_fix(self, msg: NavSatFix) -> None:
        if self.use_ranges:
            return
        if msg.status.status < NavSatStatus.STATUS_FIX:
            self.diag.count("gnss/fix without a fix ignored", log=False)
            return
        cov = np.reshape(msg.position_covariance, (3, 3))
        if not (np.isfinite([msg.latitude, msg.longitude, msg.altitude]).all()
                and np.isfinite(cov).all()):
            self.diag.count("non-finite gnss/fix rejected")
            return
        if not -1000.0 <= msg.altitude <= 1e5:
            # Outside the heights this filter navigates at (the datum.altitude_m range): a
            # corrupt fix, which max_reject_time would otherwise force in after a while.
            self.diag.count("implausible gnss/fix altitude rejected")
            return
        if msg.position_covariance_type == NavSatFix.COVARIANCE_TYPE_UNKNOWN or cov[0, 0] <= 0.0:
            cov = np.eye(3) * 25.0  # an unknown accuracy is treated as a 5 m single-point fix
            self.diag.count("gnss/fix without covariance: 5 m assumed", log=False)
        floor = self.p["gnss.position_sigma_floor_m"] ** 2
        cov = cov + np.diag(np.maximum(floor - np.diag(cov), 0.0))
        lat, lon = np.radians(msg.latitude), np.radians(msg.longitude)
        if self.datum is None:
            self.datum = (lat, lon, msg.altitude)
        self.navigator.add_measurement(
            GnssFix(stamp_to_sec(msg.header.stamp), lat, lon, msg.altitude, cov))
        self.after_filter()

    def on_vel(self, msg: TwistWithCovarianceStamped) -> None:
        if self.use_ranges:
            return
        v = vec(msg.twist.twist.linear)
        cov = np.reshape(msg.twist.covariance, (6, 6))[:3, :3]
        if not (np.isfinite(v).all() and np.isfinite(cov).all()):
            self.diag.count("non-finite gnss/vel rejected")
            return
        if np.linalg.norm(v) > 1000.0:  # beyond any vehicle this filter is for: corrupt
            self.diag.count("implausible gnss/vel rejected")
            return
        floor = self.p["gnss.velocity_sigma_floor_mps"] ** 2
        cov = cov + np.diag(np.maximum(floor - np.diag(cov), 0.0))
        t = stamp_to_sec(msg.header.stamp) - self.p["gnss.velocity_delay_s"]
        self.navigator.add_measurement(GnssVelocity(t, v, cov))
        self.after_filter()

    def on_ephemeris(self, msg: GnssEphemeris) -> None:
        system = UBX_GNSS_ID.get(int(msg.system))
        if system in self.ranges.signals:
            self.ephemeris_msgs[f"{system}{int(msg.prn):02d}"] = msg

    def on_observations(self, msg: GnssObservations) -> None:
        parsed = raw_epoch_from_msg(msg, set(self.ranges.signals))
        if parsed is None:
            self.diag.count("gnss/observations with arrays of unequal length rejected")
            return
        raw = parsed[0]
        ephemerides = {}
        for o in raw.obs:
            sat = f"{o.system}{o.prn:02d}"
            if sat in self.ephemeris_msgs and sat not in ephemerides:
                eph = kepler_from_msg(self.ephemeris_msgs[sat], raw.t_gps)
                if ephemeris_valid(eph, raw.t_gps):
                    ephemerides[sat] = eph
        nav = self.navigator
        self.use_ranges = nav.heading_known and (
            self.p["coupling"] == "tight" or len(ephemerides) < self.p["auto.min_satellites"])
        if not self.use_ranges:
            return
        t = stamp_to_sec(msg.header.stamp)
        ranges = satellite_ranges(raw, ephemerides, t, nav.state_at(t), nav.lever_arm_b, self.ranges)
        if ranges is None:
            self.diag.count("observation epoch without a usable satellite", log=False)
            return
        nav.add_measurement(ranges)
        self.after_filter()

    def on_heading(self, msg: Heading) -> None:
        if msg.status == Heading.STATUS_NONE and msg.source != Heading.SOURCE_MAGNETIC:
            return
        azimuth = msg.azimuth + (msg.declination if msg.reference == Heading.REFERENCE_MAGNETIC
                                 else 0.0)
        if not (np.isfinite(azimuth) and np.isfinite(msg.azimuth_variance)
                and msg.azimuth_variance > 0.0):
            self.diag.count("heading without a finite azimuth and variance rejected")
            return
        self.navigator.add_measurement(HeadingFix(
            stamp_to_sec(msg.header.stamp), float(azimuth), float(msg.azimuth_variance),
            magnetic=msg.source == Heading.SOURCE_MAGNETIC))
        self.after_filter()

    def on_log(self, msg: TwistWithCovarianceStamped) -> None:
        speed, variance = msg.twist.twist.linear.x, msg.twist.covariance[0]
        if not (np.isfinite(speed) and np.isfinite(variance) and variance > 0.0):
            self.diag.count("log/speed without a finite speed and variance rejected")
            return
        self.navigator.add_measurement(SpeedLog(stamp_to_sec(msg.header.stamp), speed, variance))
        self.after_filter()

    def on_ins_state(self, msg: InsState) -> None:
        stamp = stamp_to_ns(msg.header.stamp)
        if self.ins_states and stamp < self.ins_states[-1][0]:
            self.ins_states.clear()  # the strapdown restarted or the bag looped
        self.ins_states.append((stamp, msg))
        while self.ins_states and stamp - self.ins_states[0][0] > self.p["history_s"] * 1e9:
            self.ins_states.popleft()
        self.after_filter()
        t = stamp * 1e-9
        if self.navigator.started and msg.correction_sequence == self.sequence \
                and t - self.last_output_t >= 1.0 / self.p["output_rate_hz"]:
            self.last_output_t = t
            self.publish_solution(nav_state_from_msg(msg), msg)
        if t - self.last_status_t >= 1.0:  # the mode is reported even when nothing updates
            self.publish_status(t, [])

    # -- synchronisation and outputs -----------------------------------------------------------
    def after_filter(self) -> None:
        nav = self.navigator
        self.report_updates()
        if not nav.started:
            return
        updated = nav.update_count > self.synced_updates
        due = nav.solution.t - self.last_sync_t >= self.p["sync.min_interval_s"]
        if updated and due:
            self.synchronise()

    def ins_state_at(self, t_ns: int) -> InsState | None:
        """The newest kept ins/state within 1 ms of t_ns carrying the current sequence, or None.

        The kept states are in stamp order: bisection finds the 1 ms window instead of a scan of
        all of them, which ran on every message while a synchronisation was waiting.
        """
        states, key = self.ins_states, (lambda entry: entry[0])
        lo = bisect.bisect_right(states, t_ns - 1e6, key=key)
        hi = bisect.bisect_left(states, t_ns + 1e6, lo=lo, key=key)
        return next((states[i][1] for i in range(hi - 1, lo - 1, -1)
                     if states[i][1].correction_sequence == self.sequence), None)

    def synchronise(self) -> None:
        """Send the difference between the strapdown and the filter at a common epoch."""
        nav = self.navigator
        match = self.ins_state_at(int(round(nav.solution.t * 1e9)))
        if match is not None:
            self.last_match_t = nav.solution.t
        elif self.ins_states and nav.solution.t - self.last_match_t > self.p["sync.resend_after_s"]:
            # Nothing comparable for a while (lost correction, restarted strapdown): correct the
            # strapdown's newest state with the filter solution extrapolated to its epoch.
            match = self.ins_states[-1][1]
            self.diag.count("strapdown out of step: re-synchronised on its newest state")
            self.last_match_t = nav.solution.t
        else:
            return
        strapdown = nav_state_from_msg(match)
        target = nav.state_at(strapdown.t)
        if target is None:
            return
        dp, dv, phi = nav_error(strapdown, target)
        corr = InsCorrection(sequence=self.sequence + 1)
        corr.header.stamp = match.header.stamp
        corr.header.frame_id = "map"
        corr.position_error, corr.velocity_error = to_vector3(dp), to_vector3(dv)
        corr.attitude_error = to_vector3(phi)
        for field, blocks in SENSOR_FIELDS.items():
            estimate = sum(nav.estimates[b] for b in blocks if b in nav.estimates)
            if np.ndim(estimate):  # the layout has at least one of the blocks
                setattr(corr, field, to_vector3(estimate - vec(getattr(match, field))))
        self.sequence += 1
        self.synced_updates = nav.update_count
        self.last_sync_t = nav.solution.t
        self.pub_correction.publish(corr)

    def report_updates(self) -> None:
        nav = self.navigator
        # A delayed measurement re-runs the filter from an earlier epoch: its re-done updates
        # are reported again.
        self.reported_updates = min(self.reported_updates, nav.update_count)
        self.synced_updates = min(self.synced_updates, nav.update_count)
        updates = nav.updates_since(self.reported_updates)
        if updates:
            self.reported_updates = nav.update_count
            # Stamped with the filter's time: the mode is the current one, also when the last
            # update was a measurement refused as too old (a looped or restarted source).
            t = updates[-1].t if nav.solution is None else max(updates[-1].t, nav.solution.t)
            self.publish_status(t, updates)

    def publish_status(self, t: float, updates) -> None:
        nav = self.navigator
        self.last_status_t = t
        status = FilterStatus(mode=MODES[nav.mode], coupling=FilterStatus.COUPLING_TIGHT
                              if self.use_ranges else FilterStatus.COUPLING_LOOSE)
        status.header.stamp = sec_to_stamp(t)
        for u in updates:
            self.accepted += u.accepted
            self.rejected += not u.accepted
            if not u.accepted and u.reason not in ("aligning",):
                self.diag.count(f"{u.name} rejected: {u.reason}", log=False)
            elif u.reason == "forced":
                self.diag.count(f"{u.name} forced in: degraded until confirmed")
            status.updates.append(MeasurementUpdate(
                name=u.name, stamp=sec_to_stamp(u.t),
                innovation=[float(x) for x in u.innovation],
                innovation_variance=[float(x) for x in u.s_diag], nis=float(u.nis),
                gate=float(u.gate), accepted=bool(u.accepted),
                reason="" if u.accepted else u.reason))
        if nav.started:
            status.state_names = [f"{name}[{i}]" for name in nav.space.blocks
                                  for i in range(nav.space[name].stop - nav.space[name].start)]
            status.state_std = np.sqrt(np.diag(nav.covariance())).tolist()
        status.accepted_count, status.rejected_count = self.accepted, self.rejected
        self.pub_status.publish(status)

    def publish_solution(self, st: NavState, ins: InsState) -> None:
        """nav/fix and nav/odom: the synchronised strapdown state with the filter covariance
        (with the noise floors of forced measurement kinds: Navigator.covariance)."""
        P, S = self.navigator.covariance(), self.navigator.space
        stamp = ins.header.stamp
        fix = new(NavSatFix)
        fix.header.stamp, fix.header.frame_id = stamp, "base_link"
        fix.status.status = NavSatStatus.STATUS_FIX
        fix.latitude, fix.longitude, fix.altitude = np.degrees(st.lat), np.degrees(st.lon), st.h
        fix.position_covariance = P[S["pos"], S["pos"]].flatten().tolist()
        fix.position_covariance_type = NavSatFix.COVARIANCE_TYPE_KNOWN
        self.pub_fix.publish(fix)
        if self.datum is None:
            return
        odom = new(Odometry)
        odom.header.stamp, odom.header.frame_id, odom.child_frame_id = stamp, "map", "base_link"
        enu = ecef_to_enu(geodetic_to_ecef(st.lat, st.lon, st.h), *self.datum)
        odom.pose.pose.position.x, odom.pose.pose.position.y, odom.pose.pose.position.z = \
            (float(x) for x in enu)
        odom.pose.pose.orientation = to_quaternion(st.q_nb)
        pose_cov = np.zeros((6, 6))
        pose_cov[:3, :3] = P[S["pos"], S["pos"]]
        pose_cov[3:, 3:] = P[S["att"], S["att"]]  # small-angle errors about ENU axes
        odom.pose.covariance = pose_cov.flatten().tolist()
        # Odometry twists are in the child frame (base_link).
        c_bn = quat_to_dcm(st.q_nb).T
        odom.twist.twist.linear = to_vector3(c_bn @ st.v_enu)
        twist_cov = np.zeros((6, 6))
        twist_cov[:3, :3] = c_bn @ P[S["vel"], S["vel"]] @ c_bn.T
        odom.twist.twist.angular = ins.angular_velocity
        # one navigation-rate sample of gyro white noise (the rate is not a filter state)
        twist_cov[3:, 3:] = np.eye(3) * self.config.noise.gyro_psd / self.config.cov_interval
        odom.twist.covariance = twist_cov.flatten().tolist()
        self.pub_odom.publish(odom)


def main(args=None) -> int:
    return run(EkfNode, args)


if __name__ == "__main__":
    sys.exit(main())
