"""``trial replay``: run the node graph of a profile over a bag and record what the nodes publish.

The graph is every node of :mod:`ins_gnss_ros.nodes.registry` that has a section in the profile
(a ROS 2 params file); nothing here knows a particular node. Three ways to run it:

* :func:`replay` (default): deterministic and as fast as possible. One process, one rclpy
  context, the nodes on an :class:`~ins_gnss_ros.nodes.base.InProcessBus`, each given the profile
  with ``--params-file`` exactly as on the command line. Bag messages go in stamp order: set the
  bus time, publish, deliver everything that follows from it, next message. Diagnostics are
  published once per second of bag time. The same bag, profile and outages give the identical
  (decoded) output, run after run.
* :func:`replay_processes` (``--rate R --processes``): the nodes as console-script processes on
  DDS with ``use_sim_time``, a player publishing ``/clock`` and the bag messages at R times the
  bag's pace, a recorder subscribing to every topic the nodes publish (played copies on a topic
  a node also publishes are recognised and left out). Playing starts only once every endpoint
  is matched and every node acknowledged the first ``/clock`` (graph queries and DDS
  acknowledgements, no fixed sleeps). Not deterministic: DDS on a loaded machine may drop
  messages from a reader's KEEP_LAST history.
* :func:`replay_offline` (``--offline``): the offline filter path, no ROS graph: the
  :class:`~ins_gnss_ros.nav.navigator.Navigator` (the ``ekf`` node's filter code without ROS)
  over the bag, configured by the profile's ``navigator`` section (:data:`OFFLINE_PARAMS`); it
  writes ``ins/state`` and ``nav/odom`` (with the filter's covariances) like the graph would.

GNSS outages (:mod:`ins_gnss_ros.trial.outages`) withhold every ``gnss/*`` message whose stamp
falls in a window; the windows are written to ``OUT/replay.json`` with the run's other facts.
A fault specification (:mod:`ins_gnss_ros.faults`, in-process :func:`replay` only) passes the
bag's messages through a :class:`~ins_gnss_ros.faults.inject.FaultInjector` before they reach
the nodes; what each fault did goes into ``replay.json`` under ``faults``.
Output folder layout: ``OUT/bag`` (the recorded outputs, a bag) and ``OUT/replay.json``.
"""
from __future__ import annotations

import copy
import json
import os
import signal
import subprocess
import sys
import threading
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import yaml

from ins_gnss_ros import io as bagio
from ins_gnss_ros.nodes import registry
from ins_gnss_ros.trial.outages import outage_windows, parse_outage_spec

#: Topics withheld during an outage window (prefix, absolute names).
GNSS_PREFIX = "/gnss/"
#: Truth never reaches the nodes.
TRUTH_PREFIX = "/truth/"
#: Bag-time interval of the diagnostics the replay asks every node to publish, ns.
DIAGNOSTICS_PERIOD_NS = 1_000_000_000


class ProfileError(ValueError):
    """A profile (params file) that is missing, malformed or names no known node."""


@dataclass(frozen=True)
class Profile:
    """A params file: its path, the node sections it has and the graph they select.

    Attributes
    ----------
    path : Path
    sections : dict of str to dict
        Parameters of every node section, dotted names (keys without a leading '/').
    graph : tuple of str
        Registry nodes with a section, in registry order.
    ignored : tuple of str
        Sections naming no registry node (e.g. nodes not written yet).
    """

    path: Path
    sections: dict
    graph: tuple
    ignored: tuple


def load_profile(path) -> Profile:
    """Read and check a params file (``<node>: ros__parameters: {...}``, plus ``/**``) with the
    defensive loader of :mod:`ins_gnss_ros.params_io` (a hostile file is one error line).

    Raises
    ------
    ProfileError
        One line naming the file and the problem.
    """
    from ins_gnss_ros.params_io import ParamsFileError, load_params_file

    path = Path(path)
    try:
        sections = load_params_file(path)
    except ParamsFileError as err:
        raise ProfileError(str(err)) from None
    graph = tuple(name for name in registry.NODES if name in sections)
    if not graph:
        raise ProfileError(f"{path}: no section for any known node "
                           f"(known: {', '.join(registry.NODES)})")
    ignored = tuple(sorted(k for k in sections if k not in registry.NODES and k != "**"))
    return Profile(path, sections, graph, ignored)


def read_inputs(bag_path) -> list:
    """The messages of a bag the graph may see: all but ``truth/*`` (not even decoded)."""
    topics = _input_topics(bag_path)
    return bagio.read_bag(bag_path, topics) if topics else []


def _input_topics(bag_path) -> list:
    return [t for t in bagio.bag_topics(bag_path) if not t.startswith(TRUTH_PREFIX)]


