"""``trial batch``: many replays, or Monte Carlo seeds, in parallel on dask.distributed.

A Monte Carlo run is simulate + replay + evaluate of one seed; a bag run is replay + evaluate of
one bag. Each run is one dask task writing into its own folder ``OUT/<name>/`` (a worker needs
the project's venv and the shared file system: runs on one machine, or a cluster with a common
disk). Runs are independent processes' work, so a failed run is reported, not fatal. The
``--json`` metrics of all successful runs are aggregated per key: mean, standard deviation,
minimum, 5th/50th/95th percentiles and maximum (``OUT/batch.json``).

By default a :class:`distributed.LocalCluster` of single-threaded worker processes (rclpy keeps
per-process state, and the numerical work holds the GIL); ``scheduler`` connects to a running
``dask scheduler`` instead.
"""
from __future__ import annotations

import json
from pathlib import Path

import numpy as np

#: Percentiles reported by :func:`aggregate`.
PERCENTILES = (5, 50, 95)


def run_one(task: dict) -> dict:
    """One run (executed on a worker). ``task`` keys: name, out, config, outages,
    init_from_truth, and either bag, or scenario/seed/duration/imu/imu_grade.

    Returns
    -------
    dict
        name, and metrics (the evaluate JSON) or error (one line).
    """
    from ins_gnss_ros.io import first_line
    from ins_gnss_ros.trial.replay import replay
    from ins_gnss_ros.trial.report import evaluate_run
    from ins_gnss_ros.trial.simulate import SimOptions, simulate

    folder = Path(task["out"]) / task["name"]
    try:
        bag = task.get("bag")
        if bag is None:
            bag = simulate(task["scenario"], task["duration"], task["seed"], folder / "bag",
                           SimOptions(imu_grade=task.get("imu_grade"),
                                      imu_topic=task.get("imu", "data_raw")))
        replay(bag, task["config"], folder / "replay", outages=task.get("outages"),
               init_from_truth=task.get("init_from_truth", False))
        _, metrics = evaluate_run(folder / "replay", plots=False)
        return {"name": task["name"], "metrics": metrics}
    except Exception as err:  # noqa: BLE001 - a failed run is a result of the batch
        return {"name": task["name"], "error": f"{type(err).__name__}: {first_line(err)}"}


def aggregate(results) -> dict:
    """Statistics over runs of every numeric metric: {key: {n, mean, std, min, p5, p50, p95,
    max}}; runs where a metric is missing or null are left out of that metric."""
    values: dict[str, list] = {}
    for result in results:
        for key, value in result.get("metrics", {}).items():
            if isinstance(value, (int, float)) and not isinstance(value, bool):
                values.setdefault(key, []).append(float(value))
    out = {}
    for key, vals in sorted(values.items()):
        a = np.asarray(vals)
        a = a[np.isfinite(a)]
        if a.size == 0:
            continue
        stats = {"n": int(a.size), "mean": float(a.mean()), "std": float(a.std(ddof=0)),
                 "min": float(a.min()), "max": float(a.max())}
        stats.update({f"p{p}": float(np.percentile(a, p)) for p in PERCENTILES})
        out[key] = stats
    return out


def make_tasks(out, config, scenario=None, seeds=10, first_seed=0, duration=60.0, bags=None,
               outages=None, init_from_truth=False, imu="data_raw", imu_grade=None) -> list:
    """The task dicts of a batch: one per seed (Monte Carlo) or per bag."""
    common = {"out": str(Path(out).resolve()), "config": str(Path(config).resolve()),
              "outages": outages, "init_from_truth": init_from_truth}
    if bags:
        return [dict(common, name=f"{i:03d}_{Path(b).name}", bag=str(Path(b).resolve()))
                for i, b in enumerate(bags)]
    if scenario is None:
        raise ValueError("batch: give --scenario (Monte Carlo seeds) or --bags")
    if seeds < 1:
        raise ValueError(f"batch: --seeds must be >= 1, got {seeds}")
    return [dict(common, name=f"{scenario}_seed{s:04d}", scenario=scenario, seed=s,
                 duration=float(duration), imu=imu, imu_grade=imu_grade)
            for s in range(first_seed, first_seed + seeds)]


def run_tasks(tasks, scheduler=None, workers=2) -> list:
    """Run tasks on dask.distributed and return the results in task order."""
    from distributed import Client, LocalCluster

    if scheduler:
        client, cluster = Client(scheduler, timeout="20s"), None
    else:
        cluster = LocalCluster(n_workers=workers, threads_per_worker=1, processes=True,
                               dashboard_address=None)
        client = Client(cluster)
    try:
        futures = client.map(run_one, tasks, pure=False)
        return client.gather(futures)
    finally:
        client.close()
        if cluster is not None:
            cluster.close()


def run_batch(config, out, scheduler=None, workers=2, **task_options) -> dict:
    """Make the tasks, run them, aggregate, write ``OUT/batch.json``.

    Returns
    -------
    dict
        path (of batch.json), runs (per-run results), aggregate, failed (count).
    """
    from ins_gnss_ros.trial.profile import load_profile

    load_profile(config)  # bad profile: one error now, not one per run
    out = Path(out)
    if out.exists() and any(out.iterdir()):
        raise ValueError(f"{out} exists and is not empty: choose a new output folder")
    out.mkdir(parents=True, exist_ok=True)
    tasks = make_tasks(out, config, **task_options)
    results = run_tasks(tasks, scheduler, workers)
    summary = {"runs": results, "aggregate": aggregate(results),
               "failed": sum(1 for r in results if "error" in r)}
    path = out / "batch.json"
    path.write_text(json.dumps(summary, indent=2, sort_keys=True) + "\n")
    return dict(summary, path=str(path))
