"""``ekf`` node: the closed-loop error-state filter around the strapdown, on the live topics.

The node runs :class:`ins_gnss_ros.nav.navigator.Navigator` on ``imu/delta`` and the aiding
topics, fed through the aiding front end :class:`ins_gnss_ros.nav.aiding.Aiding` and configured
by :func:`ins_gnss_ros.nav.filter_config.navigator_config` (the offline replay runs the same
three). It keeps the ``strapdown`` node on the filter's solution by state synchronisation
(:class:`ins_gnss_ros.nav.strapdown_sync.StrapdownSync`): whenever the filter has corrected its
solution, the strapdown's ``ins/state`` of a common epoch is compared with the filter's solution and the
difference goes out as an ``ins/correction`` referred to that epoch.

Coupling: ``loose`` uses ``gnss/fix`` and ``gnss/vel``; ``tight`` uses the pseudoranges and
Dopplers of ``gnss/observations`` with the broadcast orbits of ``gnss/ephemeris`` (receiver clock
states, usable with fewer than four satellites, seed 004 section 2.1) once the filter has aligned
on fix and velocity; ``auto`` switches to tight whenever an epoch has fewer than
``auto.min_satellites`` usable satellites, as seed 004 describes. Fix/velocity and ranges of the
same epochs are never both used (the same data would count twice). With
``tight.align_on_observations`` the fix and velocity of the alignment are the node's own
single-point solution of each observation epoch (:mod:`ins_gnss_ros.gnss.spp`) and
``gnss/fix`` / ``gnss/vel`` are not subscribed: a receiver whose fix is not an input (the RTK
reference of a trial, or a receiver not trusted for one).

Outputs: ``nav/odom`` (ENU ``map`` frame around a datum, covariance from the filter),
``nav/fix`` (``STATUS_NO_FIX`` unless the filter is NAVIGATING: aligning or dead reckoning is
not a fix; else the augmentation of the fixes it navigates on), ``nav/imu`` (the INS
orientation as sensor_msgs/Imu), ``nav/status`` (mode, coupling, every update with innovation,
NIS and verdict), ``nav/datum`` (latched) and, with ``publish_tf``, ``/tf`` map -> base_link
and ``/tf_static`` base_link -> gnss_0 (REP-105, nodes/tf_messages.py);
/diagnostics says why the filter is not navigating (what it waits for), the datum and, per
aiding input, its rate, staleness and refusals.

Services (as robot_localization's and navsat_transform's): ``~/reset`` (std_srvs/Empty: align
again from nothing), ``~/set_pose`` (the filter navigates on from a map-frame pose:
:func:`ins_gnss_ros.nav.set_pose.set_pose`), ``~/set_datum``, ``~/to_ll``, ``~/from_ll``
(:mod:`ins_gnss_ros.nav.local_frame`).

Integrity: a measurement kind rejected at the gate for 2 s is forced in with its innovation
admitted on both sides (the navigator's integrity logic); until the noise floor this leaves decays
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

import sys
from functools import partial

import numpy as np
from diagnostic_msgs.msg import DiagnosticStatus
from geometry_msgs.msg import TwistWithCovarianceStamped
from ins_gnss_msgs.msg import FilterStatus, GnssEphemeris, GnssObservations, Heading, ImuDelta, \
    InsCorrection, InsState
from ins_gnss_msgs.srv import FromLL, SetDatum, SetPose, ToLL
from nav_msgs.msg import Odometry
from sensor_msgs.msg import Imu, NavSatFix, NavSatStatus
from std_srvs.srv import Empty
from tf2_msgs.msg import TFMessage

from ..gnss.constants import GALILEO, GPS, UBX_GNSS_ID
from ..gnss.ranges import RangeConfig, ephemeris_valid, satellite_ranges
from ..gnss.spp import DEFAULT_SIGNALS, SppConfig, solve_position, solve_velocity
from ..io import new, ns_to_stamp, stamp_to_ns, stamp_to_sec
from ..nav import NAVIGATING, Navigator
from ..nav.aiding import Aiding, AidingPolicy
from ..nav.error_model import LAYOUTS
from ..nav.filter_config import HEADING_INPUTS, PARAMS, navigator_config
from ..nav.local_frame import datum_from_degrees, from_map, to_map
from ..nav.odom_frame import OdomTrack
from ..nav.set_pose import set_pose
from ..nav.strapdown import NavState
from ..nav.strapdown_sync import StrapdownSync
from .base import DRIVER_QOS, LATCHED_QOS, SENSOR_QOS, STATE_QOS, TF_QOS, TF_STATIC_QOS, \
    NavNode, ParameterError, run
from .convert import heading_of, increment_of, nav_state_from_msg, quat, sensor_errors_of, set_vector3, vec
from .gnss_messages import kepler_from_msg, raw_epoch_from_msg
from .nav_messages import MODES, datum_msg, fix_msg, fix_status, imu_msg, odom_msg, status_msg
from .tf_messages import FRAME_PARAMS, solution_tf, static_tf


class EkfNode(NavNode):
    PARAMS = PARAMS + FRAME_PARAMS

    def __init__(self, **kwargs):
        super().__init__("ekf", **kwargs)
        p = self.p
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
        # Single-point solutions that align the filter when the receiver's fix is no input.
        self.spp = SppConfig(elevation_mask=self.ranges.elevation_mask, iono_free=False,
                             klobuchar=self.ranges.klobuchar,
                             sigma0=float(np.hypot(*self.ranges.code_sigma)),
                             signals={s: DEFAULT_SIGNALS[s] for s in self.ranges.signals}) \
            if p["coupling"] != "loose" and p["tight.align_on_observations"] else None
        self.spp_x0 = None  # the last single-point position, ECEF m: the next one starts there
        self.ephemeris_msgs: dict[str, GnssEphemeris] = {}
        self.config = navigator_config(p)
        self.navigator = Navigator(self.config)
        self.aiding = Aiding(self.navigator, AidingPolicy.from_params(p), self.diag.count)
        if not p["datum.from_first_fix"]:
            self.aiding.datum = (np.radians(p["datum.latitude_deg"]),
                                 np.radians(p["datum.longitude_deg"]), p["datum.altitude_m"])
        self.sync = StrapdownSync(p["history_s"], p["sync.min_interval_s"],
                                  p["sync.resend_after_s"],
                                  lambda msg: (nav_state_from_msg(msg), sensor_errors_of(msg)))
        self.reported_updates = 0
        self.accepted = 0
        self.rejected = 0
        self.last_output_t = -np.inf
        self.last_status_t = -np.inf
        self.published_datum = None
        self.converging = False  # re-synchronising the strapdown onto a set pose
        # NavSatStatus (status, service) of the last gnss/fix handed to the filter
        self.fix_input = (NavSatStatus.STATUS_FIX, 0)

        self.pub_correction = self.publisher(InsCorrection, "ins/correction", STATE_QOS)
        self.pub_odom = self.publisher(Odometry, "nav/odom", SENSOR_QOS)
        self.pub_fix = self.publisher(NavSatFix, "nav/fix", SENSOR_QOS)
        self.pub_status = self.publisher(FilterStatus, "nav/status", STATE_QOS)
        self.pub_imu = self.publisher(Imu, "nav/imu", SENSOR_QOS)
        self.pub_datum = self.publisher(NavSatFix, "nav/datum", LATCHED_QOS)
        self.pub_tf = self.publisher(TFMessage, "/tf", TF_QOS) if p["publish_tf"] else None
        # REP-105: with wheel odometry fused, map -> odom -> base_link with a continuous odom
        self.odom = (p["odom_frame"], OdomTrack()) if p["use_wheel_odometry"] else None
        self.pub_tf_static = self.publisher(TFMessage, "/tf_static", TF_STATIC_QOS) \
            if p["publish_tf"] else None
        self.service(Empty, "~/reset", self.on_reset)
        self.service(SetPose, "~/set_pose", self.on_set_pose)
        self.service(SetDatum, "~/set_datum", self.on_set_datum)
        self.service(ToLL, "~/to_ll", self.on_to_ll)
        self.service(FromLL, "~/from_ll", self.on_from_ll)
        self.subscribe(ImuDelta, "imu/delta", self.on_delta, SENSOR_QOS)
        self.subscribe(InsState, "ins/state", self.on_ins_state, SENSOR_QOS)
        if self.spp is None:
            self.subscribe(NavSatFix, "gnss/fix", self.on_fix, DRIVER_QOS)
            self.subscribe(TwistWithCovarianceStamped, "gnss/vel", self.on_vel, DRIVER_QOS)
        if p["coupling"] != "loose":
            self.subscribe(GnssObservations, "gnss/observations", self.on_observations, SENSOR_QOS)
            self.subscribe(GnssEphemeris, "gnss/ephemeris", self.on_ephemeris, STATE_QOS)
        for topic, use in HEADING_INPUTS.items():
            if p[use]:
                self.subscribe(Heading, topic, partial(self.on_heading, topic), SENSOR_QOS)
        if p["use_speed_log"]:
            self.subscribe(TwistWithCovarianceStamped, "log/speed", self.on_log, DRIVER_QOS)
        if p["use_wheel_odometry"]:
            self.subscribe(Odometry, "wheel/odom", self.on_wheel, DRIVER_QOS)

    # -- inputs --------------------------------------------------------------------------------
    def on_delta(self, msg: ImuDelta) -> None:
        if self.pub_tf_static is not None:
            self.publish_static_tf(msg.header.stamp)
        problem, dtheta, dv = increment_of(msg)
        if problem is not None:
            self.diag.count(problem)
            return
        if self.aiding.increment(stamp_to_sec(msg.header.stamp), dtheta, dv, msg.dt) is not None:
            # The strapdown publishes its state after the gap before this filter has applied
            # the measurements of the gap: nav/fix waits for the next synchronisation.
            self.sync.invalidate()
        self.after_filter()

    def on_fix(self, msg: NavSatFix) -> None:
        if self.aiding.fix(stamp_to_sec(msg.header.stamp), msg.latitude, msg.longitude,
                           msg.altitude, np.reshape(msg.position_covariance, (3, 3)),
                           msg.status.status,
                           msg.position_covariance_type != NavSatFix.COVARIANCE_TYPE_UNKNOWN):
            self.fix_input = (msg.status.status, msg.status.service)
            self.note_datum(msg.header.stamp)
            self.after_filter()

    def on_vel(self, msg: TwistWithCovarianceStamped) -> None:
        if self.aiding.velocity(stamp_to_sec(msg.header.stamp), vec(msg.twist.twist.linear),
                                np.reshape(msg.twist.covariance, (6, 6))[:3, :3]):
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
        nav, t = self.navigator, stamp_to_sec(msg.header.stamp)
        if not self.aiding.choose_ranges(len(ephemerides)):
            if self.spp is not None:
                self.align_on_single_point(raw, ephemerides, t, msg.header.stamp)
            return
        if self.aiding.ranges(satellite_ranges(raw, ephemerides, t, nav.state_at(t), nav.lever_arm_b,
                                               self.ranges)):
            self.after_filter()

    def align_on_single_point(self, raw, ephemerides, t, stamp) -> None:
        """Until ranges can aid (they need the heading), the epoch's single-point fix and
        Doppler velocity (gnss/spp.py) stand in for gnss/fix and gnss/vel."""
        sol = solve_position(raw, ephemerides, self.spp, self.spp_x0)
        if sol is None or not sol.valid:
            self.diag.count("observation epoch without a single-point solution", log=False)
            return
        self.spp_x0 = sol.xyz
        vel = solve_velocity(raw, ephemerides, sol, self.spp,
                             float(np.hypot(*self.ranges.doppler_sigma)))
        fixed = self.aiding.fix(t, np.degrees(sol.lat), np.degrees(sol.lon), sol.h,
                                sol.covariance_enu, NavSatStatus.STATUS_FIX, True)
        if fixed:
            self.note_datum(stamp)
        if (vel is not None and self.aiding.velocity(t, vel[0], vel[2])) or fixed:
            self.after_filter()

    def on_heading(self, topic: str, msg: Heading) -> None:
        reading = heading_of(msg)
        if reading is not None and self.aiding.heading(*reading, source=topic):
            self.after_filter()

    def on_log(self, msg: TwistWithCovarianceStamped) -> None:
        if self.aiding.speed_log(stamp_to_sec(msg.header.stamp), msg.twist.twist.linear.x,
                                 msg.twist.covariance[0]):
            self.after_filter()

    def on_wheel(self, msg: Odometry) -> None:
        if self.aiding.wheel_odometry(stamp_to_sec(msg.header.stamp), vec(msg.twist.twist.linear),
                                      np.diag(np.reshape(msg.twist.covariance, (6, 6)))[:3]):
            self.after_filter()

    def on_ins_state(self, msg: InsState) -> None:
        stamp = stamp_to_ns(msg.header.stamp)
        self.sync.add_state(stamp, msg.correction_sequence, msg)
        self.after_filter()
        t = stamp * 1e-9
        if self.navigator.started and self.sync.current(msg.correction_sequence) \
                and t - self.last_output_t >= 1.0 / self.p["output_rate_hz"]:
            self.last_output_t = t
            self.publish_solution(nav_state_from_msg(msg), msg)
        if t - self.last_status_t >= 1.0:  # the mode is reported even when nothing updates
            self.publish_status(t, [])

    # -- services ------------------------------------------------------------------------------
    def on_reset(self, request, response):
        """Forget everything: the filter aligns again (the datum stays)."""
        self.navigator.reset()
        self.sync.invalidate()  # the strapdown's states are not the solution until re-synced
        self.get_logger().info("reset: aligning again")
        return response

    def on_set_pose(self, request: SetPose.Request, response: SetPose.Response):
        pose = request.pose
        if pose.header.frame_id not in ("", self.p["map_frame"]):
            response.message = f"pose in frame {pose.header.frame_id!r}, not {self.p['map_frame']!r}"
            return response
        if self.aiding.datum is None:
            response.message = "no datum yet: set one (~/set_datum) or wait for a fix"
            return response
        p, q = pose.pose.pose.position, quat(pose.pose.pose.orientation)
        norm = np.linalg.norm(q)
        if not (np.isfinite([p.x, p.y, p.z]).all() and np.isfinite(norm) and norm > 0.5):
            response.message = "pose not finite or its quaternion not a rotation"
            return response
        lat, lon, h = from_map(self.aiding.datum, (p.x, p.y, p.z))
        set_pose(self.navigator, stamp_to_sec(pose.header.stamp), lat, lon, h, q / norm,
                 np.reshape(pose.pose.covariance, (6, 6)))
        self.sync.invalidate()
        self.converging = True
        self.after_filter()
        response.success, response.message = True, "navigating from the pose"
        return response

    def on_set_datum(self, request: SetDatum.Request, response: SetDatum.Response):
        try:
            self.aiding.datum = datum_from_degrees(request.latitude, request.longitude,
                                                   request.altitude)
        except ValueError as err:
            response.message = str(err)
            return response
        self.note_datum(self.now_msg())
        response.success, response.message = True, "datum set"
        return response

    def on_to_ll(self, request: ToLL.Request, response: ToLL.Response):
        if self.aiding.datum is None:
            response.message = "no datum yet"
            return response
        p = request.map_point
        lat, lon, response.altitude = from_map(self.aiding.datum, (p.x, p.y, p.z))
        response.latitude, response.longitude = float(np.degrees(lat)), float(np.degrees(lon))
        response.success = True
        return response

    def on_from_ll(self, request: FromLL.Request, response: FromLL.Response):
        if self.aiding.datum is None:
            response.message = "no datum yet"
            return response
        p = response.map_point
        p.x, p.y, p.z = (float(v) for v in to_map(
            self.aiding.datum, np.radians(request.latitude), np.radians(request.longitude),
            request.altitude))
        response.success = True
        return response

    # -- synchronisation and outputs -----------------------------------------------------------
    def note_datum(self, stamp) -> None:
        """Publish the datum (latched) and report it on /diagnostics when it is new."""
        datum = self.aiding.datum
        if datum is None or datum == self.published_datum:
            return
        self.published_datum = datum
        self.pub_datum.publish(datum_msg(stamp, datum, self.p["map_frame"]))
        self.diag.set_value("datum", f"{np.degrees(datum[0]):.9f} deg, "
                                     f"{np.degrees(datum[1]):.9f} deg, {datum[2]:.3f} m")

    def publish_static_tf(self, stamp) -> None:
        """base_link -> gnss_0 (the antenna lever arm) on /tf_static, once, stamped with the
        first increment."""
        pub, self.pub_tf_static = self.pub_tf_static, None
        pub.publish(static_tf(stamp, self.p["base_link_frame"], [
            (self.p["gnss_frame"], self.p["lever_arm"], np.eye(3))]))

    def after_filter(self) -> None:
        nav = self.navigator
        self.report_updates()
        if not nav.started or not self.sync.due(nav.solution.t, nav.revision):
            return
        result = self.sync.correction(nav.solution.t, nav.state_at, nav.estimates, nav.revision)
        if result is None:
            return
        c, resent = result
        if resent:
            self.diag.count("strapdown out of step: re-synchronised on its newest state")
        if c is None:
            return
        if self.converging:
            # A pose set far from the strapdown's state is not reached by one (linearised)
            # correction, and no update may follow to correct it again: compare again until
            # the strapdown is on it.
            self.converging = bool(np.linalg.norm(c.position_error) > 1e-3)
            nav.revision += self.converging
        corr = new(InsCorrection)
        corr.sequence = c.sequence
        corr.header.stamp, corr.header.frame_id = ns_to_stamp(c.t_ns), "map"
        set_vector3(corr.position_error, c.position_error)
        set_vector3(corr.velocity_error, c.velocity_error)
        set_vector3(corr.attitude_error, c.attitude_error)
        set_vector3(corr.gyro_bias, c.sensor.gyro_bias)
        set_vector3(corr.accel_bias, c.sensor.accel_bias)
        set_vector3(corr.gyro_scale_factor, c.sensor.gyro_scale)
        set_vector3(corr.accel_scale_factor, c.sensor.accel_scale)
        self.pub_correction.publish(corr)

    def report_updates(self) -> None:
        nav = self.navigator
        # A delayed measurement re-runs the filter from an earlier epoch: its re-done updates
        # are reported again.
        self.reported_updates = min(self.reported_updates, nav.update_count)
        updates = nav.updates_since(self.reported_updates)
        if updates:
            self.reported_updates = nav.update_count
            self.publish_status(updates[-1].t, updates)

    def publish_status(self, t: float, updates) -> None:
        """nav/status at t (s), or at the filter's time where it is ahead: the mode is the
        current one, also when the last update was a measurement refused as too old (a looped
        or restarted source) or t is that of an ins/state the strapdown published before the
        filter got the increments after it."""
        nav = self.navigator
        if nav.solution is not None:
            t = max(t, nav.solution.t)
        self.last_status_t = t
        for u in updates:
            self.accepted += u.accepted
            self.rejected += not u.accepted
            if not u.accepted and u.reason not in ("aligning",):
                self.diag.count(f"{u.name} rejected: {u.reason}", log=False)
            elif u.reason == "forced":
                self.diag.count(f"{u.name} forced in: degraded until confirmed")
        self.aiding.note_updates(updates)
        self.diag.set_state(DiagnosticStatus.OK if nav.mode == NAVIGATING else DiagnosticStatus.WARN,
                            self.aiding.explain(t, imu_running=np.isfinite(self.aiding.last_increment_t)))
        for name, stats in self.aiding.inputs.items():
            self.diag.set_value(name, stats.summary(t))
        self.pub_status.publish(status_msg(
            t, MODES[nav.mode], self.aiding.use_ranges, updates,
            (nav.space, nav.covariance()) if nav.started else None,
            self.accepted, self.rejected))

    def publish_solution(self, st: NavState, ins: InsState) -> None:
        """nav/fix and nav/odom: the synchronised strapdown state with the filter covariance
        (with the noise floors of forced measurement kinds: Navigator.covariance)."""
        P, S, p = self.navigator.covariance(), self.navigator.space, self.p
        status, service = (NavSatStatus.STATUS_FIX, 0) if self.aiding.use_ranges \
            else self.fix_input
        self.pub_fix.publish(fix_msg(ins.header.stamp, st, P[S["pos"], S["pos"]],
                                     fix_status(self.navigator.mode == NAVIGATING, status),
                                     service, p["base_link_frame"]))
        # one navigation-rate sample of gyro and accelerometer white noise (the rate and the
        # specific force are not filter states)
        noise, interval = self.config.noise, self.config.cov_interval
        rate_var = noise.gyro_psd / interval
        self.pub_imu.publish(imu_msg(ins.header.stamp, st, P, S, ins.angular_velocity,
                                     ins.specific_force, rate_var, noise.accel_psd / interval,
                                     p["base_link_frame"]))
        if self.aiding.datum is not None:
            self.note_datum(ins.header.stamp)
            frames = (p["map_frame"], p["base_link_frame"])
            self.pub_odom.publish(odom_msg(ins.header.stamp, st, P, S, self.aiding.datum,
                                           ins.angular_velocity, rate_var, frames))
            if self.pub_tf is not None:
                self.pub_tf.publish(solution_tf(ins.header.stamp, st, self.aiding.datum, *frames,
                                                self.odom))


def main(args=None) -> int:
    return run(EkfNode, args)


if __name__ == "__main__":
    sys.exit(main())
