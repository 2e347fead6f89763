"""``trial replay --offline``: the filter without the ROS graph, on the same front end.

The offline path runs the cores the nodes feed, configured by the same profile sections: the
``imu_preprocessor`` section builds the :class:`~ins_gnss_ros.imu.preprocessor.ImuPreprocessor`
(:func:`~ins_gnss_ros.imu.preprocessor_params.preprocessor_from_params`) that turns
``imu/data_raw`` into increments (``imu/delta`` of the bag is taken as it is), the ``ekf``
section the :class:`~ins_gnss_ros.nav.navigator.Navigator`
(:func:`~ins_gnss_ros.nav.filter_config.navigator_config`) and the
:class:`~ins_gnss_ros.nav.aiding.Aiding` front end that judges every input. What differs from
the graph is only that no strapdown node follows the filter: with a ``mag_compass`` section the
:class:`~ins_gnss_ros.magnetic.compass_front_end.CompassFrontEnd` levels each magnetometer sample
with the filter's attitude turned to its time
(:meth:`~ins_gnss_ros.nav.navigator.Navigator.attitude_at`) and its heading goes to the ekf's
``mag/heading`` handler, and the outputs are the filter's own solution as the nodes publish
it: ``ins/state`` at every IMU increment (the filter's mechanisation between its epochs, as
the strapdown's), ``nav/odom``, ``nav/fix`` (``STATUS_NO_FIX`` unless NAVIGATING, else
``STATUS_FIX``) and ``/tf`` (with ``publish_tf``: map -> base_link, and ``/tf_static``
base_link -> imu_link and gnss_0, built as the nodes build them) at the ekf's
``output_rate_hz``, and ``nav/status`` once a second with the updates since the last.
Deterministic like :func:`ins_gnss_ros.trial.replay.replay`.
"""
from __future__ import annotations

from collections import Counter
from dataclasses import dataclass
from operator import itemgetter
from pathlib import Path
from typing import Iterator

import numpy as np

from ins_gnss_ros import io as bagio
from ins_gnss_ros.nav.increments import increment_problem
from ins_gnss_ros.params import ParameterError, resolve
from ins_gnss_ros.trial.inputs import bag_rows, check_inputs, conversion_notes, input_count, \
    input_rows
from ins_gnss_ros.trial.outages import GNSS_PREFIX, gnss_windows, in_outage
from ins_gnss_ros.trial.profile import ProfileError, load_profile, profile_with_installation
from ins_gnss_ros.trial.run_folder import MessageCounts, new_run_folder, write_summary

#: The imu/data_raw type and the fields of it the offline path reads, in field order.
IMU_TYPE = "sensor_msgs/msg/Imu"
DELTA_TYPE = "ins_gnss_msgs/msg/ImuDelta"
IMU_FIELDS = ("header.stamp.sec", "header.stamp.nanosec", "orientation.x", "orientation.y",
              "orientation.z", "orientation.w", "orientation_covariance", "angular_velocity.x",
              "angular_velocity.y", "angular_velocity.z", "linear_acceleration.x",
              "linear_acceleration.y", "linear_acceleration.z")
#: The magnetometer's type (imu/mag_raw, imu/mag) and the fields read of it.
MAG_TYPE = "sensor_msgs/msg/MagneticField"
MAG_FIELDS = ("header.stamp.sec", "header.stamp.nanosec", "magnetic_field.x",
              "magnetic_field.y", "magnetic_field.z")

#: The inputs the offline path reads (the ekf's aiding topics and the IMU) and their types,
#: and the magnetometer's where it runs the compass.
OFFLINE_TOPICS = {"/imu/delta": DELTA_TYPE, "/imu/data_raw": IMU_TYPE,
                  "/gnss/fix": "sensor_msgs/msg/NavSatFix",
                  "/gnss/vel": "geometry_msgs/msg/TwistWithCovarianceStamped",
                  "/gnss/heading": "ins_gnss_msgs/msg/Heading",
                  "/mag/heading": "ins_gnss_msgs/msg/Heading",
                  "/log/speed": "geometry_msgs/msg/TwistWithCovarianceStamped",
                  "/wheel/odom": "nav_msgs/msg/Odometry",
                  "/gnss/observations": "ins_gnss_msgs/msg/GnssObservations"}
MAGNETOMETER_TOPICS = ("/imu/mag_raw", "/imu/mag")