def truth_init_parameters(bag_path) -> dict:
    """``init.*`` parameters (strapdown naming, degrees) of the first ``truth/state`` of a bag;
    components the truth lacks (NaN) are left out. Empty without truth."""
    from ins_gnss_ros.nav.conventions import azimuth_from_yaw
    from ins_gnss_ros.nav.rotations import quat_to_euler

    truth = next(bagio.iter_bag(bag_path, [TRUTH_PREFIX + "state"]), None)
    if truth is None:
        return {}
    first = truth.msg
    params = {"init.latitude_deg": float(np.degrees(first.latitude)),
              "init.longitude_deg": float(np.degrees(first.longitude)),
              "init.altitude_m": float(first.altitude)}
    v = [first.velocity.x, first.velocity.y, first.velocity.z]
    if np.all(np.isfinite(v)):
        params["init.velocity_enu"] = [float(x) for x in v]
    o = first.orientation
    q = np.array([o.w, o.x, o.y, o.z])
    if np.all(np.isfinite(q)):
        roll, pitch, yaw = (float(a) for a in quat_to_euler(q / np.linalg.norm(q)))
        params.update({"init.roll_deg": float(np.degrees(roll)),
                       "init.pitch_deg": float(np.degrees(pitch)),
                       "init.heading_deg": float(np.degrees(azimuth_from_yaw(yaw)))})
    return params


def profile_with_truth_init(profile: Profile, bag_path, path) -> Path:
    """Write a copy of ``profile`` to ``path`` in which every graph node that declares the
    truth's ``init.*`` parameters starts from the bag's first truth (a perfect initial
    alignment, for graphs that do not align themselves). Generic: no node is named; the keys
    follow the strapdown's, and a node takes those it declares."""
    from ins_gnss_ros.nodes.registry import node_class

    params = truth_init_parameters(bag_path)
    if not params:
        raise ValueError("--init-from-truth: the bag has no truth/state")
    data = {}
    for name, section in profile.sections.items():
        section = dict(section)
        if name in profile.graph:
            declared = {spec.name for spec in node_class(name).PARAMS}
            # Copies, not shared lists: yaml would write an alias, which rcl refuses.
            section.update({k: copy.deepcopy(v) for k, v in params.items() if k in declared})
        data["/" + name] = {"ros__parameters": section}
    path = Path(path)
    path.write_text(yaml.safe_dump(data, sort_keys=False))
    return path


def gnss_windows(messages, spec) -> np.ndarray:
    """Outage windows (ns, shape (k, 2)) of a ``LEN:PERIOD[:FIRST]`` spec over the GNSS span of
    ``messages`` (:class:`~ins_gnss_ros.io.BagMessage` list); empty without GNSS."""
    t = [m.t_ns for m in messages if m.topic.startswith(GNSS_PREFIX)]
    if spec is None or not t:
        return np.zeros((0, 2), np.int64)
    # Work relative to the first GNSS epoch: 1e9-scale seconds would lose sub-us resolution.
    t0 = t[0]
    windows = outage_windows(parse_outage_spec(spec), 0.0, (t[-1] - t0) * 1e-9)
    return t0 + np.round(windows * 1e9).astype(np.int64)


def _in_windows(t_ns, windows) -> bool:
    return bool(np.any((windows[:, 0] <= t_ns) & (t_ns < windows[:, 1])))


