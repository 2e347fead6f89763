"""Live load: the node graph as processes on DDS, fed in real time by a sensor process.

Every node of the profile runs as its console script (as in ``bench/soak.py``); a second
process (this script with ``--publisher``) publishes synthetic stationary ``imu/data_raw`` at
``--rate`` Hz and ``imu/mag_raw`` at a tenth of it, stamped at the sample epochs, so that
neither the publisher nor an observer shares a process with the measured path. The losses come
from the nodes' own counters (``received <topic>`` / ``published <topic>`` in each node's
/diagnostics, counted on DDS by ``nodes/base.py``), read after the graph has drained:

* input loss of a node: per topic it subscribes, what was sent (the sensor process's count, or
  the publishing node's ``published``) minus what it received;
* output loss of a node: per topic it publishes, what it published minus what its least
  served subscriber received.

A topic a node reads only now and then (``NavNode.subscribe_latest``: ``ins/state`` in
``mag_compass`` and ``phase_heading``) is counted as ``taken <topic>``, the newest message
taken when the node needed it: listed, not a loss.

This process only observes: /diagnostics, and ``ins/state`` taken serialized (the stamp is
read from the bytes) for the IMU -> ``ins/state`` latency, the time the state arrives here
minus the stamp of the IMU sample that completed it. CPU is % of one core per node process,
from /proc, after the first 10 s (or quarter of the run). Not part of CI.

Usage: .venv/bin/python bench/live_load.py --duration 60 --rate 200 [--profile P] [--json]
"""
from __future__ import annotations

import argparse
import json
import os
import struct
import subprocess
import sys
import threading
import time
from collections import defaultdict
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from soak import ProcessMeter, _imu, _mag, graph_nodes  # noqa: E402

REPO = Path(__file__).resolve().parents[1]
SENSOR = "sensor_publisher"  # the publisher process, as a source in the loss tables


def publisher(duration: float, rate: float) -> None:
    """The sensor process: wait for a subscriber, publish in real time, print one JSON line of
    what it sent and how late it was."""
    import rclpy
    from rclpy.node import Node
    from sensor_msgs.msg import Imu, MagneticField

    from ins_gnss_ros.nodes.base import DRIVER_QOS

    rclpy.init()
    node = Node("live_load_sensors")
    pub_imu = node.create_publisher(Imu, "imu/data_raw", DRIVER_QOS)
    pub_mag = node.create_publisher(MagneticField, "imu/mag_raw", DRIVER_QOS)
    while pub_imu.get_subscription_count() == 0 or pub_mag.get_subscription_count() == 0:
        time.sleep(0.05)  # discovery: the graph's subscriptions appear
    print("start", flush=True)
    dt, late = 1.0 / rate, []
    sent = {"/imu/data_raw": 0, "/imu/mag_raw": 0}
    # Stamped at the sample epochs, as a driver stamps a sensor with its own clock: a late
    # publication adds to the latency.
    t0, t_stamp0 = time.monotonic(), time.time_ns()
    for k in range(1, int(round(duration * rate)) + 1):
        wait = t0 + k * dt - time.monotonic()
        if wait > 0:
            time.sleep(wait)  # real-time pacing
        late.append(max(0.0, -wait))
        t_ns = t_stamp0 + round(k * dt * 1e9)
        pub_imu.publish(_imu(t_ns, dt))
        sent["/imu/data_raw"] += 1
        if k % 10 == 0:
            pub_mag.publish(_mag(t_ns, 10 * dt))
            sent["/imu/mag_raw"] += 1
    print(json.dumps({"sent": sent, "late_ms_p50": 1e3 * float(np.percentile(late, 50)),
                      "late_ms_p99": 1e3 * float(np.percentile(late, 99))}), flush=True)
    node.destroy_node()
    rclpy.shutdown()


def live_load(duration: float, rate: float, profile: Path) -> dict:
    import rclpy
    from diagnostic_msgs.msg import DiagnosticArray
    from ins_gnss_msgs.msg import InsState
    from rclpy.experimental import EventsExecutor
    from rclpy.node import Node

    from ins_gnss_ros.nodes.base import SENSOR_QOS
    from ins_gnss_ros.trial.processes import stop_processes

    names = graph_nodes(profile)
    env = dict(os.environ, ROS_AUTOMATIC_DISCOVERY_RANGE="LOCALHOST")
    env.setdefault("ROS_DOMAIN_ID", str(101 + os.getpid() % 100))
    os.environ.update(env)
    venv_bin = Path(sys.executable).parent
    procs = {name: subprocess.Popen([str(venv_bin / name), "--ros-args", "--params-file",
                                     str(profile)], env=env, stdout=subprocess.DEVNULL,
                                    stderr=subprocess.DEVNULL) for name in names}
    context = rclpy.Context()
    rclpy.init(context=context, args=[])
    node = Node("live_load_observer", context=context, start_parameter_services=False)
    traffic: dict[str, dict[str, int]] = {}
    latencies, measuring = [], threading.Event()

    def on_diagnostics(msg):
        for status in msg.status:
            counts = {kv.key: int(kv.value) for kv in status.values
                      if kv.key.startswith(("received ", "published ", "taken "))}
            traffic[status.hardware_id] = counts

    def on_state(data: bytes):
        if measuring.is_set():  # header.stamp: int32 sec, uint32 nanosec after the CDR header
            sec, nanosec = struct.unpack_from("<iI", data, 4)
            latencies.append(time.time_ns() - (sec * 1_000_000_000 + nanosec))

    node.create_subscription(DiagnosticArray, "/diagnostics", on_diagnostics, 100)
    node.create_subscription(InsState, "ins/state", on_state, SENSOR_QOS, raw=True)
    executor = EventsExecutor(context=context)
    executor.add_node(node)
    stop = threading.Event()

    def spin():
        while not stop.is_set():
            executor.spin_once(timeout_sec=0.1)

    spinner = threading.Thread(target=spin)
    spinner.start()
    sensors = None
    try:
        while set(names) - set(traffic):  # every node up and publishing its diagnostics
            for name, p in procs.items():
                if p.poll() is not None:
                    raise RuntimeError(f"{name} exited with {p.returncode}")
            time.sleep(0.1)
        sensors = subprocess.Popen([sys.executable, __file__, "--publisher", "--duration",
                                    str(duration), "--rate", str(rate)], env=env,
                                   stdout=subprocess.PIPE, text=True)
        assert sensors.stdout.readline().strip() == "start"
        meters = {name: ProcessMeter(p.pid) for name, p in procs.items()}
        time.sleep(min(10.0, 0.25 * duration))
        for meter in meters.values():
            meter.mark()
        measuring.set()
        sent = json.loads(sensors.stdout.readline())
        measuring.clear()
        cpu = {name: meters[name].end()["cpu_percent"] for name in names}
        # Drained when two diagnostics rounds (1 s each) leave every counter as it was.
        last, steady = None, 0
        while steady < 2:
            time.sleep(1.1)
            now = json.dumps(traffic, sort_keys=True)
            steady, last = (steady + 1 if now == last else 0), now
    finally:
        stop.set()
        spinner.join(5.0)
        stop_processes(([sensors] if sensors else []) + list(procs.values()))
        executor.shutdown()
        node.destroy_node()
        context.try_shutdown()
    return summarise(names, traffic, sent, cpu, latencies, duration, rate, profile)