def offline_parameters(profile) -> tuple[dict, dict, dict | None]:
    """The profile's ``imu_preprocessor``, ``ekf`` and ``mag_compass`` (None without one)
    sections resolved against the nodes' parameter specifications (defaults filled in, values
    checked); a ProfileError names the section and parameter at fault."""
    from ins_gnss_ros.imu.preprocessor_params import PARAMS as PREPROCESSOR_PARAMS
    from ins_gnss_ros.magnetic.compass_front_end import PARAMS as COMPASS_PARAMS
    from ins_gnss_ros.nav.filter_config import PARAMS as FILTER_PARAMS
    from ins_gnss_ros.nodes.tf_messages import FRAME_PARAMS, IMU_FRAME_PARAMS

    if "ekf" not in profile.sections:
        raise ProfileError(f"{profile.path}: the offline path runs the 'ekf' section's filter: "
                           "the profile has none")
    out = []
    for name, specs in (("imu_preprocessor", PREPROCESSOR_PARAMS + IMU_FRAME_PARAMS),
                        ("ekf", FILTER_PARAMS + FRAME_PARAMS), ("mag_compass", COMPASS_PARAMS)):
        if name == "mag_compass" and name not in profile.sections:
            out.append(None)
            continue
        section = {k: v for k, v in profile.sections.get(name, {}).items() if k != "use_sim_time"}
        try:
            out.append(resolve(specs, section))
        except ParameterError as err:
            raise ProfileError(f"{profile.path}: {name}: {err}") from None
    return tuple(out)


def replay_offline(bag_path, profile_path, out, outages=None, progress=False,
                   remap=None) -> dict:
    """Run the filter of a profile over a bag without ROS; record its outputs.

    Parameters as :func:`ins_gnss_ros.trial.replay.replay` (``gnss/*`` withheld in the outage
    windows, ``remap`` the bag's topics). Returns the summary written to ``OUT/replay.json``.
    """
    run = forward_pass(bag_path, profile_path, outages, progress, out=out, remap=remap)
    out = Path(out)
    with bagio.BagWriter(out / "bag", ordered=True) as writer:
        run.counts.recorded.update(write_ordered(writer, output_messages(
            run.navigator.output(), run.navigator.config, run.datum, run.frames)))
    return run.summary(out, bag_path, outages, "offline")


@dataclass(frozen=True)
class OutputFrames:
    """The TF set-up of the outputs, as the nodes have it: the ``ekf`` parameters (frame names,
    ``publish_tf``, ``lever_arm``) and the ``imu_preprocessor``'s with its mounting C_bs."""

    ekf_p: dict
    pre_p: dict
    c_bs: np.ndarray


@dataclass
class ForwardPass:
    """The filter of a profile run over a bag (:func:`forward_pass`).

    Attributes
    ----------
    navigator : Navigator
        After ``flush``, its record (``output()``) holds the whole pass with covariances.
    datum : tuple or None
        ``map`` origin (lat rad, lon rad, h m) of ``nav/odom``; None without a fix.
    profile : Profile
    windows : (k, 2) int ndarray
        GNSS outage windows, ns.
    counts : MessageCounts
        Played and withheld so far (the caller adds what it records).
    events : Counter
        What the front end reported, by text.
    frames : OutputFrames
    graph : tuple of str
        The cores that ran, as ``replay.json`` names them.
    unread : list of str
        The bag's topics no input took that one of their type could (check_inputs).
    installation : list of str
        What the bag's /tf_static gave the profile (trial/profile.profile_with_installation).
    converted : list of str
        The bag's topics read as another type (trial/inputs.conversion_notes).
    """

    navigator: object
    datum: tuple | None
    profile: object
    windows: np.ndarray
    counts: MessageCounts
    events: Counter
    frames: OutputFrames
    graph: tuple
    unread: list
    installation: list
    converted: list

    def summary(self, out, bag_path, outages, mode, graph=None) -> dict:
        """Write ``OUT/replay.json`` (run_folder.write_summary) with the front end's events;
        ``graph``: what ran (default: the offline path's cores)."""
        return write_summary(out, bag_path, self.profile, outages, self.windows, self.counts,
                             mode, 0.0, graph=list(graph or self.graph), events=self.events,
                             unread=self.unread, installation=self.installation,
                             converted=self.converted)