def replay(bag_path, profile_path, out, outages=None, progress=False,
           init_from_truth=False, faults=None) -> dict:
    """Run the profile's graph in-process over a bag as fast as possible (see module doc).

    Parameters
    ----------
    bag_path : path
        Input bag folder.
    profile_path : path
        Params file; its node sections select the graph.
    out : path
        New output folder (``bag`` and ``replay.json`` are written into it).
    outages : str, optional
        ``LEN:PERIOD[:FIRST]`` (s).
    progress : bool
        Show a progress bar on stderr.
    init_from_truth : bool
        Start the nodes from the bag's truth (:func:`profile_with_truth_init`); the derived
        profile is kept as ``OUT/profile.yaml``.
    faults : path, optional
        Fault specification (YAML, :mod:`ins_gnss_ros.faults.spec`) applied to the bag's
        messages on their way to the nodes (after the outages are decided on the original
        stream).

    Returns
    -------
    dict
        What ``replay.json`` holds.

    Raises
    ------
    ins_gnss_ros.faults.spec.FaultSpecError
        An unusable fault specification (before anything is written).
    """
    import rclpy
    from rclpy.exceptions import ParameterException
    from tqdm import tqdm

    from ins_gnss_ros.nodes.base import InProcessBus, ParameterError

    profile = load_profile(profile_path)
    injector = None
    if faults is not None:
        from ins_gnss_ros.faults import FaultInjector, load_fault_spec

        injector = FaultInjector(load_fault_spec(faults))
    messages = read_inputs(bag_path)
    windows = gnss_windows(messages, outages)
    stream = messages
    if injector is not None:
        # Outages are decided on the bag's own time; faults act on what is left.
        stream = (bagio.BagMessage(topic, t_ns, msg) for t_ns, topic, msg in injector(
            (m.t_ns, m.topic, m.msg) for m in messages
            if not (m.topic.startswith(GNSS_PREFIX) and _in_windows(m.t_ns, windows))))
    out = _new_out(out)
    if init_from_truth:
        profile = load_profile(profile_with_truth_init(profile, bag_path, out / "profile.yaml"))
    writer = bagio.BagWriter(out / "bag")
    context = rclpy.Context()
    rclpy.init(context=context, args=[])
    bus = InProcessBus()
    feeding = [None]  # the input message being delivered: not an output

    def record(topic, msg):
        if msg is not feeding[0]:
            writer.write(topic, msg, bagio.msg_stamp_ns(msg) if hasattr(msg, "header")
                         else bus.now_ns)

    bus.recorders.append(record)
    nodes = []
    withheld = 0
    try:
        for name in profile.graph:
            try:
                nodes.append(registry.node_class(name)(
                    bus=bus, context=context, use_global_arguments=False,
                    start_parameter_services=False,
                    cli_args=["--ros-args", "--params-file", str(profile.path)]))
            except (ParameterError, ParameterException) as err:
                raise ProfileError(f"{profile.path}: node {name}: {err}") from None
            except Exception as err:  # rcl's own params-file parser
                raise ProfileError(f"{profile.path}: node {name}: "
                                   f"{bagio.first_line(err)}") from None
        next_diag = messages[0].t_ns + DIAGNOSTICS_PERIOD_NS if messages else 0
        for m in tqdm(stream, disable=not progress, unit="msg", desc="replay",
                      total=len(messages)):
            while m.t_ns >= next_diag:
                bus.now_ns = next_diag
                for node in nodes:
                    node.diag.publish()
                bus.drain()
                next_diag += DIAGNOSTICS_PERIOD_NS
            if m.topic.startswith(GNSS_PREFIX) and _in_windows(m.t_ns, windows):
                withheld += 1
                continue
            bus.now_ns = m.t_ns
            feeding[0] = m.msg
            bus.publish(m.topic, m.msg)
            bus.drain()
        feeding[0] = None
    finally:
        for node in nodes:
            node.destroy_node()
        context.try_shutdown()
    writer.close()
    if injector is not None:
        withheld = sum(1 for m in messages
                       if m.topic.startswith(GNSS_PREFIX) and _in_windows(m.t_ns, windows))
    return _write_summary(out, bag_path, profile, outages, windows, withheld, "in-process", 0.0,
                          faults=None if injector is None else injector.summary())


