"""Soak run: the node graph as real processes on DDS, fed in real time, for a long time.

Every node of ``ins_gnss_ros.nodes.registry`` with a section in the profile runs as its console
script (``--params-file PROFILE``) on loopback discovery and a domain id of its own. This process
publishes synthetic stationary sensor data in real time on the topics the nodes subscribe to
(found by graph queries; IMU-type topics at ``--rate`` Hz, magnetometer at rate/10) and subscribes
to everything they publish. At the end it prints, per node process, RSS at start and end and CPU
(% of one core), and per output topic the messages received, their rate and the messages missing
from the periodic sequence (gaps in the header stamps longer than 1.5 median intervals), plus the
publisher's own lateness. Not part of CI: the full run is 2 h (``--duration 7200``).

Usage: .venv/bin/python bench/soak.py --duration 60 [--rate 200] [--profile config/default.yaml]
       [--json]
"""
from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import threading
import time
from collections import defaultdict
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
G = 9.81  # stationary specific force magnitude fed to the nodes, m/s^2 (any plausible value)
#: White noise on the synthetic IMU samples (rad/s, m/s^2): a real sensor's readings never repeat
#: bit for bit, and the imu_preprocessor rejects repeated ones as a frozen sensor.
GYRO_NOISE, ACCEL_NOISE = 1e-3, 1e-2
RNG = np.random.default_rng(0)


def _stamp(t_ns):
    from ins_gnss_ros.io import ns_to_stamp

    return ns_to_stamp(t_ns)


def _imu_delta(t_ns, dt):
    from ins_gnss_msgs.msg import ImuDelta

    m = ImuDelta(dt=dt)
    m.header.stamp, m.header.frame_id = _stamp(t_ns), "base_link"
    w, f = RNG.normal(0.0, GYRO_NOISE, 3), RNG.normal((0.0, 0.0, G), ACCEL_NOISE)
    (m.delta_angle.x, m.delta_angle.y, m.delta_angle.z) = (float(v) for v in w * dt)
    (m.delta_velocity.x, m.delta_velocity.y, m.delta_velocity.z) = (float(v) for v in f * dt)
    return m


def _imu(t_ns, dt):
    from sensor_msgs.msg import Imu

    m = Imu()
    m.header.stamp, m.header.frame_id = _stamp(t_ns), "imu_link"
    w, f = RNG.normal(0.0, GYRO_NOISE, 3), RNG.normal((0.0, 0.0, G), ACCEL_NOISE)
    (m.angular_velocity.x, m.angular_velocity.y, m.angular_velocity.z) = (float(v) for v in w)
    (m.linear_acceleration.x, m.linear_acceleration.y, m.linear_acceleration.z) = \
        (float(v) for v in f)
    return m


def _mag(t_ns, dt):
    from sensor_msgs.msg import MagneticField

    m = MagneticField()
    m.header.stamp, m.header.frame_id = _stamp(t_ns), "imu_link"
    m.magnetic_field.x, m.magnetic_field.z = 1.5e-5, -5.0e-5
    return m


#: Input message types this harness can synthesise: type -> (factory, rate divisor).
GENERATORS = {
    "ins_gnss_msgs/msg/ImuDelta": (_imu_delta, 1),
    "sensor_msgs/msg/Imu": (_imu, 1),
    "sensor_msgs/msg/MagneticField": (_mag, 10),
}


def graph_nodes(profile: Path) -> list[str]:
    from ins_gnss_ros.nodes import registry
    from ins_gnss_ros.params_io import load_params_file

    sections = load_params_file(profile)
    return [name for name in registry.NODES if name in sections]


