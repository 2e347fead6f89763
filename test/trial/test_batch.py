"""``trial batch`` on dask.distributed: a local cluster and a separately started scheduler.

Truth: the aggregate of hand-made results (mean, std, percentiles computed here by the
definitions), and for the real runs that every seed ran, each with its own simulated truth.
"""
import json
import os
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from ins_gnss_ros.trial.batch import aggregate, run_batch

PROFILE = "strapdown:\n  ros__parameters:\n    init.latitude_deg: 0.0\n"
DASK = Path(sys.executable).parent / "dask"


def test_aggregate_by_definition():
    values = [0.5, 1.0, 4.0, 2.5]
    results = [{"name": str(i), "metrics": {"horizontal_rms_m": v, "epochs": 10,
                                            "roll_rms_deg": None}}
               for i, v in enumerate(values)] + [{"name": "x", "error": "boom"}]
    stats = aggregate(results)["horizontal_rms_m"]
    assert stats["n"] == 4 and stats["mean"] == pytest.approx(2.0)
    assert stats["std"] == pytest.approx(np.sqrt(np.mean((np.array(values) - 2.0) ** 2)))
    assert stats["p50"] == pytest.approx(1.75) and stats["max"] == 4.0 and stats["min"] == 0.5
    assert "roll_rms_deg" not in aggregate(results)


def _batch(tmp_path, name, seeds, **kwargs):
    profile = tmp_path / "profile.yaml"
    profile.write_text(PROFILE)
    return run_batch(profile, tmp_path / name, scenario="car", seeds=seeds, duration=2.0,
                     imu="delta", imu_grade="navigation", init_from_truth=True, **kwargs)


def test_twenty_seeds_on_a_local_cluster(tmp_path):
    result = _batch(tmp_path, "local", 20, workers=2)
    assert result["failed"] == 0, [r.get("error") for r in result["runs"]]
    assert [r["name"] for r in result["runs"]] == [f"car_seed{s:04d}" for s in range(20)]
    stats = result["aggregate"]["horizontal_rms_m"]
    assert stats["n"] == 20 and 0.0 < stats["mean"] < 0.05
    saved = json.loads(Path(result["path"]).read_text())
    assert saved["aggregate"]["heading_rms_deg"]["n"] == 20


def test_separately_started_scheduler_and_worker(tmp_path):
    scheduler_file = tmp_path / "scheduler.json"
    env = dict(os.environ, DASK_DISTRIBUTED__WORKER__DAEMON="False")
    procs = [subprocess.Popen([str(DASK), "scheduler", "--host", "127.0.0.1", "--port", "0",
                               "--no-dashboard", "--scheduler-file", str(scheduler_file)],
                              stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, env=env)]
    try:
        deadline = time.monotonic() + 30
        while not scheduler_file.exists() and time.monotonic() < deadline:
            time.sleep(0.1)
        address = json.loads(scheduler_file.read_text())["address"]
        assert address.startswith("tcp://127.0.0.1:")
        procs.append(subprocess.Popen(
            # One process (no nanny): SIGTERM ends it within a second.
            [str(DASK), "worker", address, "--nthreads", "1", "--no-nanny",
             "--no-dashboard", "--host", "127.0.0.1"],
            stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, env=env))
        result = _batch(tmp_path, "remote", 2, scheduler=address)
        assert result["failed"] == 0, [r.get("error") for r in result["runs"]]
        assert result["aggregate"]["horizontal_rms_m"]["n"] == 2
    finally:
        for p in reversed(procs):
            p.terminate()
        for p in reversed(procs):
            try:
                p.wait(20)
            except subprocess.TimeoutExpired:
                p.kill()
                p.wait()