def replay_processes(bag_path, profile_path, out, rate=1.0, outages=None, progress=False,
                     init_from_truth=False, timeout=30.0) -> dict:
    """Run the graph as node processes on DDS, playing the bag at ``rate`` times real time.

    The nodes run with ``use_sim_time`` on the ``/clock`` the player publishes. Outputs are
    recorded from every topic the graph's nodes publish (found by graph queries). Not
    deterministic (DDS scheduling): use :func:`replay` for evaluation runs.
    """
    import rclpy
    from rclpy.executors import SingleThreadedExecutor
    from rclpy.node import Node
    from rclpy.qos import HistoryPolicy, QoSProfile, ReliabilityPolicy
    from rosgraph_msgs.msg import Clock
    from tqdm import tqdm

    if not rate > 0.0:
        raise ValueError(f"--rate must be > 0, got {rate}")
    profile = load_profile(profile_path)
    messages = read_inputs(bag_path)
    windows = gnss_windows(messages, outages)
    out = _new_out(out)
    if init_from_truth:
        profile = load_profile(profile_with_truth_init(profile, bag_path, out / "profile.yaml"))
    inputs = [m for m in messages
              if not (m.topic.startswith(GNSS_PREFIX) and _in_windows(m.t_ns, windows))]
    withheld = sum(1 for m in messages if m.topic.startswith(GNSS_PREFIX)) - sum(
        1 for m in inputs if m.topic.startswith(GNSS_PREFIX))
    qos = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=1000,
                     reliability=ReliabilityPolicy.RELIABLE)
    context = rclpy.Context()
    rclpy.init(context=context, args=[])
    node = Node("trial_player", context=context, use_global_arguments=False,
                start_parameter_services=False)
    executor = SingleThreadedExecutor(context=context)
    executor.add_node(node)
    # Writers exist before the nodes start, so each node discovers them while it starts up
    # rather than after playing began (a volatile reader misses what precedes its matching).
    clock_pub = node.create_publisher(Clock, "/clock", qos)
    pubs = {}
    for m in inputs:
        if m.topic not in pubs:
            pubs[m.topic] = node.create_publisher(type(m.msg), m.topic, qos)
    procs = [subprocess.Popen(
        [str(Path(sys.executable).parent / name), "--ros-args", "--params-file",
         str(profile.path), "-p", "use_sim_time:=true"],
        stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, env=dict(os.environ))
        for name in profile.graph]
    writer = bagio.BagWriter(out / "bag")
    lock = threading.Lock()
    try:
        outputs = _wait_for_graph(node, executor, procs, profile.graph, timeout)

        # A topic both played and published by a node reaches the recorder from both: the
        # played copies (same topic, stamp and fields) are not outputs. (Not bytes: rclpy's
        # CDR leaves alignment padding uninitialised.)
        overlap = set(outputs) & set(pubs)
        played: dict[tuple, list] = {}

        def recorder(topic):
            def callback(msg):
                with lock:
                    copies = played.get((topic, bagio.msg_stamp_ns(msg)), [])
                    for i, sent in enumerate(copies):
                        if bagio.messages_equal(msg, sent):
                            del copies[i]
                            return
                    writer.write(topic, msg)
            return callback

        subs = [node.create_subscription(bagio.msg_class(msgtype), topic, recorder(topic), qos)
                for topic, msgtype in sorted(outputs.items())]
        node_inputs = _subscribed_topics(node, profile.graph)
        _spin_until(executor, procs, lambda: all(
            p.get_subscription_count() > 0 for t, p in pubs.items() if t in node_inputs)
            and all(s.get_publisher_count() > 0 for s in subs), timeout, "matched endpoints")
        t_bag0 = inputs[0].t_ns if inputs else 0
        _clock_handshake(clock_pub, Clock(clock=bagio.ns_to_stamp(t_bag0)), len(profile.graph),
                         procs, timeout)
        spinner = threading.Thread(target=executor.spin, daemon=True)
        spinner.start()
        t_wall0 = time.monotonic()
        for m in tqdm(inputs, disable=not progress, unit="msg", desc="replay"):
            delay = t_wall0 + (m.t_ns - t_bag0) * 1e-9 / rate - time.monotonic()
            if delay > 0.0:
                time.sleep(delay)  # pacing the playback, not waiting for a condition
            clock_pub.publish(Clock(clock=bagio.ns_to_stamp(m.t_ns)))
            if m.topic in overlap:
                with lock:
                    played.setdefault((m.topic, m.t_ns), []).append(m.msg)
            pubs[m.topic].publish(m.msg)
        _wait_quiet(writer, lock, procs, quiet_s=1.0, timeout=timeout)
    finally:
        stop_processes(procs)
        executor.shutdown()
        node.destroy_node()
        context.try_shutdown()
    with lock:
        writer.close()
    return _write_summary(out, bag_path, profile, outages, windows, withheld,
                          "processes", float(rate))


#: Topics every rclpy node publishes: not outputs of the graph.
_DEFAULT_TOPICS = ("/rosout", "/parameter_events")
#: Consecutive identical graph queries (0.05 s apart) after which a node's endpoints count as
#: fully discovered: rmw announces a node's endpoints one by one as it creates them.
_STABLE_POLLS = 5


def _wait_for_graph(node, executor, procs, names, timeout) -> dict:
    """Wait until every graph node is up with its endpoints; return {topic: type} of what the
    nodes publish (every NavNode publishes at least /diagnostics)."""
    wanted = set(names)

    def up():
        return wanted <= {n for n, _ in node.get_node_names_and_namespaces()}

    _spin_until(executor, procs, up, timeout, f"nodes {sorted(wanted)}")

    def endpoints():
        return tuple(sorted(
            (name, kind, topic, tuple(types)) for name in names for kind, query in (
                ("pub", node.get_publisher_names_and_types_by_node),
                ("sub", node.get_subscriber_names_and_types_by_node))
            for topic, types in query(name, "/") if topic not in _DEFAULT_TOPICS))

    seen = [None, 0]

    def settled():
        current = endpoints()
        has_outputs = {n for n, kind, _, _ in current if kind == "pub"} == wanted
        seen[1] = seen[1] + 1 if current == seen[0] and has_outputs else 0
        seen[0] = current
        return seen[1] >= _STABLE_POLLS

    _spin_until(executor, procs, settled, timeout, "the nodes' endpoints")
    return {topic: types[0] for _, kind, topic, types in seen[0] if kind == "pub"}