def forward_pass(bag_path, profile_path, outages=None, progress=False, out=None,
                 navigator_type=None, remap=None) -> ForwardPass:
    """The profile's imu_preprocessor and ekf cores over a bag, recorded (``record=True``: the
    per-epoch solution, covariance, transition and corrections the smoother needs).

    ``out``: the run folder to create (run_folder.new_run_folder) once the profile and the bag
    are checked, before the work.
    ``navigator_type`` (default :class:`~ins_gnss_ros.nav.navigator.Navigator`) lets a caller
    observe the filter's input, e.g. keep the increments (trial/smooth.py).
    ``remap``: {bag topic: graph topic} (:func:`~ins_gnss_ros.trial.inputs.parse_remap`).
    """
    from tqdm import tqdm

    from ins_gnss_ros.imu.preprocessor_params import preprocessor_from_params
    from ins_gnss_ros.nav import Navigator
    from ins_gnss_ros.nav.aiding import Aiding, AidingPolicy
    from ins_gnss_ros.nav.filter_config import navigator_config

    profile, installed = profile_with_installation(load_profile(profile_path), bag_path,
                                                   remap=remap)
    pre_p, ekf_p, compass_p = offline_parameters(profile)
    runs_compass = compass_p is not None and ekf_p["use_magnetic_heading"]
    unread = check_inputs(bag_path, {**OFFLINE_TOPICS, **dict.fromkeys(
        MAGNETOMETER_TOPICS if runs_compass else (), MAG_TYPE)}, remap)
    # The GNSS span (outage windows) first, from the GNSS topics alone: the rest is streamed.
    windows = gnss_windows(bag_rows(bag_path, lambda topic: topic.startswith(GNSS_PREFIX),
                                    remap) if outages else (), outages)
    if out is not None:
        new_run_folder(out)
    navigator = (navigator_type or Navigator)(navigator_config(ekf_p, record=True))
    events = Counter()
    aiding = Aiding(navigator, AidingPolicy.from_params(ekf_p),
                    lambda text, log=True: events.update([text]))
    if not ekf_p["datum.from_first_fix"]:
        aiding.datum = (np.radians(ekf_p["datum.latitude_deg"]),
                        np.radians(ekf_p["datum.longitude_deg"]), ekf_p["datum.altitude_m"])
    try:
        preprocessor = preprocessor_from_params(pre_p)
    except ParameterError as err:
        raise ProfileError(f"{profile.path}: imu_preprocessor: {err}") from None
    try:
        feed = _Feeder(aiding, preprocessor, pre_p, ekf_p, events,
                       compass_p if runs_compass else None)
    except ParameterError as err:  # the compass's calibration file
        raise ProfileError(f"{profile.path}: mag_compass: {err}") from None
    counts = MessageCounts()
    for row in tqdm(input_rows(bag_path, remap), disable=not progress, unit="msg",
                    desc="forward", total=input_count(bag_path, remap)):
        if row.topic.startswith(GNSS_PREFIX) and in_outage(row.t_ns, windows):
            counts.withheld[row.topic] += 1
            continue
        counts.played[row.topic] += 1
        feed.row(row, bag_path)
    navigator.flush()
    graph = ("imu_preprocessor",) + (("mag_compass",) if feed.compass else ()) + \
        ("ekf (filter only)",)
    return ForwardPass(navigator, aiding.datum, profile, windows, counts, events,
                       OutputFrames(ekf_p, pre_p, preprocessor.calibration.c_bs), graph, unread,
                       installed, conversion_notes(bag_path, remap))


