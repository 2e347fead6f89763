"""The project's nodes by executable name, for tools that build a graph (replay, supervisor).

Values are ``module:Class`` so that importing the registry does not import every node.
"""

from __future__ import annotations

from importlib import import_module

NODES = {
    "strapdown": "ins_gnss_ros.nodes.strapdown_node:StrapdownNode",
}


def node_class(name: str):
    """The NavNode subclass of executable ``name`` (KeyError names the known ones)."""
    try:
        module, cls = NODES[name].split(":")
    except KeyError:
        raise KeyError(f"unknown node {name!r}; known: {', '.join(sorted(NODES))}") from None
    return getattr(import_module(module), cls)
