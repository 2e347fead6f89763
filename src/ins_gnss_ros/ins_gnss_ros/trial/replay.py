"""``trial replay``: run the node graph of a profile over a bag and record what the nodes publish.

The graph is every node of :mod:`ins_gnss_ros.nodes.registry` that has a section in the profile
(a ROS 2 params file, :mod:`ins_gnss_ros.trial.profile`); nothing here knows a particular node.
Three ways to run it:

* :func:`replay` (default, this module): deterministic and as fast as possible. One process, one
  rclpy context, the nodes on an :class:`~ins_gnss_ros.nodes.base.InProcessBus`, each given the
  profile with ``--params-file`` exactly as on the command line. Bag messages go in stamp order:
  set the bus time, publish, deliver everything that follows from it, next message. Diagnostics
  are published once per second of bag time. The same bag, profile and outages give the
  identical (decoded) output, run after run.
* :func:`~ins_gnss_ros.trial.processes.replay_processes` (``--rate R --processes``): the nodes
  as console-script processes on DDS with ``use_sim_time``, played at R times the bag's pace.
* :func:`~ins_gnss_ros.trial.offline.replay_offline` (``--offline``): the offline filter path,
  no ROS graph.

GNSS outages (:mod:`ins_gnss_ros.trial.outages`) withhold every ``gnss/*`` message whose stamp
falls in a window; satellite windows (``--satellites``, in-process only) keep the N highest
satellites in ``gnss/observations`` and withhold ``gnss/fix`` / ``gnss/vel``; the windows are
written to ``OUT/replay.json`` with the run's other facts (:mod:`ins_gnss_ros.trial.run_folder`).
A fault specification (:mod:`ins_gnss_ros.faults`, in-process :func:`replay` only) passes the
bag's messages through a :class:`~ins_gnss_ros.faults.inject.FaultInjector` before they reach
the nodes; what each fault did goes into ``replay.json`` under ``faults``.
"""
from __future__ import annotations

from collections import Counter

from ins_gnss_ros import io as bagio
from ins_gnss_ros.gnss.constants import UBX_GNSS_ID
from ins_gnss_ros.nodes import registry
from ins_gnss_ros.trial.inputs import InputTopicsError, check_inputs, conversion_notes, \
    input_types, read_inputs
from ins_gnss_ros.trial.outages import gnss_windows, highest_satellites, in_gnss_outage, \
    parse_satellite_spec, reduce_constellation
from ins_gnss_ros.trial.profile import ProfileError, load_profile, \
    profile_with_installation, profile_with_truth_init
from ins_gnss_ros.trial.run_folder import MessageCounts, new_run_folder, write_summary

#: Bag-time interval of the diagnostics the replay asks every node to publish, ns.
DIAGNOSTICS_PERIOD_NS = 1_000_000_000