class _Feeder:
    """Bag messages -> the front end, as the nodes translate them; ``compass_p``: the
    ``mag_compass`` parameters (None: no compass)."""

    def __init__(self, aiding, preprocessor, pre_p, ekf_p, events, compass_p=None):
        # Message modules load with the first offline run, not with the trial package.
        from ins_gnss_ros.imu.preprocessor_params import orientation_headings_from_params
        from ins_gnss_ros.magnetic.compass_front_end import CompassFrontEnd
        from ins_gnss_ros.nav.filter_config import STATUS_PERIOD_S
        from ins_gnss_ros.nodes.convert import compass_heading, increment_of
        from ins_gnss_ros.nodes.ekf_inputs import EkfInputs

        self.increment_of, self.compass_heading = increment_of, compass_heading
        self.read_imu = bagio.field_reader(IMU_TYPE, IMU_FIELDS)
        self.read_mag = bagio.field_reader(MAG_TYPE, MAG_FIELDS)
        # imu/heading: the imu_preprocessor node's, from the raw samples' own orientation
        self.orientation, self.declination = orientation_headings_from_params(
            pre_p, preprocessor.calibration.c_bs) if ekf_p["use_imu_heading"] else (None, None)
        self.aiding, self.preprocessor, self.events = aiding, preprocessor, events
        self.handlers = {}
        inputs = EkfInputs(aiding, ekf_p, lambda text, log=True: events.update([text]))
        for topic, (_, handler) in inputs.handlers().items():
            self.handlers["/" + topic] = handler
        # The graph's mag_compass (the ekf takes mag/heading).
        self.compass = None
        if compass_p is not None:
            self.compass = CompassFrontEnd(compass_p, lambda text, log=True: events.update([text]))
            self.compass_frame = compass_p["frame_id"]
            # (update count, t) of the graph's latest nav/status: after each update and every
            # STATUS_PERIOD_S without (EkfNode.publish_status)
            self.status, self.status_period = (-1, -np.inf), STATUS_PERIOD_S
        self.levels_compass = self.compass is not None and \
            compass_p["attitude_source"] == "imu_data"

    def row(self, row, bag_path):
        """One input row of the bag, as the node it is addressed to takes it."""
        if row.topic == "/imu/data_raw":
            self.raw(row, bag_path)
            return
        if row.topic == "/imu/delta":
            self.delta(row, bag_path)
            return
        if row.topic in MAGNETOMETER_TOPICS:
            self.magnetometer(row, bag_path)
            return
        handler = self.handlers.get(row.topic)
        if handler is not None:
            msg = bagio.decode_message(row, bag_path)
            stamp_ns = bagio.stamp_to_ns(msg.header.stamp)
            self.aiding.arrival(row.topic.lstrip("/"), stamp_ns, row.t_ns)
            msg.header.stamp = bagio.ns_to_stamp(self.stamp_ns(stamp_ns, row))
            if row.topic == "/gnss/fix" and self.compass is not None:
                self.compass.fix(msg.latitude, msg.longitude, msg.altitude,
                                 msg.status.status >= msg.status.STATUS_FIX)
            handler(msg)

    def stamp_ns(self, stamp_ns, row):
        """A message's stamp (ns), or its row's log time where the driver left it unset,
        counted as the node counts it (io.stamp_or_arrival)."""
        stamp_ns, unset = bagio.stamp_or_arrival(stamp_ns, row.t_ns, row.topic.lstrip("/"))
        if unset:
            self.events[unset] += 1
        return stamp_ns

    def magnetometer(self, row, bag_path):
        """An imu/mag_raw row (rotated into base_link as the imu_preprocessor does) or an
        imu/mag row, through the compass levelled with the filter's attitude at its stamp (as
        the strapdown's latest state serves mag_compass) to the ekf's mag/heading handler."""
        if self.compass is None:
            return
        if row.msgtype != MAG_TYPE:
            raise bagio.BagError(f"{bag_path}: {row.topic} carries {row.msgtype}, not {MAG_TYPE}")
        try:
            sec, nanosec, *field = self.read_mag(row.data)
        except bagio.CdrLayoutError as err:
            raise bagio.BagError(f"{bag_path}: message on {row.topic} at {row.t_ns} ns does not "
                                 f"decode ({err})") from None
        t_ns = self.stamp_ns(sec * bagio.NS + nanosec, row)
        if row.topic == "/imu/mag_raw":
            out = self.preprocessor.add_magnetic(t_ns, field)
            if isinstance(out, str):
                self.events[f"magnetometer sample rejected: {out}"] += 1
                return
            t_ns, field = out
        t = bagio.ns_to_sec(t_ns)
        navigator = self.aiding.navigator
        q = navigator.attitude_at(t)
        if q is None:  # the strapdown's uncorrected start: its attitude unknown
            self.compass.ins_state(t, (1.0, 0.0, 0.0, 0.0), (np.nan,) * 3, True, 0)
        else:  # corrected by the filter, with the tilt sigma of the graph's nav/status
            nav = navigator.solution
            if navigator.update_count != self.status[0] or \
                    t - self.status[1] >= self.status_period:
                self.status = (navigator.update_count, t)
                att = navigator.space["att"].start
                var = np.diagonal(navigator.covariance())[att:att + 2]
                self.compass.tilt_std(*np.sqrt(var).tolist())
            self.compass.ins_state(t, q, (nav.lat, nav.lon, nav.h), False, 1)
        reading = self.compass.mag(t, field)
        if reading is not None:
            self.handlers["/mag/heading"](self.compass_heading(
                reading, bagio.ns_to_stamp(t_ns), self.compass_frame,
                self.compass.true_reference))

    def increment(self, problem, t, dtheta, dv, dt, angle_var, velocity_var):
        """An increment with its increment_problem verdict, as the ekf node takes it."""
        if problem is not None:
            self.events[problem] += 1
            return
        self.aiding.increment(t, dtheta, dv, dt, angle_var, velocity_var)

    def delta(self, row, bag_path):
        """An imu/delta row, read by field as the ekf node reads it."""
        if row.msgtype != DELTA_TYPE:
            raise bagio.BagError(f"{bag_path}: {row.topic} carries {row.msgtype}, not "
                                 f"{DELTA_TYPE}")
        try:
            inc = self.increment_of(row.data)
        except bagio.CdrLayoutError as err:
            raise bagio.BagError(f"{bag_path}: message on {row.topic} at {row.t_ns} ns does not "
                                 f"decode ({err})") from None
        self.increment(inc.problem, inc.t, inc.dtheta, inc.dv, inc.dt, inc.angle_var,
                       inc.velocity_var)

    def raw(self, row, bag_path):
        """An imu/data_raw row, its fields read straight from the payload (IMU_FIELDS): a
        message object per sample cost more than the imu_preprocessor's work on it."""
        if row.msgtype != IMU_TYPE:
            raise bagio.BagError(f"{bag_path}: {row.topic} carries {row.msgtype}, not {IMU_TYPE}")
        try:
            sec, nanosec, ox, oy, oz, ow, *values = self.read_imu(row.data)
        except bagio.CdrLayoutError as err:
            raise bagio.BagError(f"{bag_path}: message on {row.topic} at {row.t_ns} ns does not "
                                 f"decode ({err})") from None
        orientation_covariance, w, f = values[:9], tuple(values[9:12]), tuple(values[12:])
        # The arrival clock is the log time, as the replayed graph's (its bus time). Times in s
        # as the nodes read them from the messages' stamps (io.ns_to_sec).
        stamp = self.stamp_ns(sec * bagio.NS + nanosec, row)
        # Each sample's own orientation goes with it (the node's: the sample's message): the
        # preprocessor holds the first samples while it measures the rate.
        orientation = ((ow, ox, oy, oz), orientation_covariance) \
            if self.orientation is not None else None
        for out in self.preprocessor.add(stamp, row.t_ns, w, f, orientation):
            t = bagio.ns_to_sec(out.t_ns)
            if out.rates is None:
                self.events[f"imu sample rejected: {out.reason}"] += 1
            else:
                if self.levels_compass:  # as imu/data serves mag_compass
                    self.compass.imu(t, out.rates[1])
                if self.orientation is not None:
                    heading = self.orientation.add(out.t_ns, *out.tag)
                    if heading is not None:
                        self.aiding.heading(t, *heading, self.declination, source="imu/heading")
            for inc in out.increments:
                problem = increment_problem(tuple(inc.dtheta), tuple(inc.dv), inc.dt)
                self.increment(problem, bagio.ns_to_sec(inc.t_ns), inc.dtheta, inc.dv, inc.dt,
                               inc.angle_var, inc.velocity_var)


