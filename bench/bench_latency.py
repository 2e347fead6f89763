"""Latency of the live graph: strapdown + ekf as separate processes at 200 Hz IMU, 10 Hz GNSS.

A player in this process publishes `imu/delta` at 200 Hz (a vehicle at rest at 59.9 N: Earth
rate and gravity) and `gnss/fix` + `gnss/vel` at 10 Hz, paced by the wall clock, and takes the
time from publishing each increment to receiving the `ins/state` of the same stamp. Prints
p50/p99/max latency over the data after a warm-up (the first WARMUP_S seconds load the numba
kernels), lost states, CPU time per process (in all, and per increment after the warm-up; the
player's too) and the ekf's mode at the end (at rest with no heading source it stays ALIGNING:
a MEMS heading needs motion).

    .venv/bin/python bench/bench_latency.py [--duration 30] [--executor events|single] [--fifo 10]
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO / "test"))
os.environ.setdefault("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")
os.environ.setdefault("ROS_DOMAIN_ID", str(150 + os.getpid() % 50))

LAT, LON, H = 59.9, 30.3, 20.0
RATE, GNSS_RATE = 200.0, 10.0
WARMUP_S = 3.0


def main() -> int:
    import rclpy
    from geometry_msgs.msg import TwistWithCovarianceStamped
    from ins_gnss_msgs.msg import FilterStatus, ImuDelta, InsState
    from rclpy.node import Node
    from sensor_msgs.msg import NavSatFix, NavSatStatus

    from ins_gnss_ros.nav.earth import earth_rate_enu, normal_gravity
    from ins_gnss_ros.nodes.base import EXECUTOR_ENV, EXECUTORS, SENSOR_QOS, STATE_QOS, \
        executor_kind
    from ins_gnss_ros.io import sec_to_stamp
    from ins_gnss_ros.nodes.convert import to_vector3
    from rosutil import NodeProcess, spin_until, wait_for_endpoints

    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--duration", type=float, default=30.0, help="seconds of data")
    parser.add_argument("--executor", choices=tuple(EXECUTORS),
                        help=f"executor of the nodes and the player (default: ${EXECUTOR_ENV} or "
                        "events)")
    parser.add_argument("--fifo", type=int, metavar="PRIORITY",
                        help="run the strapdown and the player (all their threads) SCHED_FIFO at "
                        "this priority, the ekf as it is (docs/results/latency.md; needs root or "
                        "CAP_SYS_NICE)")
    args = parser.parse_args()
    os.environ[EXECUTOR_ENV] = executor_kind(args.executor)  # inherited by the node processes

    rclpy.init()
    node = Node("latency_player")
    # The player spins the same kind of executor as the nodes: it shares their two cores, and
    # stands for a driver node.
    executor = EXECUTORS[os.environ[EXECUTOR_ENV]]()
    executor.add_node(node)
    pub_delta = node.create_publisher(ImuDelta, "imu/delta", SENSOR_QOS)
    pub_fix = node.create_publisher(NavSatFix, "gnss/fix", SENSOR_QOS)
    pub_vel = node.create_publisher(TwistWithCovarianceStamped, "gnss/vel", SENSOR_QOS)
    sent: dict[tuple[int, int], float] = {}
    latency: list[float] = []
    statuses: list[FilterStatus] = []

    def on_state(msg: InsState) -> None:
        key = (msg.header.stamp.sec, msg.header.stamp.nanosec)
        if key in sent:
            latency.append((key, time.perf_counter() - sent.pop(key)))

    node.create_subscription(InsState, "ins/state", on_state, SENSOR_QOS)
    node.create_subscription(FilterStatus, "nav/status", statuses.append, STATE_QOS)

    # Body axes = ENU (heading 90: x east): the gyro sees Earth rate, the accelerometer gravity.
    lat = np.radians(LAT)
    dt = 1.0 / RATE
    dtheta = to_vector3(earth_rate_enu(lat) * dt)
    dv = to_vector3(np.array([0.0, 0.0, normal_gravity(lat, H)]) * dt)
    init = ["-p", f"init.latitude_deg:={LAT}", "-p", f"init.longitude_deg:={LON}",
            "-p", f"init.altitude_m:={H}", "-p", "init.heading_deg:=90.0"]
    params = REPO / "config" / "default.yaml"
    with NodeProcess("strapdown", *init, params_file=params) as strapdown, \
            NodeProcess("ekf", params_file=params) as ekf:
        strapdown.wait_on_graph(node, executor)
        ekf.wait_on_graph(node, executor)
        wait_for_endpoints(node, executor, publishes=["/ins/state", "/nav/status"],
                           subscribes=["/imu/delta", "/gnss/fix", "/gnss/vel"])
        spin_until(executor, lambda: pub_delta.get_subscription_count() >= 2, 20, "subscribers")
        procs = {"strapdown": strapdown.proc.pid, "ekf": ekf.proc.pid, "player": os.getpid()}
        if args.fifo is not None:
            for pid in (procs["strapdown"], procs["player"]):
                set_fifo(pid, args.fifo)
        t0, wall0 = 1_750_000_000.0, time.perf_counter()
        n = int((args.duration + WARMUP_S) * RATE)
        cpu0 = None
        for k in range(1, n + 1):
            if k == int(WARMUP_S * RATE) + 1:
                cpu0 = {name: proc_cpu(pid) for name, pid in procs.items()}
            while time.perf_counter() < wall0 + k * dt:  # pace by the wall clock
                executor.spin_once(timeout_sec=max(0.0, wall0 + k * dt - time.perf_counter()))
            stamp = sec_to_stamp(t0 + k * dt)
            msg = ImuDelta(dt=dt, delta_angle=dtheta, delta_velocity=dv)
            msg.header.stamp = stamp
            sent[(stamp.sec, stamp.nanosec)] = time.perf_counter()
            pub_delta.publish(msg)
            if k % int(RATE / GNSS_RATE) == 0:
                fix = NavSatFix(latitude=LAT, longitude=LON, altitude=H)
                fix.header.stamp = stamp
                fix.status.status = NavSatStatus.STATUS_FIX
                fix.position_covariance = [0.25, 0, 0, 0, 0.25, 0, 0, 0, 0.25]
                fix.position_covariance_type = NavSatFix.COVARIANCE_TYPE_DIAGONAL_KNOWN
                vel = TwistWithCovarianceStamped()
                vel.header.stamp = stamp
                vel.twist.covariance[0] = vel.twist.covariance[7] = vel.twist.covariance[14] = 1e-4
                pub_fix.publish(fix)
                pub_vel.publish(vel)
        end = time.perf_counter() + 2.0
        while time.perf_counter() < end and sent:
            executor.spin_once(timeout_sec=0.05)
        cpu = {name: proc_cpu(pid) for name, pid in procs.items()}
        steady = {name: cpu[name] - cpu0[name] for name in procs}
    node.destroy_node()
    rclpy.shutdown()

    start = sec_to_stamp(t0 + WARMUP_S)
    lat_ms = np.array([v for k, v in latency if k > (start.sec, start.nanosec)]) * 1e3
    measured = n - int(WARMUP_S * RATE)  # the increments stamped after the warm-up
    print(f"{measured} increments at {RATE:g} Hz after {WARMUP_S:g} s warm-up, GNSS at "
          f"{GNSS_RATE:g} Hz, {args.duration:g} s")
    print(f"executor (nodes and player): {os.environ[EXECUTOR_ENV]}; strapdown and player "
          + (f"SCHED_FIFO {args.fifo}" if args.fifo is not None else "at normal priority"))
    print(f"ins/state received {len(lat_ms)} (lost {measured - len(lat_ms)})")
    print(f"IMU-to-ins/state latency: p50 {np.percentile(lat_ms, 50):.2f} ms, "
          f"p99 {np.percentile(lat_ms, 99):.2f} ms, max {lat_ms.max():.2f} ms")
    print("process CPU time: " + ", ".join(f"{k} {v:.1f} s" for k, v in cpu.items()))
    print("CPU per increment after the warm-up: " + ", ".join(
        f"{k} {v / measured * 1e3:.2f} ms" for k, v in steady.items()))
    modes = {FilterStatus.MODE_ALIGNING: "ALIGNING", FilterStatus.MODE_NAVIGATING: "NAVIGATING",
             FilterStatus.MODE_DEAD_RECKONING: "DEAD_RECKONING"}
    if statuses:
        print(f"ekf mode at the end: {modes.get(statuses[-1].mode, statuses[-1].mode)}, "
              f"{statuses[-1].accepted_count} updates accepted, {statuses[-1].rejected_count} "
              "rejected")
    return 0


def set_fifo(pid: int, priority: int) -> None:
    """Real-time (SCHED_FIFO) scheduling for every thread of a process, DDS threads included."""
    for tid in os.listdir(f"/proc/{pid}/task"):
        os.sched_setscheduler(int(tid), os.SCHED_FIFO, os.sched_param(priority))


def proc_cpu(pid: int) -> float:
    """User + system CPU seconds of a process (Linux /proc)."""
    fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


if __name__ == "__main__":
    sys.exit(main())