def _proc_usage(pid: int) -> tuple[float, int]:
    """CPU time (user + system, s) and resident set size (bytes) of a process, from /proc.

    Read directly (Linux, where ROS runs) so the harness needs no extra package.
    """
    with open(f"/proc/{pid}/stat") as f:
        # Fields after the command name, which is in parentheses and may contain spaces.
        fields = f.read().rsplit(")", 1)[1].split()
    cpu = (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")  # utime, stime
    with open(f"/proc/{pid}/status") as f:
        rss_kb = next(int(line.split()[1]) for line in f if line.startswith("VmRSS:"))
    return cpu, rss_kb * 1024


class ProcessMeter:
    """RSS and CPU time of one process: at start, after the warm-up, at the end.

    The warm-up (first messages: numba compilation, buffers filling) is excluded from the CPU
    figure and separates start-up memory from growth during the run.
    """

    def __init__(self, pid: int):
        self.pid = pid
        self.rss0 = _proc_usage(pid)[1]
        self.mark()

    def mark(self) -> None:
        """Start of the measured period (end of the warm-up)."""
        self.t1 = time.monotonic()
        self.cpu1, self.rss1 = _proc_usage(self.pid)

    def end(self) -> dict:
        cpu, rss = _proc_usage(self.pid)
        wall = time.monotonic() - self.t1
        return {"rss_start_mb": self.rss0 / 2**20, "rss_warm_mb": self.rss1 / 2**20,
                "rss_end_mb": rss / 2**20, "cpu_percent": 100.0 * (cpu - self.cpu1) / wall}


def _wait(executor, condition, timeout, what, procs):
    deadline = time.monotonic() + timeout
    while not condition():
        for name, p in procs.items():
            if p.poll() is not None:
                raise RuntimeError(f"{name} exited with {p.returncode} while waiting for {what}")
        if time.monotonic() > deadline:
            raise TimeoutError(f"timed out after {timeout} s waiting for {what}")
        executor.spin_once(timeout_sec=0.05)


def missing_in_sequence(stamps_ns: list[int]) -> int:
    """Messages missing from a periodic stamp sequence (gaps > 1.5 median intervals)."""
    if len(stamps_ns) < 3:
        return 0
    d = np.diff(np.sort(np.asarray(stamps_ns, dtype=np.int64)))
    d = d[d > 0]
    if d.size == 0:
        return 0
    period = np.median(d)
    gaps = d[d > 1.5 * period]
    return int(np.sum(np.round(gaps / period) - 1))


def soak(duration: float, rate: float, profile: Path, warmup: float = 20.0) -> dict:
    import rclpy
    from rclpy.executors import SingleThreadedExecutor
    from rclpy.node import Node
    from rclpy.qos import HistoryPolicy, QoSProfile, ReliabilityPolicy

    from ins_gnss_ros.io import msg_class
    from ins_gnss_ros.trial.processes import stop_processes

    names = graph_nodes(profile)
    if not names:
        raise SystemExit(f"{profile}: no section for any registry node")
    env = dict(os.environ, ROS_AUTOMATIC_DISCOVERY_RANGE="LOCALHOST")
    env.setdefault("ROS_DOMAIN_ID", str(101 + os.getpid() % 100))
    os.environ.update(ROS_AUTOMATIC_DISCOVERY_RANGE="LOCALHOST", ROS_DOMAIN_ID=env["ROS_DOMAIN_ID"])
    venv_bin = Path(sys.executable).parent
    procs = {name: subprocess.Popen([str(venv_bin / name), "--ros-args", "--params-file",
                                     str(profile)], env=env, stdout=subprocess.DEVNULL,
                                    stderr=subprocess.DEVNULL) for name in names}
    qos = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=1000,
                     reliability=ReliabilityPolicy.RELIABLE)
    context = rclpy.Context()
    rclpy.init(context=context, args=[])
    node = Node("soak_driver", context=context, start_parameter_services=False)
    executor = SingleThreadedExecutor(context=context)
    executor.add_node(node)
    received: dict[str, list[int]] = defaultdict(list)
    lock = threading.Lock()
    meters, result = {}, {}
    stop, spinner = threading.Event(), None
    try:
        _wait(executor, lambda: set(names) <= {n for n, _ in node.get_node_names_and_namespaces()},
              warmup, "nodes on the graph", procs)
        subscribed, outputs = {}, {}
        for name in names:
            _wait(executor, lambda: bool(node.get_publisher_names_and_types_by_node(name, "/")),
                  warmup, f"{name} publishers", procs)
            for topic, types in node.get_subscriber_names_and_types_by_node(name, "/"):
                subscribed[topic] = types[0]
            for topic, types in node.get_publisher_names_and_types_by_node(name, "/"):
                if topic not in ("/rosout", "/parameter_events", "/diagnostics"):
                    outputs[topic] = types[0]
        # Feed only the graph's external inputs: a topic some node publishes is its business.
        inputs = {t: k for t, k in subscribed.items() if k in GENERATORS and t not in outputs}

        def recorder(topic):
            def callback(msg):
                with lock:
                    received[topic].append(msg.header.stamp.sec * 1_000_000_000
                                           + msg.header.stamp.nanosec)
            return callback

        subs = [node.create_subscription(msg_class(t), topic, recorder(topic), qos)
                for topic, t in sorted(outputs.items())]
        pubs = {topic: node.create_publisher(msg_class(t), topic, qos)
                for topic, t in sorted(inputs.items())}
        _wait(executor, lambda: all(p.get_subscription_count() > 0 for p in pubs.values())
              and all(s.get_publisher_count() > 0 for s in subs), warmup, "matched endpoints",
              procs)
        meters = {name: ProcessMeter(p.pid) for name, p in procs.items()}

        def spin():
            while not stop.is_set():
                executor.spin_once(timeout_sec=0.1)

        spinner = threading.Thread(target=spin)
        spinner.start()
        dt = 1.0 / rate
        n_ticks = int(round(duration * rate))
        warm_tick = int(round(min(10.0, 0.25 * duration) * rate))
        sent: dict[str, int] = defaultdict(int)
        late, tick_stamps = [], set()
        t_stamp0 = time.time_ns() // 1_000_000 * 1_000_000
        t_wall0 = time.monotonic()
        for k in range(1, n_ticks + 1):
            due = t_wall0 + k * dt
            wait = due - time.monotonic()
            if wait > 0:
                time.sleep(wait)  # real-time pacing, not waiting for a condition
            late.append(max(0.0, -wait))
            if k == warm_tick:
                for meter in meters.values():
                    meter.mark()
            t_ns = t_stamp0 + int(round(k * dt * 1e9))
            tick_stamps.add(t_ns)
            for topic, msgtype in inputs.items():
                factory, every = GENERATORS[msgtype]
                if k % every == 0:
                    pubs[topic].publish(factory(t_ns, dt * every))
                    sent[topic] += 1
        # Let the graph drain: stop once no output arrived for 1 s (bounded by 10 s).
        deadline, last, since = time.monotonic() + 10.0, -1, time.monotonic()
        while time.monotonic() < deadline:
            with lock:
                total = sum(len(v) for v in received.values())
            if total != last:
                last, since = total, time.monotonic()
            elif time.monotonic() - since > 1.0:
                break
            time.sleep(0.05)
        result = {
            "duration_s": duration, "rate_hz": rate, "profile": str(profile),
            "nodes": {name: {**meters[name].end(), "alive": procs[name].poll() is None}
                      for name in names},
            "inputs": dict(sent),
            "outputs": {},
            "publisher_late_ms": {"p50": 1e3 * float(np.percentile(late, 50)),
                                  "p99": 1e3 * float(np.percentile(late, 99)),
                                  "max": 1e3 * float(np.max(late))},
        }
        with lock:
            for topic in sorted(outputs):
                stamps = received[topic]
                result["outputs"][topic] = {
                    "received": len(stamps),
                    "rate_hz": len(stamps) / duration,
                    "missing_in_sequence": missing_in_sequence(stamps),
                    "duplicate_stamps": len(stamps) - len(set(stamps)),
                    # An output stamped with the input epochs (one per tick, e.g. ins/state per
                    # increment): every tick whose stamp never came back is a lost message.
                    "lost_ticks": None, "lost_span_s": None,
                }
                if stamps and set(stamps) <= tick_stamps and len(stamps) > 0.5 * len(tick_stamps):
                    lost = sorted(tick_stamps - set(stamps))
                    result["outputs"][topic]["lost_ticks"] = len(lost)
                    if lost:  # when in the run (s after the first tick) the losses happened
                        result["outputs"][topic]["lost_span_s"] = [
                            (lost[0] - t_stamp0) * 1e-9, (lost[-1] - t_stamp0) * 1e-9]
    finally:
        stop.set()
        if spinner is not None:
            spinner.join(5.0)
        stop_processes(procs.values())
        executor.shutdown()
        node.destroy_node()
        context.try_shutdown()
    return result


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--duration", type=float, default=7200.0, help="s of real time")
    parser.add_argument("--rate", type=float, default=200.0, help="IMU rate, Hz")
    parser.add_argument("--profile", type=Path, default=REPO / "config" / "default.yaml")
    parser.add_argument("--json", action="store_true", help="print one JSON object")
    args = parser.parse_args()
    if not (0 < args.duration <= 86_400 and 0 < args.rate <= 2000):
        parser.error("--duration must be in (0, 86400] s and --rate in (0, 2000] Hz")
    r = soak(args.duration, args.rate, args.profile)
    if args.json:
        print(json.dumps(r, indent=2))
        return 0
    print(f"soak: {r['duration_s']:g} s at {r['rate_hz']:g} Hz, profile {r['profile']}")
    print(f"{'node':20s} {'RSS start MB':>12s} {'after warm-up':>13s} {'RSS end MB':>11s}"
          f" {'CPU %':>7s} alive")
    for name, n in r["nodes"].items():
        print(f"{name:20s} {n['rss_start_mb']:12.1f} {n['rss_warm_mb']:13.1f}"
              f" {n['rss_end_mb']:11.1f} {n['cpu_percent']:7.1f} {n['alive']}")
    print("inputs sent: " + ", ".join(f"{t} {n}" for t, n in r["inputs"].items()))
    print(f"{'output topic':24s} {'received':>9s} {'rate Hz':>8s} {'missing':>8s} {'dup':>5s}"
          f" {'lost ticks':>10s}")
    for topic, o in r["outputs"].items():
        lost = "-" if o["lost_ticks"] is None else str(o["lost_ticks"])
        if o["lost_span_s"]:
            lost += " (t = {:.2f}..{:.2f} s)".format(*o["lost_span_s"])
        print(f"{topic:24s} {o['received']:9d} {o['rate_hz']:8.1f} {o['missing_in_sequence']:8d}"
              f" {o['duplicate_stamps']:5d} {lost:>10s}")
    late = r["publisher_late_ms"]
    print(f"publisher lateness ms: p50 {late['p50']:.2f}, p99 {late['p99']:.2f},"
          f" max {late['max']:.2f}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
