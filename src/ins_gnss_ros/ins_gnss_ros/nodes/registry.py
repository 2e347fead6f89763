"""The project's nodes by executable name, for tools that build a graph (replay, supervisor).

Values are ``module:Class`` so that importing the registry does not import every node.
"""

from __future__ import annotations

from importlib import import_module

NODES = {
    "imu_preprocessor": "ins_gnss_ros.nodes.imu_preprocessor_node:ImuPreprocessorNode",
    "strapdown": "ins_gnss_ros.nodes.strapdown_node:StrapdownNode",
    "mag_compass": "ins_gnss_ros.nodes.mag_compass_node:MagCompassNode",
    "phase_heading": "ins_gnss_ros.nodes.phase_heading_node:PhaseHeadingNode",
    "gnss_driver": "ins_gnss_ros.nodes.gnss_driver_node:GnssDriverNode",
    "gnss_simulator": "ins_gnss_ros.nodes.gnss_simulator_node:GnssSimulatorNode",
    "ekf": "ins_gnss_ros.nodes.ekf_node:EkfNode",
    # optional: runs where a profile has a live_view section (config/default.yaml has none)
    "live_view": "ins_gnss_ros.nodes.live_view_node:LiveViewNode",
}

#: Nodes that make sensor data (from a receiver, from a simulation): a replay's sensors are the
#: bag, so a replay leaves them out of the graph (``trial run`` keeps them).
SENSOR_SOURCES = ("gnss_driver", "gnss_simulator")


def node_class(name: str):
    """The NavNode subclass of executable ``name`` (KeyError names the known ones)."""
    try:
        module, cls = NODES[name].split(":")
    except KeyError:
        raise KeyError(f"unknown node {name!r}; known: {', '.join(sorted(NODES))}") from None
    return getattr(import_module(module), cls)
