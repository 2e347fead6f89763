"""The output folder of a replay: ``OUT/bag`` (the recorded outputs) and ``OUT/replay.json``.

Every replay (in-process, processes, offline) creates its folder and writes its summary here, so
that ``trial evaluate`` reads the same keys whatever produced them.
"""
from __future__ import annotations

import json
from pathlib import Path

from ins_gnss_ros import io as bagio


def new_run_folder(out) -> Path:
    """Create the output folder ``out`` (it may exist if empty) and return it as a Path.

    Raises
    ------
    ValueError
        ``out`` exists and holds something: a replay never overwrites an earlier one.
    """
    out = Path(out)
    if out.exists() and any(out.iterdir()):
        raise ValueError(f"{out} exists and is not empty: choose a new output folder")
    out.mkdir(parents=True, exist_ok=True)
    return out


def write_summary(out, bag_path, profile, outages, windows, withheld, mode, rate,
                  graph=None, faults=None) -> dict:
    """Write ``OUT/replay.json``, the facts of a replay, and return them.

    Parameters
    ----------
    out : Path
        The output folder (its ``bag`` is listed if it was written).
    bag_path : path
        Input bag.
    profile : Profile
    outages : str or None
        The ``LEN:PERIOD[:FIRST]`` spec as given.
    windows : (k, 2) int ndarray
        Outage windows, ns on the ROS time axis.
    withheld : int
        GNSS messages withheld in them.
    mode : str
        ``in-process``, ``processes`` or ``offline``.
    rate : float
        Real-time factor (0 for as fast as possible).
    graph : list of str, optional
        What ran, when not the profile's graph (the offline navigator).
    faults : dict, optional
        What the fault injector did.
    """
    summary = {
        "input_bag": str(Path(bag_path).resolve()),
        "profile": str(profile.path.resolve()),
        "graph": list(profile.graph if graph is None else graph),
        "ignored_sections": list(profile.ignored),
        "mode": mode,
        "rate": rate,
        "outages": outages,
        # Windows on the ROS time axis, s (what trial evaluate needs) and ns (exact).
        "outage_windows_s": (windows * 1e-9).tolist(),
        "outage_windows_ns": windows.tolist(),
        "gnss_withheld": int(withheld),
        "output_bag": "bag",
        "topics": bagio.bag_topics(out / "bag") if (out / "bag").exists() else {},
    }
    if faults is not None:
        summary["faults"] = faults
    (out / "replay.json").write_text(json.dumps(summary, indent=2) + "\n")
    return summary

