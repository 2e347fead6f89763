"""What a replay feeds the graph from a bag: every topic but the truth, under absolute names.

Bags name topics with or without the leading ``/`` (``ros2 bag record`` writes absolute names,
other tools relative ones, as the contract's names are); the nodes subscribe to absolute names.
Every topic read here is resolved (:func:`ins_gnss_ros.io.resolve`), so a bag recorded as
``imu/data_raw`` replays like ``/imu/data_raw``, and what the replays record is always fully
qualified. Truth (``truth/*``) never reaches the nodes; it is not even decoded.

A bag recorded under other names (a driver's ``/fix``, ``/imu/data``) replays with a remapping,
``{bag topic: graph topic}`` (``trial replay --remap /fix:=/gnss/fix``, as ``ros2 bag play
--remap`` does), applied to the absolute names. :func:`check_inputs` names the remapping: a
bag topic no node reads whose type is that of a sensor input the bag lacks.

A velocity recorded without its covariance, as drivers publish one (nmea_navsat_driver's
``vel`` is a ``geometry_msgs/TwistStamped``), is read on ``gnss/vel`` and ``log/speed`` as the
``TwistWithCovarianceStamped`` the graph takes there, with an all-zero covariance: the ekf takes
that as none given and assumes one, named on /diagnostics (:data:`CONVERSIONS`). The live graph
cannot: a ROS topic has one type.
"""
from __future__ import annotations

from typing import Callable, Iterator, Mapping

from ins_gnss_ros import io as bagio

#: Truth never reaches the nodes.
TRUTH_PREFIX = "/truth/"
#: Read by nodes where a bag has them (the installation: imu_preprocessor), never a sensor
#: input a bag lacks: no other topic is proposed for them.
FRAME_TOPICS = ("/tf", "/tf_static")

#: A velocity as drivers record it without its covariance, and as the graph takes it.
TWIST = "geometry_msgs/msg/TwistStamped"
TWIST_WITH_COVARIANCE = "geometry_msgs/msg/TwistWithCovarianceStamped"


def _twist_without_covariance(msg):
    """A TwistStamped as a TwistWithCovarianceStamped whose covariance is all zero (none)."""
    from geometry_msgs.msg import TwistWithCovarianceStamped

    out = TwistWithCovarianceStamped(header=msg.header)
    out.twist.twist = msg.twist
    return out


#: (graph topic, bag type) -> (the type the graph takes there, conversion of a decoded message).
CONVERSIONS = {(topic, TWIST): (TWIST_WITH_COVARIANCE, _twist_without_covariance)
               for topic in ("/gnss/vel", "/log/speed")}


class InputTopicsError(ValueError):
    """A bag none of whose topics is an input of the graph (nothing would reach the nodes), or
    one whose type on an input is not the one the nodes take."""


def parse_remap(rules) -> dict[str, str]:
    """``FROM:=TO`` rules (``ros2 bag play --remap``'s form) as {absolute FROM: absolute TO}.

    Raises
    ------
    ValueError
        A rule without ``:=`` or with an empty side.
    """
    remap = {}
    for rule in rules or ():
        source, sep, target = rule.partition(":=")
        if not (sep and source.strip() and target.strip()):
            raise ValueError(f"--remap {rule!r}: expected FROM:=TO, e.g. /fix:=/gnss/fix")
        remap[bagio.resolve(source.strip())] = bagio.resolve(target.strip())
    return remap


def _topics(bag_path, remap) -> dict[str, tuple[str, str]]:
    """The bag's topics -> (the absolute name the graph sees it under, the bag's type), from one
    reading of its metadata."""
    remap = remap or {}
    return {t: (remap.get(bagio.resolve(t), bagio.resolve(t)), msgtype)
            for t, msgtype in bagio.bag_topics(bag_path).items()}


