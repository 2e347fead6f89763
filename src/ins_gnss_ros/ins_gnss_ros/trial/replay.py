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
import subprocess
import sys
import threading
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import yaml

from ins_gnss_ros.nodes import registry
from ins_gnss_ros.trial import bag as bagio
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


def read_inputs(bag_path, plain=False, decode=None) -> list:
    """The messages of a bag the graph may see: all but ``truth/*`` (not even decoded); with
    ``decode`` (topics) only those are decoded, the others come with ``msg`` None."""
    topics = [t for t in bagio.bag_topics(bag_path) if not t.startswith(TRUTH_PREFIX)]
    return bagio.read_bag(bag_path, topics, plain, decode) if topics else []


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
    ``messages`` (:class:`~ins_gnss_ros.trial.bag.BagMessage` list); empty without GNSS."""
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
            writer.write(topic, msg, bagio.stamp_ns(msg) if hasattr(msg, "header")
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
                    copies = played.get((topic, bagio.stamp_ns(msg)), [])
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
        _clock_handshake(clock_pub, Clock(clock=bagio.to_stamp(t_bag0)), len(profile.graph),
                         procs, timeout)
        spinner = threading.Thread(target=executor.spin, daemon=True)
        spinner.start()
        t_wall0 = time.monotonic()
        for m in tqdm(inputs, disable=not progress, unit="msg", desc="replay"):
            delay = t_wall0 + (m.t_ns - t_bag0) * 1e-9 / rate - time.monotonic()
            if delay > 0.0:
                time.sleep(delay)  # pacing the playback, not waiting for a condition
            clock_pub.publish(Clock(clock=bagio.to_stamp(m.t_ns)))
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
            p.send_signal(2)
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
    from ins_gnss_ros.nav import navigator as navmod
    from ins_gnss_ros.nav.rotations import dcm_from_euler
    from ins_gnss_ros.nav.sensor_errors import GRADES, filter_noise

    profile = load_profile(profile_path)
    config = offline_config(profile)
    # Every input keeps its place (the time origin t0 is the first input of any topic), but
    # only what the navigator uses is decoded.
    messages = read_inputs(bag_path, plain=True,
                           decode=[t for t in bagio.bag_topics(bag_path)
                                   if t in OFFLINE_IMU_TOPICS or t.startswith(GNSS_PREFIX)])
    windows = gnss_windows(messages, outages)
    out = _new_out(out)
    nav = navmod.Navigator(navmod.NavigatorConfig(
        noise=filter_noise(GRADES[config["imu_grade"]], config["bias_model"]),
        layout=config["layout"], lever_arm_b=np.asarray(config["lever_arm"], float)))
    c_mount = dcm_from_euler(*np.radians(np.asarray(config["mounting_rpy_deg"], float)))
    t0 = messages[0].t_ns if messages else 0
    imu_t, imu_th, imu_dv = [], [], []
    last_raw = None
    withheld = 0

    def flush_imu():
        if imu_t:
            nav.add_imu(np.array(imu_t), np.array(imu_th), np.array(imu_dv))
            imu_t.clear(), imu_th.clear(), imu_dv.clear()

    from tqdm import tqdm

    for m in tqdm(messages, disable=not progress, unit="msg", desc="offline"):
        t = (m.t_ns - t0) * 1e-9
        msg = m.msg
        if m.topic == "/imu/delta":
            imu_t.append(t), imu_th.append(_xyz(msg.delta_angle)), imu_dv.append(
                _xyz(msg.delta_velocity))
        elif m.topic == "/imu/data_raw":
            if last_raw is not None and t > last_raw:
                dt = t - last_raw
                imu_t.append(t)
                imu_th.append(c_mount @ _xyz(msg.angular_velocity) * dt)
                imu_dv.append(c_mount @ _xyz(msg.linear_acceleration) * dt)
            last_raw = t
        elif m.topic.startswith(GNSS_PREFIX):
            if _in_windows(m.t_ns, windows):
                withheld += 1
                continue
            measurement = _measurement(m.topic, msg, t, config)
            if measurement is not None:
                flush_imu()
                nav.add_measurement(measurement)
    flush_imu()
    nav.flush()
    result = nav.output()
    _write_navigator_output(out / "bag", result, t0)
    return _write_summary(out, bag_path, profile, outages, windows, withheld, "offline", 0.0,
                          graph=["navigator"])


#: IMU topics the offline path reads (increments, or raw rates it integrates itself).
OFFLINE_IMU_TOPICS = ("/imu/delta", "/imu/data_raw")


def _xyz(v):
    return np.array([v.x, v.y, v.z])


def _measurement(topic, msg, t, config):
    """Navigator measurement of a gnss/* message (None: not used or not valid)."""
    from ins_gnss_ros.nav import navigator as navmod

    if topic == "/gnss/fix":
        if msg.status.status < 0 or not np.isfinite([msg.latitude, msg.longitude,
                                                     msg.altitude]).all():
            return None
        var = np.asarray(msg.position_covariance)[[0, 4, 8]]
        if msg.position_covariance_type == 0 or not np.all(np.isfinite(var) & (var > 0)):
            var = np.full(3, config["gnss_sigma_m"] ** 2)
        return navmod.GnssFix(t, np.radians(msg.latitude), np.radians(msg.longitude),
                              msg.altitude, np.diag(var))
    if topic == "/gnss/vel":
        v = _xyz(msg.twist.twist.linear)
        var = np.asarray(msg.twist.covariance)[[0, 7, 14]]
        if not (np.all(np.isfinite(v)) and np.all(np.isfinite(var) & (var > 0))):
            return None
        return navmod.GnssVelocity(t, v, np.diag(var))
    if topic == "/gnss/heading" and config["heading"]:
        if not (np.isfinite(msg.azimuth) and msg.azimuth_variance > 0):
            return None
        return navmod.HeadingFix(t, msg.azimuth, msg.azimuth_variance,
                                 magnetic=msg.reference == REFERENCE_MAGNETIC)
    return None


#: ins_gnss_msgs/Heading.REFERENCE_MAGNETIC.
REFERENCE_MAGNETIC = 1
#: Navigator mode -> InsState mode.
_MODES = {"ALIGNING": 0, "NAVIGATING": 1, "DEAD_RECKONING": 2}


def _write_navigator_output(path, result, t0):
    """ins/state and nav/odom (map = ENU at the first epoch) of a NavigatorOutput."""
    from geometry_msgs.msg import Point, Quaternion
    from nav_msgs.msg import Odometry

    from ins_gnss_ros.nav.earth import ecef_to_enu, geodetic_to_ecef
    from ins_gnss_ros.nav.rotations import quat_to_dcm

    writer = bagio.BagWriter(path)
    if len(result.t) == 0:
        return writer.close()
    stamps = bagio.seconds_to_ns(result.t, t0)
    enu = ecef_to_enu(geodetic_to_ecef(result.lat, result.lon, result.h),
                      result.lat[0], result.lon[0], result.h[0])
    space = result.space
    c_nb = quat_to_dcm(result.q_nb)
    for k, t in enumerate(stamps):
        state = bagio.ins_state_msg(t, result.lat[k], result.lon[k], result.h[k],
                                    result.v_enu[k], result.q_nb[k])
        state.mode = _MODES.get(str(result.mode[k]), 3)
        writer.write("ins/state", state)
        odom = Odometry(child_frame_id="base_link")
        odom.header.stamp, odom.header.frame_id = bagio.to_stamp(t), "map"
        odom.pose.pose.position = Point(x=float(enu[k, 0]), y=float(enu[k, 1]),
                                        z=float(enu[k, 2]))
        q = result.q_nb[k]
        odom.pose.pose.orientation = Quaternion(w=float(q[0]), x=float(q[1]), y=float(q[2]),
                                                z=float(q[3]))
        v_body = c_nb[k].T @ result.v_enu[k]
        odom.twist.twist.linear.x, odom.twist.twist.linear.y, odom.twist.twist.linear.z = (
            float(x) for x in v_body)
        if result.P is not None:
            P = result.P[k]
            pose = np.zeros((6, 6))
            pose[:3, :3] = P[space["pos"], space["pos"]]
            pose[3:, 3:] = P[space["att"], space["att"]]
            twist = np.full((6, 6), 0.0)
            twist[:3, :3] = c_nb[k].T @ P[space["vel"], space["vel"]] @ c_nb[k]
            twist[3:, 3:] = -np.eye(3)  # angular rate not estimated
            odom.pose.covariance = pose.ravel().tolist()
            odom.twist.covariance = twist.ravel().tolist()
        writer.write("nav/odom", odom)
    return writer.close()