def replay(bag_path, profile_path, out, outages=None, progress=False,
           init_from_truth=False, faults=None, satellites=None, remap=None) -> dict:
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
    satellites : str, optional
        ``N:LEN:PERIOD[:FIRST]``: in those windows only the N highest satellites stay in
        ``gnss/observations`` and ``gnss/fix`` / ``gnss/vel`` are withheld
        (:func:`~ins_gnss_ros.trial.outages.reduce_constellation`).
    remap : dict, optional
        {bag topic: graph topic}, absolute names (:func:`~ins_gnss_ros.trial.inputs.parse_remap`).

    Returns
    -------
    dict
        What ``replay.json`` holds.

    Raises
    ------
    ins_gnss_ros.faults.spec.FaultSpecError
        An unusable fault specification (before anything is written).
    ProfileError
        A node refused the profile's parameters.
    ins_gnss_ros.trial.inputs.InputTopicsError
        No topic of the bag is one the nodes subscribe to, or one they subscribe to is of
        another type in the bag.
    """
    import rclpy
    from rclpy.exceptions import ParameterException
    from tqdm import tqdm

    from ins_gnss_ros.nodes.base import ParameterError

    profile = load_profile(profile_path)
    injector = None
    if faults is not None:
        from ins_gnss_ros.faults import FaultInjector, load_fault_spec

        injector = FaultInjector(load_fault_spec(faults))
    # The bag's payloads go to the nodes as they are unless faults or satellite windows,
    # which act on message objects, come between.
    payloads = injector is None and satellites is None
    messages = read_inputs(bag_path, remap, payloads)
    windows = gnss_windows(messages, outages)
    counts = MessageCounts(withheld=Counter(
        m.topic for m in messages if in_gnss_outage(m.topic, m.t_ns, windows)))
    reduced = None
    if satellites is not None:
        spec = parse_satellite_spec(satellites)
        sat_windows = gnss_windows(messages, str(spec.windows))
        kept = highest_satellites(messages, sat_windows, spec.count)
        messages, thinned = reduce_constellation(messages, sat_windows, kept)
        counts.withheld.update(thinned)
        reduced = {"satellites": satellites, "satellite_windows_s": (sat_windows * 1e-9).tolist(),
                   "satellite_windows_ns": sat_windows.tolist(),
                   "satellites_kept": [[f"{UBX_GNSS_ID[s]}{p:02d}" for s, p in k] for k in kept]}
    stream = messages
    if injector is not None:
        # Outages are decided on the bag's own time; faults act on what is left.
        stream = (bagio.BagMessage(topic, t_ns, msg) for t_ns, topic, msg in injector(
            (m.t_ns, m.topic, m.msg) for m in messages
            if not in_gnss_outage(m.topic, m.t_ns, windows)))
    out = new_run_folder(out)
    profile, installed = profile_with_installation(profile, bag_path, out / "profile.yaml",
                                                   remap)
    if init_from_truth:
        profile = load_profile(profile_with_truth_init(profile, bag_path, out / "profile.yaml"))
    writer = bagio.BagWriter(out / "bag")
    context = rclpy.Context()
    rclpy.init(context=context, args=[])
    bus = _bus()

    def record(topic, msg, cls):
        """What a node published, as it was published (object or payload)."""
        if type(msg) is not bytes:
            header = getattr(msg, "header", None)
            writer.write(topic, msg, bus.now_ns if header is None
                         else bagio.stamp_to_ns(header.stamp))
        elif bagio.starts_with_header(cls):
            writer.write_raw(topic, bagio.msgtype_of_class(cls), bagio.payload_stamp_ns(msg),
                             msg)
        else:
            writer.write(topic, bagio.codec(cls).decode(msg), bus.now_ns)
        counts.recorded[topic] += 1

    bus.raw_recorders.append(record)
    nodes = []
    try:
        for name in profile.replay_graph:
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
        unread = check_inputs(bag_path, bus.inputs, remap, bus.published)
        # The bag's type on each topic the nodes take: theirs, or one clear error now
        # rather than a traceback from a node (and the type the bus decodes payloads as).
        for topic, msgtype in input_types(bag_path, remap).items():
            if topic in bus.inputs:
                try:
                    bus.advertise(topic, bagio.msg_class(msgtype))
                except TypeError as err:
                    raise InputTopicsError(f"{bag_path}: {err} (the bag's type on a topic "
                                           "the nodes take)") from None
        next_diag = messages[0].t_ns + DIAGNOSTICS_PERIOD_NS if messages else 0
        for m in tqdm(stream, disable=not progress, unit="msg", desc="replay",
                      total=len(messages)):
            while m.t_ns >= next_diag:
                bus.now_ns = next_diag
                for node in nodes:
                    node.diag.publish()
                bus.drain()
                next_diag += DIAGNOSTICS_PERIOD_NS
            # Withheld: with faults, only one a fault moved into a window gets this far.
            if in_gnss_outage(m.topic, m.t_ns, windows):
                continue
            bus.now_ns = m.t_ns
            bus.publish(m.topic, m.msg, recorded=False)
            counts.played[m.topic] += 1
            bus.drain()
    finally:
        for node in nodes:
            node.destroy_node()
        context.try_shutdown()
    writer.close()
    return write_summary(out, bag_path, profile, outages, windows, counts, "in-process", 0.0,
                         faults=None if injector is None else injector.summary(),
                         satellites=reduced, unread=unread, installation=installed,
                         converted=conversion_notes(bag_path, remap))


def _bus():
    # Defined when a replay runs: nodes.base imports rclpy, which this module loads only then.
    from ins_gnss_ros.nodes.base import InProcessBus

    class Bus(InProcessBus):
        """The bus, keeping the topics the nodes subscribe to and their types: the graph's
        inputs."""

        def __init__(self):
            super().__init__()
            self.inputs = {}

        def subscribe(self, topic, callback, form=InProcessBus.OBJECT, msg_type=None):
            self.inputs[self.resolve(topic)] = None if msg_type is None \
                else bagio.msgtype_of_class(msg_type)
            super().subscribe(topic, callback, form, msg_type)

    return Bus()