def _clock_handshake(clock_pub, first, n_nodes, procs, timeout) -> None:
    """Publish the first ``/clock`` until every node's clock subscription acknowledged it.

    A writer matches a reader as soon as it discovers it, but the reader drops data until it
    has discovered the writer in turn, and a volatile reader never gets what came before. Every
    node (``use_sim_time``) subscribes to /clock, and the player's writers are announced
    together, so an acknowledged clock sample means the node knows the data writers too.
    """
    from rclpy.duration import Duration

    deadline = time.monotonic() + timeout
    while True:
        for p in procs:
            if p.poll() is not None:
                raise RuntimeError(f"a node process exited with status {p.returncode}")
        clock_pub.publish(first)
        if clock_pub.get_subscription_count() >= n_nodes and \
                clock_pub.wait_for_all_acked(Duration(seconds=0.1)):
            return
        if time.monotonic() > deadline:
            raise TimeoutError(f"timed out after {timeout} s waiting for the nodes' /clock")


def _subscribed_topics(node, names) -> set:
    return {topic for name in names
            for topic, _ in node.get_subscriber_names_and_types_by_node(name, "/")}


def _spin_until(executor, procs, condition, timeout, what) -> None:
    deadline = time.monotonic() + timeout
    while not condition():
        for p in procs:
            if p.poll() is not None:
                raise RuntimeError(f"a node process exited with status {p.returncode} "
                                   f"while waiting for {what}")
        if time.monotonic() > deadline:
            raise TimeoutError(f"timed out after {timeout} s waiting for {what}")
        executor.spin_once(timeout_sec=0.05)


def _wait_quiet(writer, lock, procs, quiet_s, timeout) -> None:
    """Return once no output arrived for ``quiet_s`` s: the nodes have caught up."""
    deadline = time.monotonic() + timeout
    last, since = -1, time.monotonic()
    while time.monotonic() < deadline:
        with lock:
            count = len(writer)
        if count != last:
            last, since = count, time.monotonic()
        elif time.monotonic() - since > quiet_s:
            return
        time.sleep(0.05)


def stop_processes(procs, timeout=10.0) -> None:
    """SIGINT every running node process (they shut down cleanly), then wait; kill what is
    still running after ``timeout`` s."""
    procs = list(procs)
    for p in procs:
        if p.poll() is None:
            p.send_signal(signal.SIGINT)
    for p in procs:
        try:
            p.wait(timeout)
        except subprocess.TimeoutExpired:
            p.kill()
            p.wait()


def _new_out(out) -> Path:
    out = Path(out)
    if out.exists() and any(out.iterdir()):
        raise ValueError(f"{out} exists and is not empty: choose a new output folder")
    out.mkdir(parents=True, exist_ok=True)
    return out


def _write_summary(out, bag_path, profile, outages, windows, withheld, mode, rate,
                   graph=None, faults=None) -> dict:
    summary = {
        "input_bag": str(Path(bag_path).resolve()),
        "profile": str(profile.path.resolve()),
        "graph": list(profile.graph if graph is None else graph),
        "ignored_sections": list(profile.ignored),
        "mode": mode,
        "rate": rate,
        "outages": outages,
        # Windows on the ROS time axis, s (what trial evaluate needs) and ns (exact).
        "outage_windows_s": (windows * 1e-9).tolist(),
        "outage_windows_ns": windows.tolist(),
        "gnss_withheld": int(withheld),
        "output_bag": "bag",
        "topics": bagio.bag_topics(out / "bag") if (out / "bag").exists() else {},
    }
    if faults is not None:
        summary["faults"] = faults
    (out / "replay.json").write_text(json.dumps(summary, indent=2) + "\n")
    return summary


# ---------------------------------------------------------------------------------------------
# Offline filter path
# ---------------------------------------------------------------------------------------------
#: Parameters of the profile's ``navigator`` section (offline path) and their defaults.
OFFLINE_PARAMS = {
    "imu_grade": "tactical",        # nav.sensor_errors.GRADES key: the filter's IMU noise model
    "bias_model": "rw",             # "rw" (one random-walk bias state) or "gm" (exact model)
    "layout": "15",                 # nav.error_model.LAYOUTS key
    "lever_arm": [0.0, 0.0, 0.0],   # GNSS antenna relative to the IMU, base_link FLU, m
    "mounting_rpy_deg": [0.0, 0.0, 0.0],  # imu/data_raw sensor axes -> base_link (ROS Euler)
    "gnss_sigma_m": 1.0,            # fix standard deviation when the fix has no covariance, m
    "heading": True,                # use gnss/heading (Heading messages)
}