def bag_rows(bag_path, keep: Callable[[str], bool], remap=None) -> Iterator:
    """The undecoded messages of the topics of a bag whose absolute name passes ``keep``.

    Parameters
    ----------
    bag_path : path
        Bag folder.
    keep : callable
        ``keep(topic)`` with the absolute topic name (after ``remap``).
    remap : dict, optional
        {absolute bag topic: absolute name} (:func:`parse_remap`).

    Returns
    -------
    iterator of RawMessage
        Streamed in stamp order (ties in writing order), each under its absolute topic name,
        of the type the graph takes on it (:data:`CONVERSIONS`).
    """
    topics = _topics(bag_path, remap)
    listed = [t for t, (name, _) in topics.items() if keep(name)]
    if not listed:
        return iter(())
    if all(t.startswith("/") for t in listed):
        rows = bagio.iter_raw(bag_path, listed)
    else:
        # The reader selects topics by absolute name only: read every row and pick them here.
        selected = set(listed)
        rows = (row for row in bagio.iter_raw(bag_path) if row.topic in selected)
    if any(t != topics[t][0] for t in listed):
        rows = (row._replace(topic=topics[row.topic][0]) for row in rows)
    if any(topics[t] in CONVERSIONS for t in listed):
        rows = (_converted(row, bag_path) for row in rows)
    return rows


def _converted(row, bag_path):
    """A row of a type the graph takes converted on its topic (:data:`CONVERSIONS`), or the
    row."""
    conversion = CONVERSIONS.get((row.topic, row.msgtype))
    if conversion is None:
        return row
    msgtype, convert = conversion
    return row._replace(msgtype=msgtype,
                        data=bagio.serialize(convert(bagio.decode_message(row, bag_path))))


def input_rows(bag_path, remap=None) -> Iterator:
    """The undecoded messages a graph may see (:func:`bag_rows` of all but ``truth/*``)."""
    return bag_rows(bag_path, lambda topic: not topic.startswith(TRUTH_PREFIX), remap)


def input_count(bag_path, remap=None) -> int:
    """How many messages :func:`input_rows` gives at most (metadata.yaml's counts: a progress
    bar's total)."""
    topics = _topics(bag_path, remap)
    return sum(n for topic, n in bagio.bag_message_counts(bag_path).items()
               if not topics[topic][0].startswith(TRUTH_PREFIX))


def read_inputs(bag_path, remap=None, payloads: bool = False) -> list:
    """The messages a graph may see: :class:`~ins_gnss_ros.io.BagMessage` list in stamp order,
    absolute topic names (after ``remap``), decoded.

    With ``payloads``, those of a type with a fixed layout (:func:`payload_types`) are kept as
    their CDR payloads, checked against the layout but not decoded: an in-process bus hands
    them as they are to a node that reads them by field, and decodes them once for one that
    takes message objects.

    Raises
    ------
    ins_gnss_ros.io.BagError
        A message that does not decode, or a payload that does not fit its type's layout.
    """
    rows = input_rows(bag_path, remap)
    if not payloads:
        return list(_decoded(bag_path, rows))
    checks = {topic: bagio.field_reader(msgtype, ())
              for topic, msgtype in payload_types(bag_path, remap).items()}
    out = []
    for row in rows:
        check = checks.get(row.topic)
        if check is None:
            out.append(bagio.BagMessage(row.topic, row.t_ns, bagio.decode_message(row, bag_path)))
            continue
        try:
            check(row.data)
        except bagio.CdrLayoutError as err:
            raise bagio.BagError(f"{bag_path}: message on {row.topic} at {row.t_ns} ns does not "
                                 f"decode ({err})") from None
        out.append(bagio.BagMessage(row.topic, row.t_ns, row.data))
    return out


def conversion_notes(bag_path, remap=None) -> list[str]:
    """One line per bag topic read as another type (:data:`CONVERSIONS`)."""
    return [f"{topic} ({msgtype}) read as {CONVERSIONS[(name, msgtype)][0]} without a "
            "covariance: the ekf assumes one"
            for topic, (name, msgtype) in _topics(bag_path, remap).items()
            if (name, msgtype) in CONVERSIONS]


