"""``ekf`` node: the closed-loop error-state filter around the strapdown, on the live topics.

The node runs :class:`ins_gnss_ros.nav.navigator.Navigator` on ``imu/delta`` and the aiding
topics, fed through the aiding front end :class:`ins_gnss_ros.nav.aiding.Aiding` and configured
by :func:`ins_gnss_ros.nav.filter_config.navigator_config` (the offline replay runs the same
three). It keeps the ``strapdown`` node on the filter's solution by state synchronisation
(:class:`ins_gnss_ros.nav.strapdown_sync.StrapdownSync`): whenever the filter has corrected its
solution, the strapdown's ``ins/state`` of a common epoch is compared with the filter's solution and the
difference goes out as an ``ins/correction`` referred to that epoch, with the filter's mode
(the strapdown's ``ins/state`` reports it: ALIGNING while the filter levels and aligns).

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
and ``/tf_static`` base_link -> gnss_0 (REP-105, nodes/tf_messages.py). The solution topics
come at ``output_rate_hz`` (:class:`.nav_messages.OutputSchedule`) from the strapdown's
``ins/state`` that carry every correction sent, or lack only the last one, which the node
applies to them; /diagnostics says why the filter is not navigating (what it waits for), the
datum and, per aiding input, its rate, staleness and refusals. The mode on nav/status and in
nav/fix is the filter's, but ALIGNING from its heading alignment until the strapdown's
``ins/state`` carries the correction made after it (``StrapdownSync.mode``): the outputs agree
about when the solution is aligned, and nav/status says NAVIGATING with the first such
ins/state.

Inputs are translated by :class:`.ekf_inputs.EkfInputs`, as the offline replay translates
them. Where ``lever_arm`` is zero (not known), ``/tf_static`` places the antenna until the
filter starts: the place of ``gnss/fix``'s frame in base_link less that of the IMU's
(``imu/data_raw``'s frame, read off one raw sample; base_link's origin where nothing places
it), as the replays take it from a recording (trial/installation.py); /diagnostics ``GNSS
antenna lever arm`` says so. Services (``~/reset``, ``~/set_pose``, ``~/set_datum``,
``~/to_ll``, ``~/from_ll``): :class:`.ekf_services.EkfServices`.

Integrity: a measurement kind rejected at the gate for 2 s is forced in with its innovation
admitted on both sides (the navigator's integrity logic); until the noise floor this leaves decays
(``forced.*``), ``nav/status`` says ``MODE_DEAD_RECKONING`` (degraded: the solution is not
confirmed by its aiding), the published covariances include the floor, and /diagnostics
counts ``<kind> forced in: degraded until confirmed`` (for the receiver's vertical velocity,
which does not degrade the solution, ``gnss_vel_up forced in: its floor published``).
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
from ins_gnss_msgs.msg import FilterStatus, ImuDelta, InsCorrection, InsState
from nav_msgs.msg import Odometry
from sensor_msgs.msg import Imu, NavSatFix, NavSatStatus
from tf2_msgs.msg import TFMessage

from ..io import NS, codec, field_reader, new, ns_to_stamp, stamp_to_ns
from ..nav import ALIGNING, NAVIGATING, Navigator
from ..nav.aiding import Aiding, AidingPolicy, velocity_latency_summary
from ..nav.error_model import LAYOUTS
from ..nav.filter_config import PARAMS, STATUS_PERIOD_S, navigator_config
from ..nav.frame_tree import FrameTree
from ..nav.integrity import NOT_VOUCHING
from ..nav.odom_frame import OdomTrack
from ..nav.strapdown import NavState, apply_correction
from ..nav.strapdown_sync import StrapdownSync
from .base import DRIVER_QOS, LATCHED_QOS, SENSOR_QOS, STATE_QOS, TF_QOS, TF_STATIC_QOS, \
    TF_STATIC_READ_QOS, NavNode, ParameterError, run
from .convert import MODE_VALUES, increment_of, nav_state_from_msg, sensor_errors_of, set_vector3
from .ekf_inputs import EkfInputs
from .ekf_services import EkfServices
from .nav_messages import OutputSchedule, datum_msg, fix_payload, fix_status, imu_payload, \
    odom_payload, status_msg
from .tf_messages import FRAME_PARAMS, solution_tf, static_tf

#: QoS of the inputs that are not sensor streams (EkfInputs.handlers gives the topics).
INPUT_QOS = {"gnss/fix": DRIVER_QOS, "gnss/vel": DRIVER_QOS, "log/speed": DRIVER_QOS,
             "wheel/odom": DRIVER_QOS, "gnss/ephemeris": STATE_QOS}


class EkfNode(EkfServices, NavNode):
    PARAMS = PARAMS + FRAME_PARAMS

    def __init__(self, **kwargs):
        super().__init__("ekf", **kwargs)
        p = self.p
        if p["coupling"] != "loose" and "clock" not in LAYOUTS[p["layout"]]:
            raise ParameterError(f"parameter 'layout' = {p['layout']!r} has no receiver clock "
                                 f"states: coupling {p['coupling']!r} needs one (e.g. '24')")
        self.config = navigator_config(p)
        self.navigator = Navigator(self.config)
        self.aiding = Aiding(self.navigator, AidingPolicy.from_params(p), self.diag.count)
        self.inputs = EkfInputs(self.aiding, p, self.diag.count)
        # what is missing from the installation, said once
        if any(p["lever_arm_sigma_m"]) or any(p["lever_arm_published_sigma_m"]):
            self.report_lever_arm("not measured")
        # A lever arm not given is read off /tf_static until the filter starts (module doc).
        self.frames = self.raw_imu = self.imu_frame = None
        if not any(p["lever_arm"]):
            self.frames = FrameTree()
            self.subscribe(TFMessage, "/tf_static", self.on_tf_static, TF_STATIC_READ_QOS)
            self.raw_imu = self.subscribe_latest(Imu, "imu/data_raw", DRIVER_QOS, None)
        # the turn check's verdict, what each biased heading source's readings carry
        # (nav/heading_noise.py) and whether each heading source turns with the gyros
        # (nav/heading_turns.py), at each /diagnostics publication
        self.diag.before_publish.append(lambda: self.diag.set_value(
            "IMU time offset from turns", self.aiding.timing.verdict().summary))
        self.diag.before_publish.append(self._report_heading_sources)
        if not p["datum.from_first_fix"]:
            self.aiding.datum = (np.radians(p["datum.latitude_deg"]),
                                 np.radians(p["datum.longitude_deg"]), p["datum.altitude_m"])
        # ins/state is kept as its payloads: only the matched one and the published ones are
        # decoded.
        self._decode_state = codec(InsState).decode
        self._read_state_stamp = field_reader("ins_gnss_msgs/msg/InsState", (
            "header.stamp.sec", "header.stamp.nanosec", "correction_sequence"))
        self.sync = StrapdownSync(p["history_s"], p["sync.min_interval_s"],
                                  p["sync.resend_after_s"], self._state_of)
        self.reported_updates = 0
        # A synchronisation was due but no kept ins/state compared with the filter's epoch:
        # the next ins/state may (the filter changes only with its own inputs).
        self.awaiting_state = False
        self.accepted = 0
        self.rejected = 0
        self.output = OutputSchedule(p["output_rate_hz"])
        self.last_status_t = -np.inf
        self.published_datum = None
        self.converging = False  # re-synchronising the strapdown onto a set pose

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
        self.static_tf_stamp = None  # the first increment's, once published
        self.register_services()
        self.subscribe(ImuDelta, "imu/delta", self.on_delta, SENSOR_QOS, serialized=True)
        # Every state is kept for the synchronisation, but none is needed before the filter's
        # next step: on DDS they are taken at the next increment or aiding message instead of
        # each waking this process's executor (~190 us of CPU each, at the moment the
        # strapdown's other readers want the CPU; docs/results/live_cost.md).
        self.ins_states = self.subscribe_queued(InsState, "ins/state", SENSOR_QOS,
                                                self.on_ins_state, serialized=True)
        for topic, (msg_type, handler) in self.inputs.handlers().items():
            self.subscribe(msg_type, topic, partial(self.on_input, topic, handler),
                           INPUT_QOS.get(topic, SENSOR_QOS))

    # -- inputs --------------------------------------------------------------------------------
    def on_delta(self, data: bytes) -> None:
        self.ins_states.handle()
        inc = increment_of(data)
        if self.static_tf_stamp is None and self.pub_tf_static is not None:
            self.static_tf_stamp = ns_to_stamp(inc.t_ns)
            self.publish_static_tf()
        if inc.problem is not None:
            self.diag.count(inc.problem)
            return
        if self.aiding.increment(inc.t, inc.dtheta, inc.dv, inc.dt, inc.angle_var,
                                 inc.velocity_var) is not None:
            # The strapdown publishes its state after the gap before this filter has applied
            # the measurements of the gap: nav/fix waits for the next synchronisation.
            self.sync.invalidate()
        self.after_filter()

    def on_input(self, topic, handler, msg) -> None:
        self.ins_states.handle()
        self.aiding.arrival(topic, stamp_to_ns(msg.header.stamp), self.transport_arrival_ns())
        self.stamp_unset_to_arrival(msg.header, topic)
        if self.frames is not None and topic == "gnss/fix":
            self.place_antenna(msg.header.frame_id.lstrip("/"))
        if handler(msg):
            self.note_datum(msg.header.stamp)  # a first fix sets the datum
            self.after_filter()

    def on_ins_state(self, data: bytes) -> None:
        sec, nanosec, sequence = self._read_state_stamp(data)
        stamp = sec * NS + nanosec
        was_applied = self.sync.alignment_applied
        self.sync.add_state(stamp, sequence, data)
        if self.awaiting_state:
            self.after_filter()
        t = stamp * 1e-9
        if self.navigator.started and self.output.due(t):
            lacking = self.sync.lacking(stamp, sequence)
            if lacking is not None or self.sync.current(sequence):
                msg = self._decode_state(data)
                st = nav_state_from_msg(msg)
                if lacking is not None:
                    st = apply_correction(st, lacking.position_error, lacking.velocity_error,
                                          lacking.attitude_error)
                self.output.published(t)
                self.publish_solution(st, msg)
        # The mode is reported even when nothing updates, and at once when this state is the
        # first to carry the alignment.
        if t - self.last_status_t >= STATUS_PERIOD_S or \
                (self.sync.alignment_applied and not was_applied):
            self.publish_status(t, [])

    def on_tf_static(self, msg: TFMessage) -> None:
        if self.frames is not None:
            self.frames.add_transforms(msg.transforms)

    def place_antenna(self, frame: str) -> None:
        """The lever arm from /tf_static before the filter starts: ``frame`` (a fix's) in
        base_link less the IMU's frame there (module doc)."""
        base = self.p["base_link_frame"]
        if self.navigator.started:  # the antenna stays where the filter started
            if frame and frame != base and not self.navigator.lever_arm_b.any():
                self.report_lever_arm(f"not measured: /tf_static does not place gnss/fix's "
                                      f"frame '{frame}' in '{base}'")
            self.frames = None
            self.raw_imu.stop()
            return
        if self.imu_frame is None:
            raw = self.raw_imu.take()
            if raw is None:
                return
            self.imu_frame = raw.header.frame_id.lstrip("/")
            self.raw_imu.stop()
        lever = self.frames.lever_arm(base, frame, self.imu_frame)
        if lever is None or np.array_equal(lever, self.navigator.lever_arm_b):
            return
        self.navigator.set_lever_arm(lever)
        self.report_lever_arm(f"/tf_static's place of '{frame}' less the IMU's "
                              f"'{self.imu_frame}' in '{base}'")
        if self.static_tf_stamp is not None:
            self.publish_static_tf()  # the newest of a frame's static transforms holds

    def report_lever_arm(self, source: str) -> None:
        """/diagnostics ``GNSS antenna lever arm``: the one in use, where it comes from, and
        the uncertainty carried for it (lever_arm_sigma_m, lever_arm_published_sigma_m)."""
        sigma, published = self.p["lever_arm_sigma_m"], self.p["lever_arm_published_sigma_m"]
        self.diag.set_value("GNSS antenna lever arm", (
            f"{np.round(self.navigator.lever_arm_b, 4).tolist()} m FLU, {source}") + (
            f"; within +-{list(sigma)} m assumed (lever_arm_sigma_m)" if any(sigma) else "") + (
            f"; +-{list(published)} m in the published covariance "
            "(lever_arm_published_sigma_m)" if any(published) else ""))

    def _report_heading_sources(self) -> None:
        for source, noise in self.aiding.heading_noise.items():
            self.diag.set_value(f"{source} error correlation", noise.summary())
        for source, turns in self.aiding.heading_turns.items():
            self.diag.set_value(f"{source} turns", turns.summary())

    # -- synchronisation and outputs -----------------------------------------------------------
    def _state_of(self, data: bytes):
        """(NavState, SensorErrors applied) of a kept ins/state payload."""
        msg = self._decode_state(data)
        return nav_state_from_msg(msg), sensor_errors_of(msg)

    def note_datum(self, stamp) -> None:
        """Publish the datum (latched) and report it on /diagnostics when it is new."""
        datum = self.aiding.datum
        if datum is None or datum == self.published_datum:
            return
        self.published_datum = datum
        self.pub_datum.publish(datum_msg(stamp, datum, self.p["map_frame"]))
        self.diag.set_value("datum", f"{np.degrees(datum[0]):.9f} deg, "
                                     f"{np.degrees(datum[1]):.9f} deg, {datum[2]:.3f} m")

    def publish_static_tf(self) -> None:
        """base_link -> gnss_0 (the antenna lever arm) on /tf_static, stamped with the first
        increment."""
        self.pub_tf_static.publish(static_tf(self.static_tf_stamp, self.p["base_link_frame"], [
            (self.p["gnss_frame"], self.navigator.lever_arm_b, np.eye(3))]))

    def after_filter(self) -> None:
        nav = self.navigator
        if nav.mode == ALIGNING:
            self.sync.aligning()
        # Called after every increment and state, most of which change neither: the two
        # counters tell without asking for the updates or the solution.
        if nav.update_count != self.reported_updates:
            self.report_updates()
        self.awaiting_state = False
        if nav.revision <= self.sync.synced_revision or not nav.started \
                or not self.sync.due(nav.solution.t, nav.revision):
            return
        result = self.sync.correction(nav.solution.t, nav.state_at, nav.estimates, nav.revision,
                                      nav.mode)
        if result is None:
            self.awaiting_state = True
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
        corr.mode = MODE_VALUES[c.mode]
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
                self.diag.count(f"{u.name} forced in: " + (
                    "its floor published" if u.name in NOT_VOUCHING
                    else "degraded until confirmed"))
        self.aiding.note_updates(updates)
        mode = self.sync.mode(nav.mode)
        explanation = self.aiding.explain(t, imu_running=np.isfinite(self.aiding.last_increment_t))
        level = DiagnosticStatus.OK if mode == NAVIGATING else DiagnosticStatus.WARN
        message = self.sync.waiting_for(nav.mode) or explanation
        # An IMU whose stamps or rates the turns show wrong errs in every turn, beyond the
        # covariance (the car drive 190 ms off: 12 % of its valid nav/fix beyond 5 sigma).
        imu = self.aiding.timing.verdict()
        if imu.problem:
            level, message = DiagnosticStatus.WARN, f"{message}; IMU from turns: {imu.summary}"
        self.diag.set_state(level, message)
        for name, stats in self.aiding.inputs.items():
            self.diag.set_value(name, stats.summary(t))
        if nav.imu_noise_at_rest is not None:
            self.diag.set_value("IMU noise at rest", nav.imu_noise_at_rest)
        if nav.learned_constraint is not None:
            self.diag.set_value("non-holonomic constraint", nav.learned_constraint)
        latency = nav.velocity_latency()
        if latency is not None:
            self.diag.set_value("gnss/vel latency estimate", velocity_latency_summary(*latency))
        self.pub_status.publish(status_msg(
            t, MODE_VALUES[mode], self.aiding.use_ranges, updates,
            (nav.space, nav.covariance()) if nav.started else None,
            self.accepted, self.rejected))

    def publish_solution(self, st: NavState, ins: InsState) -> None:
        """nav/fix and nav/odom: the synchronised strapdown state with the filter covariance
        (with the noise floors of forced measurement kinds: Navigator.covariance)."""
        P, S, p = self.navigator.covariance(), self.navigator.space, self.p
        status, service = (NavSatStatus.STATUS_FIX, 0) if self.aiding.use_ranges \
            else self.inputs.fix_input
        stamp_ns = stamp_to_ns(ins.header.stamp)
        self.pub_fix.publish(fix_payload(stamp_ns, st, P[S["pos"], S["pos"]],
                                         fix_status(self.sync.mode(self.navigator.mode)
                                                    == NAVIGATING, status),
                                         service, p["base_link_frame"]))
        # one navigation-rate sample of gyro and accelerometer white noise (the rate and the
        # specific force are not filter states)
        noise, interval = self.config.noise, self.config.cov_interval
        rate_var = noise.gyro_psd / interval
        w, f = ins.angular_velocity, ins.specific_force
        rate, force = (w.x, w.y, w.z), (f.x, f.y, f.z)
        self.pub_imu.publish(imu_payload(stamp_ns, st, P, S, rate, force, rate_var,
                                         noise.accel_psd / interval, p["base_link_frame"]))
        if self.aiding.datum is not None:
            self.note_datum(ins.header.stamp)
            frames = (p["map_frame"], p["base_link_frame"])
            self.pub_odom.publish(odom_payload(stamp_ns, st, P, S, self.aiding.datum, rate,
                                               rate_var, frames))
            if self.pub_tf is not None:
                self.pub_tf.publish(solution_tf(ins.header.stamp, st, self.aiding.datum, *frames,
                                                self.odom))


def main(args=None) -> int:
    return run(EkfNode, args)


if __name__ == "__main__":
    sys.exit(main())
