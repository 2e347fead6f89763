"""The output folder of a replay: ``OUT/bag`` (the recorded outputs) and ``OUT/replay.json``.

Every replay (in-process, processes, offline) creates its folder and writes its summary here, so
that ``trial evaluate`` reads the same keys whatever produced them.
"""
from __future__ import annotations

import json
from collections import Counter
from dataclasses import dataclass, field
from pathlib import Path

from ins_gnss_ros import io as bagio


@dataclass
class MessageCounts:
    """What a replay moved, per absolute topic name.

    Attributes
    ----------
    played : Counter
        Messages the player handed to the graph (after outages and faults).
    withheld : Counter
        Messages of the bag withheld by the GNSS outages.
    recorded : Counter
        Outputs recorded into ``OUT/bag``.
    """

    played: Counter = field(default_factory=Counter)
    withheld: Counter = field(default_factory=Counter)
    recorded: Counter = field(default_factory=Counter)

    def per_topic(self) -> dict:
        """``{topic: {"in": n, "withheld": n, "out": n}}``, topics sorted (``replay.json``)."""
        topics = sorted(set(self.played) | set(self.withheld) | set(self.recorded))
        return {t: {"in": self.played[t], "withheld": self.withheld[t],
                    "out": self.recorded[t]} for t in topics}


def counts_table(messages: dict) -> list:
    """Lines of a table of the ``messages`` of a ``replay.json`` (:meth:`MessageCounts.per_topic`):
    one row per topic and the totals."""
    rows = [(topic, c["in"], c["withheld"], c["out"]) for topic, c in messages.items()]
    rows.append(("total", *(sum(row[i] for row in rows) for i in (1, 2, 3))))
    width = max(len(row[0]) for row in rows)
    lines = [f"{'topic':<{width}} {'in':>9} {'withheld':>9} {'out':>9}"]
    lines += [f"{name:<{width}} {n_in:>9,} {n_held:>9,} {n_out:>9,}"
              for name, n_in, n_held, n_out in rows]
    return lines


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


def write_summary(out, bag_path, profile, outages, windows, counts, mode, rate,
                  graph=None, faults=None, satellites=None, events=None, unread=(),
                  installation=(), converted=()) -> dict:
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
    counts : MessageCounts
        What was played, withheld and recorded.
    mode : str
        ``in-process``, ``processes`` or ``offline``.
    rate : float
        Real-time factor (0 for as fast as possible).
    graph : list of str, optional
        What ran, when not the profile's graph (the offline navigator).
    faults : dict, optional
        What the fault injector did.
    satellites : dict, optional
        The reduced-constellation windows (``satellites``, ``satellite_windows_s`` and
        ``_ns``, ``satellites_kept``: the satellites left in each window).
    events : Counter, optional
        What the offline path's front end reported (refused inputs, withheld headings), by
        text: the nodes' /diagnostics counters.
    unread : list of str
        The bag's topics no node read that an input of their type could take, with the
        remapping (:func:`~ins_gnss_ros.trial.inputs.check_inputs`).
    installation : list of str
        What was taken from the bag's /tf_static, or found there unplaced
        (:func:`~ins_gnss_ros.trial.profile.profile_with_installation`).
    converted : list of str
        The bag's topics read as another type
        (:func:`~ins_gnss_ros.trial.inputs.conversion_notes`).
    """
    summary = {
        "input_bag": str(Path(bag_path).resolve()),
        "profile": str(profile.path.resolve()),
        "graph": list(profile.replay_graph if graph is None else graph),
        "ignored_sections": list(profile.ignored),
        "sensor_sources_left_out": [name for name in profile.graph
                                    if name not in profile.replay_graph],
        "mode": mode,
        "rate": rate,
        "outages": outages,
        # Windows on the ROS time axis, s (what trial evaluate needs) and ns (exact).
        "outage_windows_s": (windows * 1e-9).tolist(),
        "outage_windows_ns": windows.tolist(),
        "gnss_withheld": sum(counts.withheld.values()),
        "output_bag": "bag",
        "topics": bagio.bag_topics(out / "bag") if (out / "bag").exists() else {},
        "messages": counts.per_topic(),
        "unread_topics": list(unread),
        "installation": list(installation),
        "converted": list(converted),
    }
    if faults is not None:
        summary["faults"] = faults
    if satellites is not None:
        summary.update(satellites)
    if events is not None:
        summary["events"] = dict(sorted(events.items()))
    (out / "replay.json").write_text(json.dumps(summary, indent=2) + "\n")
    return summary

