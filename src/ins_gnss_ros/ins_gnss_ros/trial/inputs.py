"""What a replay feeds the graph from a bag: every topic but the truth, under absolute names.

Bags name topics with or without the leading ``/`` (``ros2 bag record`` writes absolute names,
other tools relative ones, as the contract's names are); the nodes subscribe to absolute names.
Every topic read here is resolved (:func:`ins_gnss_ros.io.resolve`), so a bag recorded as
``imu/data_raw`` replays like ``/imu/data_raw``, and what the replays record is always fully
qualified. Truth (``truth/*``) never reaches the nodes; it is not even decoded.
"""
from __future__ import annotations

from typing import Callable, Iterator

from ins_gnss_ros import io as bagio

#: Truth never reaches the nodes.
TRUTH_PREFIX = "/truth/"


class InputTopicsError(ValueError):
    """A bag none of whose topics is an input of the graph (nothing would reach the nodes)."""


def bag_rows(bag_path, keep: Callable[[str], bool]) -> Iterator:
    """The undecoded messages of the topics of a bag whose absolute name passes ``keep``.

    Parameters
    ----------
    bag_path : path
        Bag folder.
    keep : callable
        ``keep(topic)`` with the absolute topic name.

    Returns
    -------
    iterator of RawMessage
        Streamed in stamp order (ties in writing order), each under its absolute topic name.
    """
    listed = [t for t in bagio.bag_topics(bag_path) if keep(bagio.resolve(t))]
    if not listed:
        return iter(())
    if all(t.startswith("/") for t in listed):
        return bagio.iter_raw(bag_path, listed)
    # The reader selects topics by absolute name only: read every row and pick them here.
    names = set(listed)
    return (row._replace(topic=bagio.resolve(row.topic)) for row in bagio.iter_raw(bag_path)
            if row.topic in names)


def input_rows(bag_path) -> Iterator:
    """The undecoded messages a graph may see (:func:`bag_rows` of all but ``truth/*``)."""
    return bag_rows(bag_path, lambda topic: not topic.startswith(TRUTH_PREFIX))


def input_count(bag_path) -> int:
    """How many messages :func:`input_rows` gives at most (metadata.yaml's counts: a progress
    bar's total)."""
    return sum(n for topic, n in bagio.bag_message_counts(bag_path).items()
               if not bagio.resolve(topic).startswith(TRUTH_PREFIX))


def read_inputs(bag_path) -> list:
    """The messages a graph may see, decoded: :class:`~ins_gnss_ros.io.BagMessage` list in
    stamp order, absolute topic names."""
    return list(_decoded(bag_path, input_rows(bag_path)))


def iter_topic(bag_path, topic: str) -> Iterator:
    """The messages of one topic (with or without its leading ``/`` in the bag), decoded
    lazily: :class:`~ins_gnss_ros.io.BagMessage` in stamp order, absolute topic name."""
    topic = bagio.resolve(topic)
    return _decoded(bag_path, bag_rows(bag_path, lambda name: name == topic))


def _decoded(bag_path, rows) -> Iterator:
    for row in rows:
        yield bagio.BagMessage(row.topic, row.t_ns, bagio.decode_message(row, bag_path))


def check_inputs(bag_path, inputs) -> None:
    """Refuse a bag none of whose topics is among ``inputs`` (absolute names).

    Raises
    ------
    InputTopicsError
        One line listing the bag's topics and the inputs.
    """
    topics = list(bagio.bag_topics(bag_path))
    if not {bagio.resolve(t) for t in topics} & set(inputs):
        raise InputTopicsError(
            f"{bag_path}: none of the bag's topics ({', '.join(topics) or 'none'}) is an input "
            f"of the graph, whose nodes subscribe to {', '.join(sorted(inputs)) or 'nothing'}")
