"""Launch files (ROS launch is not on PyPI: checked statically here, run in a full ROS install)."""

from __future__ import annotations

import ast
import re
from importlib.metadata import entry_points

from conftest import REPO

NODE_SCRIPTS = {ep.name for ep in entry_points(group="console_scripts")
                if ep.value.startswith("ins_gnss_ros.nodes.")}


def test_launch_files_parse_and_name_only_registered_or_contract_nodes():
    files = sorted((REPO / "launch").glob("*.launch.py"))
    assert files
    contract = {"imu_preprocessor", "strapdown", "gnss_driver", "gnss_simulator", "phase_heading",
                "mag_compass", "ekf"}
    for path in files:
        tree = ast.parse(path.read_text(), str(path))
        assert any(isinstance(n, ast.FunctionDef) and n.name == "generate_launch_description"
                   for n in tree.body), path
        graph = re.search(r'LIVE_GRAPH = "([^"]+)"', path.read_text())
        names = set(graph.group(1).split(",")) if graph else set()
        assert names <= contract, names - contract
    extensions = {"live_view"}  # README "Extensions of the interface contract"
    assert NODE_SCRIPTS <= contract | extensions