def offline_config(profile: Profile) -> dict:
    """The ``navigator`` section of a profile over :data:`OFFLINE_PARAMS` (unknown keys and
    grades are a :class:`ProfileError`)."""
    from ins_gnss_ros.nav.sensor_errors import GRADES

    section = profile.sections.get("navigator")
    if section is None:
        raise ProfileError(f"{profile.path}: the offline path needs a 'navigator' section")
    unknown = sorted(set(section) - set(OFFLINE_PARAMS))
    if unknown:
        raise ProfileError(f"{profile.path}: navigator: unknown parameter(s) {', '.join(unknown)}"
                           f" (known: {', '.join(OFFLINE_PARAMS)})")
    config = dict(OFFLINE_PARAMS, **section)
    if config["imu_grade"] not in GRADES:
        raise ProfileError(f"{profile.path}: navigator: imu_grade {config['imu_grade']!r} is not"
                           f" one of {', '.join(GRADES)}")
    for key in ("lever_arm", "mounting_rpy_deg"):
        if len(config[key]) != 3:
            raise ProfileError(f"{profile.path}: navigator: {key} needs 3 values")
    return config


def replay_offline(bag_path, profile_path, out, outages=None, progress=False) -> dict:
    """Run the offline navigator over a bag and record ``ins/state`` and ``nav/odom``.

    IMU: ``imu/delta`` as is, or ``imu/data_raw`` rotated by ``mounting_rpy_deg`` into
    base_link and integrated over the stamp intervals (rate x dt, the interval-mean rates of a
    raw IMU message). Aiding: ``gnss/fix`` (its ENU covariance, or ``gnss_sigma_m``),
    ``gnss/vel`` and ``gnss/heading``; ``gnss/*`` is withheld in the outage windows.
    Deterministic like :func:`replay`.
    """
    from ins_gnss_ros import nav as navmod
    from ins_gnss_ros.nav.rotations import dcm_from_euler
    from ins_gnss_ros.nav.sensor_errors import GRADES, filter_noise

    profile = load_profile(profile_path)
    config = offline_config(profile)
    # Every input keeps its place (the time origin t0 is the first input of any topic), but
    # only what the navigator uses is decoded: the IMU topics in bulk, gnss/* one by one.
    topics = _input_topics(bag_path)
    rows = bagio.read_raw(bag_path, topics) if topics else []
    windows = gnss_windows(rows, outages)
    out = _new_out(out)
    nav = navmod.Navigator(navmod.NavigatorConfig(
        noise=filter_noise(GRADES[config["imu_grade"]], config["bias_model"]),
        layout=config["layout"], lever_arm_b=np.asarray(config["lever_arm"], float)))
    c_mount = dcm_from_euler(*np.radians(np.asarray(config["mounting_rpy_deg"], float)))
    t0 = rows[0].t_ns if rows else 0
    imu_at, imu_t, imu_th, imu_dv = _imu_increments(rows, t0, c_mount)
    gnss_at = [k for k, m in enumerate(rows) if m.topic.startswith(GNSS_PREFIX)]
    t_gnss = np.array([rows[k].t_ns for k in gnss_at], np.int64)
    inside = np.any((windows[:, :1] <= t_gnss) & (t_gnss < windows[:, 1:]), axis=0)
    withheld = int(inside.sum())
    used = [k for k, out_of_window in zip(gnss_at, ~inside)
            if out_of_window and rows[k].topic in OFFLINE_GNSS_TOPICS]
    measurements = _gnss_measurements(rows, used, t0, config)
    done = 0

    from tqdm import tqdm

    for k, measurement in tqdm(zip(used, measurements), disable=not progress, unit="msg",
                               desc="offline", total=len(used)):
        if measurement is not None:
            # The IMU samples before it in the stream go first, in one batch.
            end = int(np.searchsorted(imu_at, k))
            if end > done:
                nav.add_imu(imu_t[done:end], imu_th[done:end], imu_dv[done:end])
                done = end
            nav.add_measurement(measurement)
    if len(imu_t) > done:
        nav.add_imu(imu_t[done:], imu_th[done:], imu_dv[done:])
    nav.flush()
    result = nav.output()
    _write_navigator_output(out / "bag", result, t0)
    return _write_summary(out, bag_path, profile, outages, windows, withheld, "offline", 0.0,
                          graph=["navigator"])


#: IMU topics the offline path reads (increments, or raw rates it integrates itself).
OFFLINE_IMU_TOPICS = ("/imu/delta", "/imu/data_raw")
#: GNSS topics it turns into measurements (:func:`_gnss_measurements`).
OFFLINE_GNSS_TOPICS = ("/gnss/fix", "/gnss/vel", "/gnss/heading")