def input_types(bag_path, remap=None) -> dict[str, str]:
    """{absolute topic (after ``remap``): type name} of the bag's topics a graph may see."""
    return {name: CONVERSIONS.get((name, msgtype), (msgtype,))[0]
            for name, msgtype in _topics(bag_path, remap).values()
            if not name.startswith(TRUTH_PREFIX)}


def payload_types(bag_path, remap=None) -> dict[str, str]:
    """:func:`input_types` of a fixed layout (no sequences, at most one string:
    :func:`~ins_gnss_ros.io.field_reader` reads it)."""
    out = {}
    for topic, msgtype in input_types(bag_path, remap).items():
        try:
            bagio.field_reader(msgtype, ())
        except bagio.CdrLayoutError:   # a sequence, two strings, or not installed
            continue
        out[topic] = msgtype
    return out


def iter_topic(bag_path, topic: str) -> Iterator:
    """The messages of one topic (with or without its leading ``/`` in the bag), decoded
    lazily: :class:`~ins_gnss_ros.io.BagMessage` in stamp order, absolute topic name."""
    topic = bagio.resolve(topic)
    return _decoded(bag_path, bag_rows(bag_path, lambda name: name == topic))


def _decoded(bag_path, rows) -> Iterator:
    for row in rows:
        yield bagio.BagMessage(row.topic, row.t_ns, bagio.decode_message(row, bag_path))


def check_inputs(bag_path, inputs: Mapping[str, str | None], remap=None,
                 published=frozenset()) -> list[str]:
    """Refuse a bag none of whose topics (after ``remap``) is among ``inputs``; name the bag's
    topics no node reads that could feed an input the bag lacks.

    Parameters
    ----------
    inputs : mapping
        {absolute name: type name} of the topics the graph's nodes subscribe to (type None
        where it is not known).
    published : set of str
        Topics the graph publishes itself (``/imu/delta`` beside the imu_preprocessor): a bag
        may feed them, but none is proposed as the place of a bag topic no node reads.

    Returns
    -------
    list of str
        One note per bag topic (not truth) that no node reads and whose type is that of inputs
        the bag lacks (a driver's ``/fix`` beside the bag's ``/imu/data_raw``: the graph would
        run without GNSS and say only that none arrives), with the remapping that feeds it.

    Raises
    ------
    InputTopicsError
        One line listing the bag's topics, the inputs and the remappings that would feed them.
    """
    topics = _topics(bag_path, remap)
    names = {topic: name for topic, (name, _) in topics.items()}
    types = {topic: msgtype for topic, (_, msgtype) in topics.items()}
    lacking = sorted(topic for topic, msgtype in inputs.items()
                     if msgtype is not None and topic not in published
                     and topic not in names.values() and topic not in FRAME_TOPICS)

    def feeds(topic):
        """The lacking inputs the bag topic could feed (of their type, or converted to it)."""
        return [target for target in lacking
                if types[topic] == inputs[target] or (target, types[topic]) in CONVERSIONS]

    rules = {topic: " or ".join(f"--remap {topic}:={target}" for target in feeds(topic))
             for topic, name in names.items()
             if name not in inputs and not name.startswith(TRUTH_PREFIX) and feeds(topic)}
    if not set(names.values()) & set(inputs):
        shown = [t if bagio.resolve(t) == name else f"{t} (as {name})"
                 for t, name in names.items()]
        raise InputTopicsError(
            f"{bag_path}: none of the bag's topics ({', '.join(shown) or 'none'}) is an input "
            f"of the graph, whose nodes subscribe to {', '.join(sorted(inputs)) or 'nothing'} "
            f"(a bag recorded under other names: "
            f"{' '.join(rules.values()) if rules else '--remap FROM:=TO'})")
    return [f"{topic} ({types[topic]}) is read by no node: {rule}"
            for topic, rule in rules.items()]