def summarise(names, traffic, sent, cpu, latencies, duration, rate, profile) -> dict:
    """Per node CPU and input/output losses from the counters (see the module docstring)."""
    published = {SENSOR: sent["sent"]}
    received = defaultdict(dict)  # topic -> node -> count
    taken = defaultdict(dict)
    for name in names:
        counts = traffic.get(name, {})
        published[name] = {k.split(" ", 1)[1]: v for k, v in counts.items()
                           if k.startswith("published ")}
        for k, v in counts.items():
            for kind, counts_of in (("received ", received), ("taken ", taken)):
                if k.startswith(kind):
                    counts_of[k.split(" ", 1)[1]][name] = v
    source = {topic: (who, n) for who, topics in published.items() for topic, n in topics.items()}
    nodes = {}
    for name in names:
        inputs = {topic: {"sent": source[topic][1], "received": by[name],
                          "lost": source[topic][1] - by[name]}
                  for topic, by in received.items() if name in by and topic in source}
        outputs = {topic: {"published": n, "lost": n - min(received[topic].values())}
                   for topic, n in published[name].items() if received.get(topic)}
        taken_here = {topic: {"sent": source[topic][1], "taken": by[name]}
                      for topic, by in taken.items() if name in by and topic in source}
        nodes[name] = {"cpu_percent": cpu[name], "inputs": inputs, "outputs": outputs,
                       "taken": taken_here}
    lat = np.asarray(latencies, float) * 1e-6
    return {"duration_s": duration, "rate_hz": rate, "profile": str(profile),
            "total_cpu_percent": sum(cpu.values()), "nodes": nodes,
            "sensor_late_ms": {"p50": sent["late_ms_p50"], "p99": sent["late_ms_p99"]},
            "ins_state_latency_ms": {"n": int(lat.size),
                                     "p50": float(np.percentile(lat, 50)) if lat.size else None,
                                     "p99": float(np.percentile(lat, 99)) if lat.size else None}}


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--duration", type=float, default=60.0, help="s of real time")
    parser.add_argument("--rate", type=float, default=200.0, help="IMU rate, Hz")
    parser.add_argument("--profile", type=Path, default=REPO / "config" / "default.yaml")
    parser.add_argument("--json", action="store_true", help="print one JSON object")
    parser.add_argument("--publisher", action="store_true", help=argparse.SUPPRESS)
    args = parser.parse_args()
    if not (0 < args.duration <= 86_400 and 0 < args.rate <= 2000):
        parser.error("--duration must be in (0, 86400] s and --rate in (0, 2000] Hz")
    if args.publisher:
        publisher(args.duration, args.rate)
        return 0
    r = live_load(args.duration, args.rate, args.profile)
    if args.json:
        print(json.dumps(r, indent=2))
        return 0
    print(f"live load: {r['duration_s']:g} s at {r['rate_hz']:g} Hz, profile {r['profile']}")
    print(f"{'node':18s} {'CPU %':>6s}  input loss (sent/received)  output loss")
    for name, n in r["nodes"].items():
        ins = ", ".join([f"{t} {i['lost']} of {i['sent']}" for t, i in n["inputs"].items()]
                        + [f"{t} taken {i['taken']} of {i['sent']}"
                           for t, i in n["taken"].items()])
        outs = ", ".join(f"{t} {o['lost']} of {o['published']}" for t, o in n["outputs"].items())
        print(f"{name:18s} {n['cpu_percent']:6.1f}  {ins or '-'}  |  {outs or '-'}")
    lat, late = r["ins_state_latency_ms"], r["sensor_late_ms"]
    print(f"all nodes {r['total_cpu_percent']:.1f} % of one core")
    if lat["n"]:
        print(f"IMU -> ins/state latency ms: p50 {lat['p50']:.2f}, p99 {lat['p99']:.2f} "
              f"({lat['n']} states)")
    print(f"sensor process lateness ms: p50 {late['p50']:.2f}, p99 {late['p99']:.2f}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