def write_ordered(writer, messages) -> Counter:
    """Write (t_ns, topic, msgtype, payload) in stamp order into an ``ordered`` BagWriter as
    they come; returns the counts per topic."""
    counts = Counter()
    for t_ns, topic, msgtype, data in messages:
        writer.write_raw(topic, msgtype, t_ns, data)
        counts[bagio.resolve(topic)] += 1
    return counts


#: Rows (samples or epochs) whose messages are encoded at once: the payloads of a block are a
#: few MB.
OUTPUT_BLOCK = 4096


@dataclass(frozen=True)
class _OutputRows:
    """What the nodes' outputs of a recorded pass are taken from: a state per row, the epoch
    each row takes its covariance, mode and sensor errors from, and the rows at which nav/fix,
    nav/odom and /tf are published (ins/state is at every row)."""

    states: object       # Track
    epoch: np.ndarray    # (r,) int
    outputs: np.ndarray  # (r,) bool

    @classmethod
    def of(cls, result, output_rate_hz):
        """Of a forward pass with its samples, as the nodes publish it: ins/state at every
        IMU sample (the strapdown's, mechanised from the epoch before it: at a sample ending
        an epoch, before that epoch's updates), nav/fix, nav/odom and /tf at
        ``output_rate_hz`` from those states, each with the covariance of the epoch before it
        (the filter's when that sample arrives). Of a solution without samples (the smoothed
        one): everything at every epoch."""
        from ins_gnss_ros.nodes.nav_messages import OutputSchedule

        samples = getattr(result, "samples", None)
        if samples is None:
            n = len(result.t)
            return cls(result, np.arange(n), np.ones(n, bool))
        outputs = np.zeros(len(samples.t), bool)
        schedule = OutputSchedule(output_rate_hz)  # as the ekf node's on_ins_state
        for i, t in enumerate(samples.t.tolist()):
            if schedule.due(t):
                outputs[i] = True
                schedule.published(t)
        return cls(samples, samples.epoch - 1, outputs)


