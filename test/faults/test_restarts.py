"""Node restarts in the running graph (issue 9): the graph recovers by itself.

In-process: the strapdown + ekf graph on an InProcessBus over a simulated car trial; mid-run one
node object is destroyed and a fresh one (same parameters) takes its place, as a supervisor
restarting a crashed process would do. With processes: the strapdown is SIGKILLed while the
graph plays a bag at real time on DDS, and restarted.

Truth: the bag's truth/state (simulated trajectory); the published covariance as the bound.
"""
from __future__ import annotations

import importlib.util
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from ins_gnss_ros import io as bagio

REPO = Path(__file__).resolve().parents[2]
_spec = importlib.util.spec_from_file_location("bench_faults", REPO / "bench" / "bench_faults.py")
bench_faults = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(bench_faults)

DURATION = 30.0
RESTART_S = 15.0  # bag time of the restart, s after the first message


@pytest.fixture(scope="module")
def trial(tmp_path_factory):
    from ins_gnss_ros.trial.profile import load_profile, profile_with_truth_init

    root = tmp_path_factory.mktemp("restarts")
    bag = bench_faults.simulate_car(root / "car", DURATION, 50.0)
    profile = profile_with_truth_init(load_profile(bench_faults.write_profile(
        root / "graph.yaml")), bag, root / "profile.yaml")
    return bag, profile


def _run_with_restart(bag, profile, restart: str | None, out: Path):
    """Feed the bag through the graph; at RESTART_S replace node ``restart`` by a fresh one.

    The loop of ``trial.replay.replay`` (which has no hook to swap a node), minus its options.

    Returns the recorded outputs (a bag folder) and the nodes' diagnostics keys seen.
    """
    import rclpy

    from ins_gnss_ros.nodes import registry
    from ins_gnss_ros.nodes.base import InProcessBus
    from ins_gnss_ros.trial.inputs import read_inputs
    from ins_gnss_ros.trial.profile import load_profile

    graph = load_profile(profile).graph
    messages = read_inputs(bag)
    context = rclpy.Context()
    rclpy.init(context=context, args=[])
    bus = InProcessBus()
    writer = bagio.BagWriter(out)
    bus.recorders.append(lambda topic, msg: writer.write(topic, msg, bagio.msg_stamp_ns(msg)))

    def start(name):
        return registry.node_class(name)(
            bus=bus, context=context, use_global_arguments=False,
            start_parameter_services=False,
            cli_args=["--ros-args", "--params-file", str(profile)])

    nodes = {name: start(name) for name in graph}
    t_restart = messages[0].t_ns + int(RESTART_S * 1e9)
    next_diag = messages[0].t_ns + 10**9
    try:
        for m in messages:
            while m.t_ns >= next_diag:
                bus.now_ns = next_diag
                for node in nodes.values():
                    node.diag.publish()
                bus.drain()
                next_diag += 10**9
            if restart is not None and m.t_ns >= t_restart:
                old = nodes[restart]
                # A killed process: its subscriptions vanish with it (the bus has no
                # unsubscribe, so its callbacks are taken off by hand).
                for callbacks in bus._subscribers.values():
                    callbacks[:] = [(c, form) for c, form in callbacks
                                    if getattr(c, "__self__", None) is not old]
                old.destroy_node()
                nodes[restart] = start(restart)
                restart = None
            bus.now_ns = m.t_ns
            bus.publish(m.topic, m.msg, recorded=False)
            bus.drain()
    finally:
        for node in nodes.values():
            node.destroy_node()
        context.try_shutdown()
    writer.close()
    return out


