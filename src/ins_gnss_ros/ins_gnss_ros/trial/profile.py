"""Profiles: the ROS 2 params file that selects and configures a graph.

The graph of a profile is every node of :mod:`ins_gnss_ros.nodes.registry` that has a section in
it; nothing here knows a particular node. :func:`profile_with_truth_init` derives a profile that
starts the nodes from a bag's first truth (``trial replay --init-from-truth``).
"""
from __future__ import annotations

import copy
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import yaml

from ins_gnss_ros.nodes import registry
from ins_gnss_ros.trial.inputs import TRUTH_PREFIX, iter_topic


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

    @property
    def replay_graph(self) -> tuple:
        """The graph a replay runs: without the sensor sources (the bag is the sensor;
        a profile for live use, such as config/default.yaml, names them)."""
        return tuple(name for name in self.graph if name not in registry.SENSOR_SOURCES)


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



def truth_init_parameters(bag_path) -> dict:
    """``init.*`` parameters (strapdown naming, degrees) of the first ``truth/state`` of a bag;
    components the truth lacks (NaN) are left out. Empty without truth."""
    from ins_gnss_ros.nav.conventions import azimuth_from_yaw
    from ins_gnss_ros.nav.rotations import quat_to_euler

    truth = next(iter_topic(bag_path, TRUTH_PREFIX + "state"), None)
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
    sections = {}
    for name, section in profile.sections.items():
        if name in profile.graph:
            declared = {spec.name for spec in node_class(name).PARAMS}
            section = {**section, **{k: v for k, v in params.items() if k in declared}}
        sections[name] = section
    return _write(sections, path)


def _write(sections: dict, path) -> Path:
    """A params file of these node sections at path."""
    # Copies, not shared lists: yaml would write an alias, which rcl refuses.
    data = {"/" + name: {"ros__parameters": copy.deepcopy(section)}
            for name, section in sections.items()}
    path = Path(path)
    path.write_text(yaml.safe_dump(data, sort_keys=False))
    return path


#: Where a replay puts the installation the bag's /tf_static gives (trial/installation.py):
#: parameter -> node section.
INSTALLATION_PARAMS = {"mounting_rpy_deg": "imu_preprocessor", "lever_arm": "ekf"}


def profile_with_installation(profile: Profile, bag_path, path=None,
                              remap=None) -> tuple[Profile, list]:
    """``profile`` with the IMU mounting and antenna lever arm of the bag's /tf_static
    (:func:`~ins_gnss_ros.trial.installation.installation`) where its sections run and leave
    them at zero, the value that stands for "not known" (config/default.yaml writes it; an
    imu_preprocessor with a ``calibration_file`` keeps that file's mounting), written to
    ``path`` if given and anything was taken (the nodes read a params file); and what was
    taken, kept or not found, as lines."""
    from ins_gnss_ros.imu.preprocessor_params import mounting_given
    from ins_gnss_ros.trial.installation import installation

    base = profile.sections.get("imu_preprocessor", {}).get("frame_id", "base_link")
    found, unplaced = installation(bag_path, base, remap)
    sections, notes = dict(profile.sections), []
    for param, node in INSTALLATION_PARAMS.items():
        section = sections.get(node)
        if section is None or param not in found and param not in unplaced:
            continue
        kept = mounting_given(section) if param == "mounting_rpy_deg" \
            else any(section.get(param, ()))
        if param in unplaced:
            if not kept:
                notes.append(f"{node} {param} left at zero: the bag's /tf_static does not place "
                             f"the frame '{unplaced[param]}' of its messages in '{base}'")
        elif kept:
            notes.append(f"{node} {param}: the profile's kept, the bag's /tf_static gives "
                         f"{found[param]}")
        else:
            sections[node] = {**section, param: found[param]}
            notes.append(f"{node} {param} {found[param]}: from the bag's /tf_static")
    if sections == profile.sections:
        return profile, notes
    if path is None:
        return Profile(profile.path, sections, profile.graph, profile.ignored), notes
    return load_profile(_write(sections, path)), notes