def output_messages(result, config, datum, frames, prefix="") -> Iterator:
    """The messages the nodes would publish for a recorded pass (:class:`_OutputRows`):
    ins/state, nav/fix, nav/odom, /tf, nav/status once a second and /tf_static at the first
    row, as (t_ns, topic, type name, CDR payload) in stamp order.

    The per-row messages are encoded for a block of rows at once
    (:func:`~ins_gnss_ros.io.cdr.encode_columns`), not built as message objects: a long run
    has hundreds of thousands of them, and an rclpy object with its CDR cost about 100 us
    each. /tf and nav/status (sequences) are built as objects.

    Parameters
    ----------
    result : NavigatorOutput
        The forward pass (``navigator.output()``, with its samples) or another solution at its
        epochs with its covariance (the smoothed one, trial/smooth.py); its update results
        since the last nav/status go into each nav/status.
    config : NavigatorConfig
        The filter's (the variance of the angular rate in nav/odom).
    datum : tuple or None
        ``map`` origin of nav/odom and /tf (none written without it).
    frames : OutputFrames
        The TF frames and mountings, as the nodes have them.
    prefix : str
        Put before every topic name (``forward/``); /tf and /tf_static only for the solution
        without one (a bag holds one tree).
    """
    from sensor_msgs.msg import NavSatStatus

    from ins_gnss_ros.io import msgtype_of, ns_to_stamp, sec_to_ns, sec_to_stamp_ns, serialize
    from ins_gnss_ros.nav import NAVIGATING, NavState
    from ins_gnss_ros.nav.filter_config import STATUS_PERIOD_S
    from ins_gnss_ros.nav.increments import SensorErrors
    from ins_gnss_ros.nav.odom_frame import OdomTrack
    from ins_gnss_ros.nav.recording import published_covariance
    from ins_gnss_ros.nodes.convert import MODE_VALUES, ins_state_payloads
    from ins_gnss_ros.nodes.nav_messages import fix_payloads, fix_status, odom_payloads, status_msg
    from ins_gnss_ros.nodes.tf_messages import solution_tf, static_tf

    ekf_p, pre_p = frames.ekf_p, frames.pre_p
    rows = _OutputRows.of(result, ekf_p["output_rate_hz"])
    st = rows.states
    if len(st.t) == 0:
        return
    space, updates = result.space, result.updates
    rate_var = config.noise.gyro_psd / config.cov_interval
    u = 0
    accepted = rejected = 0
    next_status = -np.inf
    topic = {name: prefix + name for name in ("ins/state", "nav/fix", "nav/odom", "nav/status")}
    types = {"ins/state": "ins_gnss_msgs/msg/InsState", "nav/fix": "sensor_msgs/msg/NavSatFix",
             "nav/odom": "nav_msgs/msg/Odometry"}
    names = (ekf_p["map_frame"], ekf_p["base_link_frame"])
    publish_tf = ekf_p["publish_tf"] and not prefix
    odom = (ekf_p["odom_frame"], OdomTrack()) if ekf_p["use_wheel_odometry"] else None
    # The messages carry the stamp set_stamp_sec gives the row's time; /tf is logged at the
    # row's ns (the two roundings differ by up to a few hundred ns at epoch scale).
    stamps_ns, rows_ns = sec_to_stamp_ns(st.t), sec_to_ns(st.t)
    # As the imu_preprocessor and ekf nodes publish them: each its own, once (with the first
    # row's messages).
    statics = []
    for parent, publish, child in (
            (pre_p["frame_id"], pre_p["publish_tf"],
             (pre_p["imu_frame"], (0.0, 0.0, 0.0), frames.c_bs)),
            (names[1], ekf_p["publish_tf"], (ekf_p["gnss_frame"], ekf_p["lever_arm"], np.eye(3)))):
        if publish and not prefix:
            msg = static_tf(ns_to_stamp(rows_ns[0]), parent, [child])
            statics.append((int(rows_ns[0]), "/tf_static", msgtype_of(msg), serialize(msg)))
    navigating = fix_status(True, NavSatStatus.STATUS_FIX)
    not_navigating = fix_status(False, NavSatStatus.STATUS_FIX)
    for first in range(0, len(st.t), OUTPUT_BLOCK):
        k = slice(first, first + OUTPUT_BLOCK)
        epoch = rows.epoch[k]
        mode = result.mode[epoch]
        stamp = stamps_ns[k]
        # The sensor errors the solution was compensated with, as the strapdown's ins/state
        # carries its applied ones.
        errors = SensorErrors.of_estimates({name: values[epoch] for name, values in
                                            result.estimates.items()})
        payloads = [(topic["ins/state"], types["ins/state"], ins_state_payloads(
            stamp, st.lat[k], st.lon[k], st.h[k], st.v_enu[k], st.q_nb[k],
            [MODE_VALUES[m] for m in mode], errors=errors), False)]
        out = np.flatnonzero(rows.outputs[k])  # the block's rows with a solution published
        o = first + out
        if len(out):
            # As the ekf node publishes it (Navigator.covariance).
            P = published_covariance(result.P[epoch[out]], result.published_var[epoch[out]])
            # The input's augmentation is not kept per epoch: a NAVIGATING solution is a FIX.
            payloads.append((topic["nav/fix"], types["nav/fix"], fix_payloads(
                stamp[out], st.lat[o], st.lon[o], st.h[o], P[:, space["pos"], space["pos"]],
                np.where(mode[out] == NAVIGATING, navigating, not_navigating), names[1]), True))
            if datum is not None:
                payloads.append((topic["nav/odom"], types["nav/odom"], odom_payloads(
                    stamp[out], st.lat[o], st.lon[o], st.h[o], st.v_enu[o], st.q_nb[o], P,
                    space, datum, rate_var, names), True))
        # each row's place among the block's rows with a solution published (the payloads
        # marked True are of those rows only)
        published = np.cumsum(rows.outputs[k]) - 1
        states = payloads[0][2]
        for i in range(len(epoch)):
            r = first + i
            stamp_ns = int(stamps_ns[r])
            solution = bool(rows.outputs[r])
            t = float(st.t[r])
            if not (solution or r == 0 or t >= next_status):  # most samples: ins/state alone
                yield stamp_ns, topic["ins/state"], types["ins/state"], states[i]
                continue
            # Each at its log time, ties in this order (sorted below).
            logged = statics if r == 0 else []
            logged += [(stamp_ns, name, msgtype, data[published[i] if of_solution else i])
                       for name, msgtype, data, of_solution in payloads
                       if solution or not of_solution]
            if solution and publish_tf and datum is not None:
                state = NavState(st.lat[r], st.lon[r], st.h[r], st.v_enu[r], st.q_nb[r], t)
                msg = solution_tf(ns_to_stamp(stamp_ns), state, datum, *names, odom)
                logged.append((int(rows_ns[r]), "/tf", "tf2_msgs/msg/TFMessage",
                               serialize(msg)))
            if t >= next_status:
                next_status = t + STATUS_PERIOD_S
                since = []
                while u < len(updates) and updates[u].t <= t:
                    since.append(updates[u])
                    u += 1
                accepted += sum(x.accepted for x in since)
                rejected += sum(not x.accepted for x in since)
                e = int(epoch[i])
                P_e = published_covariance(result.P[e], result.published_var[e])
                status = status_msg(t, MODE_VALUES[mode[i]], False, since, (space, P_e),
                                    accepted, rejected)
                logged.append((stamp_ns, topic["nav/status"], "ins_gnss_msgs/msg/FilterStatus",
                               serialize(status)))
            yield from sorted(logged, key=itemgetter(0))
