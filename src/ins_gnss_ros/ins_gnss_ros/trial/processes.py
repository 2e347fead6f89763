"""``trial replay --rate R --processes``: the graph's nodes as processes on DDS, in real time.

The nodes run as console-script processes with ``use_sim_time``; a player publishes ``/clock``
and the bag messages at R times the bag's pace; a recorder subscribes to every topic the nodes
publish (played copies on a topic a node also publishes are recognised and left out). Playing
starts only once every endpoint is matched and every node acknowledged the first ``/clock``
(graph queries and DDS acknowledgements, no fixed sleeps). Not deterministic: DDS on a loaded
machine may drop messages from a reader's KEEP_LAST history; use
:func:`ins_gnss_ros.trial.replay.replay` for evaluation runs.

:func:`stop_processes` also stops the supervised graph of ``trial run``.
"""
from __future__ import annotations

import os
import signal
import subprocess
import sys
import threading
import time
from collections import Counter
from pathlib import Path

from ins_gnss_ros import io as bagio
from ins_gnss_ros.trial.inputs import check_inputs, conversion_notes, read_inputs
from ins_gnss_ros.trial.outages import gnss_windows, in_gnss_outage
from ins_gnss_ros.trial.profile import load_profile, profile_with_installation, \
    profile_with_truth_init
from ins_gnss_ros.trial.run_folder import MessageCounts, new_run_folder, write_summary


def replay_processes(bag_path, profile_path, out, rate=1.0, outages=None, progress=False,
                     init_from_truth=False, timeout=30.0, remap=None) -> dict:
    """Run the graph as node processes on DDS, playing the bag at ``rate`` times real time
    (``remap`` as :func:`~ins_gnss_ros.trial.replay.replay`'s).

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

    from ins_gnss_ros.nodes.base import TF_STATIC_READ_QOS

    if not rate > 0.0:
        raise ValueError(f"--rate must be > 0, got {rate}")
    profile = load_profile(profile_path)
    messages = read_inputs(bag_path, remap)
    windows = gnss_windows(messages, outages)
    out = new_run_folder(out)
    profile, installed = profile_with_installation(profile, bag_path, out / "profile.yaml",
                                                   remap)
    if init_from_truth:
        profile = load_profile(profile_with_truth_init(profile, bag_path, out / "profile.yaml"))
    inputs = [m for m in messages if not in_gnss_outage(m.topic, m.t_ns, windows)]
    counts = MessageCounts(played=Counter(m.topic for m in inputs), withheld=Counter(
        m.topic for m in messages if in_gnss_outage(m.topic, m.t_ns, windows)))
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
            # (/tf_static latched, as its readers ask: a volatile writer would never match them)
            pubs[m.topic] = node.create_publisher(
                type(m.msg), m.topic, TF_STATIC_READ_QOS if m.topic == "/tf_static" else qos)
    procs = [subprocess.Popen(
        [str(Path(sys.executable).parent / name), "--ros-args", "--params-file",
         str(profile.path), "-p", "use_sim_time:=true"],
        stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, env=dict(os.environ))
        for name in profile.replay_graph]
    writer = bagio.BagWriter(out / "bag")
    lock = threading.Lock()
    try:
        outputs = _wait_for_graph(node, executor, procs, profile.replay_graph, timeout)

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
                    counts.recorded[topic] += 1
            return callback

        subs = [node.create_subscription(bagio.msg_class(msgtype), topic, recorder(topic), qos)
                for topic, msgtype in sorted(outputs.items())]
        node_inputs = _subscribed_topics(node, profile.replay_graph)
        # /clock comes from the player, the default topics from rclpy: not the bag's to feed.
        unread = check_inputs(bag_path, {topic: msgtype for topic, msgtype in node_inputs.items()
                                         if topic not in {"/clock", *_DEFAULT_TOPICS}},
                              remap, set(outputs))
        _spin_until(executor, procs, lambda: all(
            p.get_subscription_count() > 0 for t, p in pubs.items() if t in node_inputs)
            and all(s.get_publisher_count() > 0 for s in subs), timeout, "matched endpoints")
        t_bag0 = inputs[0].t_ns if inputs else 0
        _clock_handshake(clock_pub, Clock(clock=bagio.ns_to_stamp(t_bag0)),
                         len(profile.replay_graph), procs, timeout)
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
    return write_summary(out, bag_path, profile, outages, windows, counts,
                         "processes", float(rate), unread=unread, installation=installed,
                         converted=conversion_notes(bag_path, remap))


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


def _subscribed_topics(node, names) -> dict:
    """{topic: type name} of the subscriptions of the nodes ``names``."""
    return {topic: types[0] for name in names
            for topic, types in node.get_subscriber_names_and_types_by_node(name, "/")}


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
    """SIGTERM every running node process, then wait; kill what is still running after
    ``timeout`` s.

    SIGTERM, not SIGINT: a node that is up shuts down cleanly on either (``nodes/base.py``
    ``run``), but one still starting (importing, before rclpy handles signals) would print a
    KeyboardInterrupt traceback on SIGINT, and ends silently on SIGTERM.
    """
    procs = list(procs)
    for p in procs:
        if p.poll() is None:
            p.send_signal(signal.SIGTERM)
    for p in procs:
        try:
            p.wait(timeout)
        except subprocess.TimeoutExpired:
            p.kill()
            p.wait()
