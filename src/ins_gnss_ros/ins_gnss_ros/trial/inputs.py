"""What a replay feeds the graph from a bag: every topic but the truth.

Truth (``truth/*``) never reaches the nodes; it is not even decoded.
"""
from __future__ import annotations

from ins_gnss_ros import io as bagio

#: Truth never reaches the nodes.
TRUTH_PREFIX = "/truth/"


def read_inputs(bag_path) -> list:
    """The messages of a bag the graph may see: all but ``truth/*`` (not even decoded)."""
    topics = input_topics(bag_path)
    return bagio.read_bag(bag_path, topics) if topics else []


def input_topics(bag_path) -> list:
    """The topics of a bag the graph may see (all but ``truth/*``), as the bag names them."""
    return [t for t in bagio.bag_topics(bag_path) if not t.startswith(TRUTH_PREFIX)]