def _truth_error(bag, fixes):
    truth = bagio.read_bag(bag, ["truth/state"])
    tt = np.array([m.t_ns for m in truth])
    tl = np.array([[m.msg.latitude, m.msg.longitude, m.msg.altitude] for m in truth])
    from ins_gnss_ros.nav.earth import radii

    err, sig, t = [], [], []
    for m in fixes:
        s = bagio.msg_stamp_ns(m.msg)
        lat, lon, h = (np.interp(s, tt, tl[:, k]) for k in range(3))
        rm, rn = radii(lat)
        err.append([(np.radians(m.msg.longitude) - lon) * (rn + h) * np.cos(lat),
                    (np.radians(m.msg.latitude) - lat) * (rm + h), m.msg.altitude - h])
        sig.append(np.sqrt(np.diag(np.reshape(m.msg.position_covariance, (3, 3)))))
        t.append((s - tt[0]) * 1e-9)
    return np.array(t), np.array(err), np.array(sig)


def _assert_no_jump(t, err, sig, navigating):
    """No jump between consecutive solutions published while NAVIGATING beyond their stated
    uncertainty: the change of the error (estimate minus truth) within K sigma of the two
    covariances together."""
    jump = np.abs(np.diff(err, axis=0)) / np.hypot(sig[1:], sig[:-1])
    worst = np.where(navigating[1:] & navigating[:-1], np.max(jump, axis=1), 0.0)
    assert np.max(worst) < bench_faults.K_SIGMA, \
        f"jump of {np.max(worst):.1f} sigma at t={t[1 + np.argmax(worst)]:.1f} s"


def _check_recovery(bag, out, restart_s):
    r = bench_faults.integrity(out, bag)
    assert r["wrong"] == 0, (f"{r['wrong']} confident wrong solutions"
                             f" (max {r['max_ratio_navigating']:.1f} sigma)")
    fixes = bagio.read_bag(out, ["nav/fix"])
    t, err, sig = _truth_error(bag, fixes)
    _assert_no_jump(t, err, sig, r["fix_modes"] == bench_faults.NAVIGATING)
    # Solutions again after the restart, navigating, within 5 s of bag time.
    after = t > restart_s
    assert np.any(after) and t[after][0] < restart_s + 5.0
    status = bagio.read_bag(out, ["nav/status"])
    st = [((bagio.msg_stamp_ns(m.msg) - bagio.msg_stamp_ns(status[0].msg)) * 1e-9, m.msg.mode)
          for m in status]
    assert st[-1][1] == bench_faults.NAVIGATING
    assert any(s > restart_s and mode == bench_faults.NAVIGATING for s, mode in st)
    return t, err, sig, st


def test_restarted_strapdown_is_resynchronised_by_the_ekf(trial, tmp_path):
    bag, profile = trial
    out = _run_with_restart(bag, profile, "strapdown", tmp_path / "bag")
    t, err, sig, _ = _check_recovery(bag, out, RESTART_S)
    # The fresh strapdown starts from its init.* (the trial's first position, ~100 m away): the
    # ekf sees it out of step and re-synchronises it; /diagnostics says so.
    keys = bench_faults.diagnostics_messages(out)
    assert "strapdown out of step: re-synchronised on its newest state" in keys
    # The outage is visible: no nav/fix while the strapdown was out of step...
    after = t[t > RESTART_S]
    assert after[0] - RESTART_S > 0.1
    # ...and the solutions after it are as good as before it.
    late = t > RESTART_S + 5.0
    assert np.all(np.abs(err[late, :2]) < 5 * sig[late, :2])
    assert np.max(np.abs(err[late, :2])) < 1.0


def test_restarted_ekf_realigns_and_corrects_the_strapdown(trial, tmp_path):
    bag, profile = trial
    out = _run_with_restart(bag, profile, "ekf", tmp_path / "bag")
    t, err, sig, st = _check_recovery(bag, out, RESTART_S)
    # The fresh filter starts ALIGNING (visible on nav/status) before navigating again.
    modes_after = [mode for s, mode in st if s >= RESTART_S]
    assert modes_after[0] == bench_faults.ALIGNING
    late = t > RESTART_S + 5.0
    assert np.max(np.abs(err[late, :2])) < 1.0