def _imu_increments(rows, t0, c_mount):
    """IMU increments of the offline path from the bag rows, decoded in bulk.

    ``imu/delta`` as is; ``imu/data_raw`` rotated by ``c_mount`` into base_link and integrated
    over the stamp intervals (rate x dt; a sample not later than its predecessor is dropped).

    Returns
    -------
    at : (N,) int
        Position of each sample's message in ``rows``, increasing.
    t : (N,) s after ``t0`` (ns); dtheta, dv : (N, 3) rad, m/s
    """
    from ins_gnss_ros.io import cdr

    parts = []
    for topic in OFFLINE_IMU_TOPICS:
        at = np.array([k for k, m in enumerate(rows) if m.topic == topic], np.int64)
        if not len(at):
            continue
        try:
            cols = cdr.decode_columns(rows[at[0]].msgtype, [rows[k].data for k in at])
        except cdr.CdrLayoutError as err:
            raise bagio.BagError(f"{topic}: {err}") from None
        t = (np.array([rows[k].t_ns for k in at], np.int64) - t0) * 1e-9
        if topic == "/imu/delta":
            parts.append((at, t, _vectors(cols, "delta_angle"), _vectors(cols, "delta_velocity")))
            continue
        dt = np.diff(t)
        keep = np.flatnonzero(dt > 0.0) + 1
        dt = dt[keep - 1, None]
        parts.append((at[keep], t[keep],
                      _rotate(c_mount, _vectors(cols, "angular_velocity")[keep]) * dt,
                      _rotate(c_mount, _vectors(cols, "linear_acceleration")[keep]) * dt))
    if not parts:
        return np.zeros(0, np.int64), np.zeros(0), np.zeros((0, 3)), np.zeros((0, 3))
    order = np.argsort(np.concatenate([p[0] for p in parts]), kind="stable")
    return tuple(np.concatenate([p[i] for p in parts])[order] for i in range(4))


def _rotate(c, v):
    """c @ v[k] (or c[k] @ v[k] for a stack c of (n, 3, 3)) for every row of v (n, 3), as a
    stack of matrix-vector products: bit-identical to the per-row product."""
    return np.matmul(c, v[..., None])[..., 0]


def _vectors(columns, prefix):
    """(n, 3) array of the x, y, z columns of a Vector3 field from :func:`cdr.decode_columns`."""
    return np.stack([columns[f"{prefix}.{c}"] for c in "xyz"], -1)


def _gnss_measurements(rows, at, t0, config) -> list:
    """Navigator measurements of the gnss/* rows at positions ``at`` (None where the topic is
    not used or the message not valid), decoded in bulk per topic."""
    from ins_gnss_ros.io import cdr

    out = [None] * len(at)
    for topic, convert in (("/gnss/fix", _fixes), ("/gnss/vel", _velocities),
                           ("/gnss/heading", _headings)):
        sel = [i for i, k in enumerate(at) if rows[k].topic == topic]
        if not sel or (topic == "/gnss/heading" and not config["heading"]):
            continue
        try:
            cols = cdr.decode_columns(rows[at[sel[0]]].msgtype, [rows[at[i]].data for i in sel])
        except cdr.CdrLayoutError as err:
            raise bagio.BagError(f"{topic}: {err}") from None
        t = ((np.array([rows[at[i]].t_ns for i in sel], np.int64) - t0) * 1e-9).tolist()
        for i, measurement in zip(sel, convert(cols, t, config)):
            out[i] = measurement
    return out


def _fixes(c, t, config):
    """GnssFix of NavSatFix columns: its ENU covariance diagonal, or ``gnss_sigma_m``."""
    from ins_gnss_ros.nav import GnssFix

    position = np.stack([c["latitude"], c["longitude"], c["altitude"]], -1)
    valid = (c["status.status"] >= 0) & np.all(np.isfinite(position), axis=1)
    var = c["position_covariance"][:, [0, 4, 8]]
    given = (c["position_covariance_type"] != 0) & np.all(np.isfinite(var) & (var > 0), axis=1)
    var = np.where(given[:, None], var, config["gnss_sigma_m"] ** 2)
    lat, lon = np.radians(c["latitude"]).tolist(), np.radians(c["longitude"]).tolist()
    h = c["altitude"].tolist()
    return [GnssFix(t[k], lat[k], lon[k], h[k], np.diag(var[k])) if valid[k] else None
            for k in range(len(t))]


def _velocities(c, t, config):
    """GnssVelocity of TwistWithCovarianceStamped columns (valid: finite, positive variances)."""
    from ins_gnss_ros.nav import GnssVelocity

    v = np.stack([c[f"twist.twist.linear.{x}"] for x in "xyz"], -1)
    var = c["twist.covariance"][:, [0, 7, 14]]
    valid = np.all(np.isfinite(v), axis=1) & np.all(np.isfinite(var) & (var > 0), axis=1)
    return [GnssVelocity(t[k], v[k].copy(), np.diag(var[k])) if valid[k] else None
            for k in range(len(t))]


