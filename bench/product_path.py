"""The product path as the accuracy benches run it: the ``trial`` commands, nothing of their own.

docs/DEVELOPING.md: every accuracy figure in docs/RESULTS.md comes from ``trial replay`` (the
in-process node graph, or ``--offline``: the same imu_preprocessor and ekf cores without it),
``trial smooth`` and ``trial evaluate``. A bench composes these commands; it never builds its
own measurements, IMU grid or noise floors. The commands run with this interpreter, so the
``ins_gnss_ros`` they import is the one the bench imports (a worktree's, with PYTHONPATH).
"""
from __future__ import annotations

import json
import shutil
import subprocess
import sys
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
TRIAL = [sys.executable, "-m", "ins_gnss_ros.trial.cli"]

#: How a solution is produced from a bag: mode -> the trial command and its options.
MODES = {"graph": ("replay", ()), "offline": ("replay", ("--offline",)), "smooth": ("smooth", ())}


def trial(*args) -> str:
    """Run a trial command from the repository root; returns its stdout (raises with its
    stderr when it fails)."""
    done = subprocess.run(TRIAL + [str(a) for a in args], cwd=REPO, capture_output=True,
                          text=True)
    if done.returncode:
        raise RuntimeError(f"trial {' '.join(map(str, args))} failed ({done.returncode}):\n"
                           f"{done.stderr}")
    return done.stdout


def solve(mode, bag, config, out, *options) -> Path:
    """The solution of `bag` by `mode` (MODES) with the profile `config`, in the new folder
    `out` (replaced if it exists); returns `out`."""
    command, mode_options = MODES[mode]
    shutil.rmtree(out, ignore_errors=True)
    trial(command, bag, "--config", config, "--out", out, "--no-progress", *mode_options,
          *options)
    return Path(out)


def evaluate(out, *options) -> dict:
    """``trial evaluate OUT --json`` (no plots) with `options`, as a dict."""
    return json.loads(trial("evaluate", out, "--json", "--no-plots", *options))


def command_line(mode, bag, config, *options) -> str:
    """The command a user types for `solve` (for the printed tables)."""
    command, mode_options = MODES[mode]
    return " ".join(["trial", command, str(bag), "--config", str(config), *mode_options,
                     *map(str, options), "--out", "OUT"])
