"""Every node console script starts as a real process with a params file and joins the graph."""

from __future__ import annotations

from importlib.metadata import entry_points

import pytest

from conftest import REPO
from rosutil import NodeProcess, wait_for_endpoints

NODES = sorted(ep.name for ep in entry_points(group="console_scripts")
               if ep.value.startswith("ins_gnss_ros.nodes."))
PARAMS = REPO / "config" / "default.yaml"
# (publishes, subscribes) of each node, as ../shared/design/CONTRACT.md fixes them (relative names
# resolve in the root namespace here).
CONTRACT = {
    "imu_preprocessor": (["/imu/data", "/imu/delta", "/imu/mag"], ["/imu/data_raw", "/imu/mag_raw"]),
    "strapdown": (["/ins/state"], ["/imu/delta", "/ins/correction"]),
    "mag_compass": (["/mag/heading"], ["/imu/mag", "/ins/state", "/gnss/fix"]),
    # ins/state (optional in the contract) from the first gnss/observations on: none here
    # (test_phase_heading_node.py::test_publishes_over_ros)
    "phase_heading": (["/gnss/heading"], ["/gnss/observations", "/gnss/ephemeris", "/gnss/fix"]),
    "gnss_driver": (["/gnss/fix", "/gnss/vel", "/gnss/observations", "/gnss/ephemeris",
                     "/gnss/heading", "/gnss/time_reference"], []),
    "gnss_simulator": (["/gnss/fix", "/gnss/vel", "/gnss/observations", "/gnss/ephemeris",
                        "/gnss/time_reference"], ["/sim/truth"]),
    "ekf": (["/ins/correction", "/nav/odom", "/nav/fix", "/nav/status"],
            ["/imu/delta", "/ins/state", "/gnss/fix", "/gnss/vel", "/gnss/heading"]),
    # extension (README): the Foxglove live view
    "live_view": ([], ["/nav/fix", "/gnss/fix", "/nav/odom", "/ins/state", "/nav/status",
                       "/diagnostics"]),
}
# Arguments a node needs beside the params file here: the live view on any free port, so that
# test runs side by side never compete for Foxglove's 8765.
ROS_ARGS = {"live_view": ("-p", "port:=0")}


def test_every_node_is_in_the_contract_table():
    assert NODES and set(NODES) <= set(CONTRACT)


@pytest.mark.parametrize("script", NODES)
def test_node_starts_with_params_file_and_stops_cleanly(script, probe, executor):
    with NodeProcess(script, *ROS_ARGS.get(script, ()), params_file=PARAMS) as proc:
        proc.wait_on_graph(probe, executor)
        publishes, subscribes = CONTRACT[script]
        wait_for_endpoints(probe, executor, publishes, subscribes)
        assert proc.stop() == 0, proc.output()


def test_bad_parameter_is_one_clear_error(tmp_path, probe, executor):
    bad = tmp_path / "bad.yaml"
    bad.write_text("strapdown:\n  ros__parameters:\n    init.latitude_deg: 123.0\n")
    with NodeProcess("strapdown", params_file=bad) as proc:
        assert proc.proc.wait(30) == 2
        out = proc.output()
    assert "init.latitude_deg" in out
    assert "Traceback" not in out