def _headings(c, t, config):
    """HeadingFix of Heading columns (valid: finite azimuth, positive variance)."""
    from ins_gnss_ros.nav import HeadingFix

    valid = np.isfinite(c["azimuth"]) & (c["azimuth_variance"] > 0)
    azimuth, variance = c["azimuth"].tolist(), c["azimuth_variance"].tolist()
    magnetic = (c["reference"] == REFERENCE_MAGNETIC).tolist()
    return [HeadingFix(t[k], azimuth[k], variance[k], magnetic=magnetic[k]) if valid[k]
            else None for k in range(len(t))]


#: ins_gnss_msgs/Heading.REFERENCE_MAGNETIC.
REFERENCE_MAGNETIC = 1
#: Navigator mode -> InsState mode.
_MODES = {"ALIGNING": 0, "NAVIGATING": 1, "DEAD_RECKONING": 2}


def _write_navigator_output(path, result, t0):
    """ins/state and nav/odom (map = ENU at the first epoch) of a NavigatorOutput, serialised
    in bulk (:mod:`ins_gnss_ros.io.cdr`; the fields of :func:`~ins_gnss_ros.trial.contract_messages.ins_state_msg`)."""
    from ins_gnss_ros.nav.earth import ecef_to_enu, geodetic_to_ecef
    from ins_gnss_ros.nav.rotations import quat_to_dcm
    from ins_gnss_ros.io import cdr

    writer = bagio.BagWriter(path)
    n = len(result.t)
    if n == 0:
        return writer.close()
    stamps = bagio.sec_to_ns(result.t, t0)
    enu = ecef_to_enu(geodetic_to_ecef(result.lat, result.lon, result.h),
                      result.lat[0], result.lon[0], result.h[0])
    q, c_nb = result.q_nb, quat_to_dcm(result.q_nb)
    c_bn = c_nb.transpose(0, 2, 1)
    sec, nanosec = np.divmod(stamps, 1_000_000_000)
    header = {"header.stamp.sec": sec, "header.stamp.nanosec": nanosec}
    orientation = {f"orientation.{c}": q[:, i] for i, c in enumerate("wxyz")}
    unknown = np.full((n, 3), np.nan)
    state = dict(header, latitude=result.lat, longitude=result.lon, altitude=result.h,
                 mode=[_MODES.get(str(mode), 3) for mode in result.mode],
                 correction_sequence=0, **_fields("velocity", result.v_enu), **orientation,
                 **_fields("angular_velocity", unknown), **_fields("specific_force", unknown),
                 **_fields("gyro_bias", unknown), **_fields("accel_bias", unknown),
                 **_fields("gyro_scale_factor", np.zeros((n, 3))),
                 **_fields("accel_scale_factor", np.zeros((n, 3))))
    pose, twist = np.zeros((n, 6, 6)), np.zeros((n, 6, 6))
    if result.P is not None:
        space = result.space
        pose[:, :3, :3] = result.P[:, space["pos"], space["pos"]]
        pose[:, 3:, 3:] = result.P[:, space["att"], space["att"]]
        twist[:, :3, :3] = c_bn @ result.P[:, space["vel"], space["vel"]] @ c_nb
        twist[:, 3:, 3:] = -np.eye(3)  # angular rate not estimated
    odom = dict(header, **_fields("pose.pose.position", enu),
                **{"pose.pose." + k: v for k, v in orientation.items()},
                **_fields("twist.twist.linear", _rotate(c_bn, result.v_enu)),
                **_fields("twist.twist.angular", np.zeros((n, 3))),
                **{"pose.covariance": pose.reshape(n, 36),
                   "twist.covariance": twist.reshape(n, 36)})
    states = cdr.encode_columns("ins_gnss_msgs/msg/InsState", state, {"header.frame_id": "map"})
    odoms = cdr.encode_columns("nav_msgs/msg/Odometry", odom,
                       {"header.frame_id": "map", "child_frame_id": "base_link"})
    for t, state_data, odom_data in zip(stamps.tolist(), states, odoms):
        writer.write_raw("ins/state", "ins_gnss_msgs/msg/InsState", t, state_data)
        writer.write_raw("nav/odom", "nav_msgs/msg/Odometry", t, odom_data)
    return writer.close()


def _fields(prefix, xyz):
    """x, y, z columns of a Vector3/Point field for :func:`cdr.encode_columns` from (n, 3) values."""
    return {f"{prefix}.{c}": xyz[:, i] for i, c in enumerate("xyz")}