# ---------------------------------------------------------------------------------------------
# Real processes: SIGKILL the strapdown while the trial plays at real time
# ---------------------------------------------------------------------------------------------
def test_sigkilled_strapdown_process_is_restarted_and_resynchronised(trial, tmp_path):
    pytest.importorskip("rclpy")
    from ins_gnss_ros.trial.processes import replay_processes

    bag, profile = trial
    script = Path(sys.executable).parent / "strapdown"
    if not script.exists():
        pytest.fail(f"console script {script} missing: the package is not installed")
    killed = {}
    t_kill_ns = bagio.read_bag(bag, ["truth/state"])[0].t_ns + int(RESTART_S * 1e9)

    def killer():
        # Watch ins/state on DDS; once the strapdown has reached RESTART_S of the trial, SIGKILL
        # the strapdown process the replay started (a child of this process), start a new one.
        import rclpy
        from ins_gnss_msgs.msg import InsState
        from rclpy.executors import SingleThreadedExecutor
        from rclpy.node import Node

        context = rclpy.Context()
        rclpy.init(context=context, args=[])
        node = Node("restart_watcher", context=context, use_global_arguments=False)
        seen = []
        node.create_subscription(InsState, "/ins/state",
                                 lambda m: seen.append(bagio.msg_stamp_ns(m)), 10)
        executor = SingleThreadedExecutor(context=context)
        executor.add_node(node)
        deadline = time.monotonic() + 120.0
        try:
            while time.monotonic() < deadline and not (seen and seen[-1] >= t_kill_ns):
                executor.spin_once(timeout_sec=0.1)
        finally:
            node.destroy_node()
            context.try_shutdown()
        pids = subprocess.run(["pgrep", "-P", str(os.getpid()), "-f", str(script)],
                              capture_output=True, text=True).stdout.split()
        if not (seen and pids):
            return
        os.kill(int(pids[0]), signal.SIGKILL)
        killed["t"] = time.monotonic()
        killed["proc"] = subprocess.Popen(
            [str(script), "--ros-args", "--params-file", str(profile), "-p",
             "use_sim_time:=true"], stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)

    import threading

    thread = threading.Thread(target=killer, daemon=True)
    thread.start()
    try:
        replay_processes(bag, profile, tmp_path / "run", rate=1.0, timeout=60.0)
    finally:
        thread.join(timeout=1.0)
        if "proc" in killed:
            killed["proc"].send_signal(signal.SIGINT)
            try:
                killed["proc"].wait(timeout=10.0)
            except subprocess.TimeoutExpired:
                killed["proc"].kill()
    assert "t" in killed, "the strapdown never reached the restart time or was never seen"
    out = tmp_path / "run" / "bag"
    states = bagio.read_bag(out, ["ins/state"])
    fixes = bagio.read_bag(out, ["nav/fix"])
    assert states and fixes
    t, err, sig = _truth_error(bag, fixes)
    # The outage is visible: a gap in ins/state while the new process started (its correction
    # sequence continues: the ekf's re-synchronising correction sets it before it publishes).
    t_states = np.array([bagio.msg_stamp_ns(m.msg) for m in states])
    gap = int(np.argmax(np.diff(t_states)))
    assert np.diff(t_states)[gap] > 0.2e9, "no outage visible in ins/state"  # 10 periods
    t_kill = (t_states[gap] - bagio.read_bag(bag, ["truth/state"])[0].t_ns) * 1e-9
    assert abs(t_kill - RESTART_S) < 2.0
    assert "strapdown out of step: re-synchronised on its newest state" in \
        bench_faults.diagnostics_messages(out)
    # Solutions resumed after the restart and stay within their stated uncertainty.
    assert np.any(t > t_kill + 3.0)
    late = t > t_kill + 5.0
    assert np.all(np.abs(err[late, :2]) < bench_faults.K_SIGMA * sig[late, :2])
    r = bench_faults.integrity(out, bag)
    assert r["wrong"] == 0, f"{r['wrong']} confident wrong solutions"
    _assert_no_jump(t, err, sig, r["fix_modes"] == bench_faults.NAVIGATING)
