"""The ``trial`` command line: the main job end to end, and bad input as ONE line, status 2.

Truth for the end-to-end run: the simulated truth (a navigation-grade strapdown started on it
stays within centimetres over a few seconds), and the contract's JSON keys.
"""
import json
import os
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

import pytest

from ins_gnss_ros import io as bagio
from ins_gnss_ros.trial.cli import main
from ins_gnss_ros.trial.profile import load_profile
from ins_gnss_ros.trial.supervisor import Supervisor

STRAPDOWN_PROFILE = "strapdown:\n  ros__parameters:\n    init.latitude_deg: 10.0\n"


@pytest.fixture(scope="module")
def workdir(tmp_path_factory):
    d = tmp_path_factory.mktemp("cli")
    (d / "profile.yaml").write_text(STRAPDOWN_PROFILE)
    assert main(["simulate", "--scenario", "car", "--duration", "4", "--seed", "5", "--imu",
                 "delta", "--imu-grade", "navigation", "--out", str(d / "bag")]) == 0
    return d


def test_simulate_replay_evaluate_json(workdir, capsys):
    d = workdir
    assert main(["replay", str(d / "bag"), "--config", str(d / "profile.yaml"),
                 "--init-from-truth", "--out", str(d / "run")]) == 0
    # What was replayed: messages in, withheld and out per topic (the truth never goes in).
    lines = capsys.readouterr().out.splitlines()
    n_delta = len(bagio.read_bag(d / "bag", ["imu/delta"]))
    assert lines[0].startswith("replayed ") and "in-process" in lines[0]
    assert lines[1].split() == ["topic", "in", "withheld", "out"]
    assert [f"{n_delta:,}", "0", "0"] == next(
        line.split()[1:] for line in lines if line.split()[0] == "/imu/delta")
    assert not any("truth" in line for line in lines)
    assert main(["evaluate", str(d / "run"), "--json"]) == 0
    out = capsys.readouterr().out
    metrics = json.loads(out)  # one JSON object and nothing else
    for key in ("horizontal_rms_m", "vertical_rms_m", "roll_rms_deg", "pitch_rms_deg",
                "heading_rms_deg"):
        assert isinstance(metrics[key], float), key
    assert metrics["horizontal_rms_m"] < 0.05 and metrics["heading_rms_deg"] < 0.01
    assert (d / "run" / "report.md").is_file()
    assert (d / "run" / "plots" / "trajectory.png").is_file()
    assert main(["evaluate", str(d / "run"), "--no-plots"]) == 0
    table = capsys.readouterr().out
    assert "| horizontal |" in table and "report:" in table
    assert main(["evaluate", str(d / "run"), "--no-plots", "--json", "--skip", "2"]) == 0
    skipped = json.loads(capsys.readouterr().out)
    assert skipped["epochs"] == metrics["epochs"] - 40  # 20 Hz truth
    assert "first 2 s" in (d / "run" / "report.md").read_text()


def test_evaluate_reports_outage_drift(workdir, capsys):
    """Outage windows recorded in replay.json give the contract's outage keys."""
    import shutil

    run = workdir / "run_outage"
    shutil.copytree(workdir / "run", run)
    summary = json.loads((run / "replay.json").read_text())
    t0 = 1_767_225_600 * 10**9
    summary["outage_windows_ns"] = [[t0 + 10**9, t0 + 2 * 10**9], [t0 + 3 * 10**9, t0 + 35 * 10**8]]
    (run / "replay.json").write_text(json.dumps(summary))
    assert main(["evaluate", str(run), "--json", "--no-plots"]) == 0
    metrics = json.loads(capsys.readouterr().out)
    assert len(metrics["outages"]) == 2
    assert metrics["outage_drift_max_m"] >= metrics["outage_drift_rms_m"] > 0.0
    assert metrics["outages"][0]["start"] == pytest.approx(1.0)  # s after the first truth epoch


def _bad_cases(d):
    (d / "not_a_mapping.yaml").write_text("- 1\n- 2\n")
    (d / "broken.yaml").write_text("strapdown: {ros__parameters: {a: [1, 2}\n")
    (d / "bomb.yaml").write_text("a: &a [1, 1, 1, 1, 1, 1, 1, 1, 1, 1]\n" + "".join(
        f"{c}: &{c} [{', '.join(['*' + p] * 10)}]\n" for p, c in zip("abcdefgh", "bcdefghi")))
    hostile = d / "hostile_bag"
    hostile.mkdir(exist_ok=True)
    (hostile / "metadata.yaml").write_text("rosbag2_bagfile_information: {version: 9, "
                                           "storage_identifier: mcap, relative_file_paths: "
                                           "[../../../etc/passwd], files: 7}\n")
    (d / "bad_run").mkdir(exist_ok=True)
    (d / "bad_run" / "replay.json").write_text("{not json")
    profile, bag = str(d / "profile.yaml"), str(d / "bag")
    return {
        "missing bag": ["replay", str(d / "nope"), "--config", profile, "--out", str(d / "o1")],
        "hostile bag": ["replay", str(hostile), "--config", profile, "--out", str(d / "o2")],
        "YAML list": ["replay", bag, "--config", str(d / "not_a_mapping.yaml"), "--out",
                      str(d / "o3")],
        "broken YAML": ["replay", bag, "--config", str(d / "broken.yaml"), "--out",
                        str(d / "o4")],
        "alias bomb": ["replay", bag, "--config", str(d / "bomb.yaml"), "--out", str(d / "o5")],
        "outage spec": ["replay", bag, "--config", profile, "--outages", "15:10", "--out",
                        str(d / "o6")],
        "rate without processes": ["replay", bag, "--config", profile, "--rate", "1", "--out",
                                   str(d / "o7")],
        "bad replay.json": ["evaluate", str(d / "bad_run")],
        "no truth": ["evaluate", str(d / "bag"), "--truth", str(d / "nope")],
        "unknown import": ["import", "gpx", "x", "--out", str(d / "o8")],
        "bad duration": ["simulate", "--scenario", "car", "--duration", "-3", "--out",
                         str(d / "o9")],
        "GNSS rate": ["simulate", "--scenario", "car", "--duration", "1", "--gnss-rate", "0",
                      "--out", str(d / "o10")],
        "antenna array": ["simulate", "--scenario", "sea", "--antennas", "4", "--array", "2.7",
                          "--out", str(d / "o11")],
        "antennas": ["simulate", "--scenario", "sea", "--antennas", "5", "--out",
                     str(d / "o12")],
    }


def test_bad_input_is_one_line_and_status_2(workdir, capsys):
    for name, argv in _bad_cases(workdir).items():
        try:
            status = main(argv)
        except SystemExit as stop:  # argparse
            status = stop.code
        err = capsys.readouterr().err.strip()
        assert status == 2, name
        assert err.startswith("trial: error: ") and "\n" not in err, (name, err)
        assert "Traceback" not in err, name


def test_hostile_bag_in_a_real_process(workdir):
    """The console entry point itself: status 2, one stderr line, no traceback."""
    bag = workdir / "garbage_bag"
    bag.mkdir(exist_ok=True)
    (bag / "metadata.yaml").write_text((workdir / "bag" / "metadata.yaml").read_text())
    for mcap in (workdir / "bag").glob("*.mcap"):
        (bag / mcap.name).write_bytes(b"\x89MCAP0\r\n" + os.urandom(3000))
    proc = subprocess.run([sys.executable, "-m", "ins_gnss_ros.trial.cli", "evaluate",
                           str(workdir / "bag"), "--truth", str(bag)],
                          capture_output=True, text=True, timeout=60)
    assert proc.returncode == 2
    assert len(proc.stderr.strip().splitlines()) == 1 and "Traceback" not in proc.stderr


def test_run_supervisor_restarts_a_crashed_node(workdir):
    """trial run: the strapdown as a supervised process; killed, it is reported and restarted."""
    supervisor = Supervisor(load_profile(workdir / "profile.yaml"), max_restarts=2, poll_s=0.05,
                            log=sys.stdout)
    status = []
    runner = threading.Thread(target=lambda: status.append(supervisor.run(False)))
    runner.start()
    try:
        record = supervisor.nodes["strapdown"]
        deadline = time.monotonic() + 20
        while record.process is None and time.monotonic() < deadline:
            time.sleep(0.05)
        first_pid = record.process.pid
        os.kill(first_pid, signal.SIGKILL)
        while (record.process is None or record.process.pid == first_pid) \
                and time.monotonic() < deadline:
            time.sleep(0.05)
        assert record.process.pid != first_pid and record.restarts == 1
        assert any("exited with status -9; restart 1/2" in e for e in supervisor.events)
    finally:
        supervisor.stop()
        runner.join(20)
    assert status == [0] and supervisor.events[-1] == "stopped"
    assert record.process.poll() is not None  # stopped with the supervisor


def _children(pid):
    """Process ids of the children of ``pid`` (None where /proc does not list them)."""
    try:
        return (Path("/proc") / str(pid) / "task" / str(pid) / "children").read_text().split()
    except OSError:
        return None


@pytest.mark.parametrize("command, status", [(["run"], 0),
                                             (["replay", "--rate", "1", "--processes"], 130)])
def test_ctrl_c_stops_the_graph_without_a_traceback(workdir, tmp_path, command, status):
    """Ctrl-C at a terminal: SIGINT to the foreground process group, here 0.5 s after the first
    node process started (still importing: the hardest case, where a node given SIGINT prints a
    KeyboardInterrupt traceback). The nodes are stopped, trial ends with its status and no
    traceback, from itself or from a node."""
    argv = [str(Path(sys.executable).parent / "trial"), command[0]]
    if command[0] == "replay":
        argv += [str(workdir / "bag"), "--out", str(tmp_path / "out"), *command[1:]]
    argv += ["--config", str(workdir / "profile.yaml")]
    # A job of its own with SIGINT at its default, like a shell's foreground job (a suite
    # started in the background, `make test &`, has SIGINT ignored, and children inherit it).
    proc = subprocess.Popen(argv, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            start_new_session=True,
                            preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))
    try:
        deadline = time.monotonic() + 30
        while not _children(proc.pid) and proc.poll() is None and time.monotonic() < deadline:
            time.sleep(0.02)
        nodes = _children(proc.pid)
        if not nodes:
            pytest.skip(f"no node process started (status {proc.poll()})")
        time.sleep(0.5)
        os.killpg(proc.pid, signal.SIGINT)
        _, err = proc.communicate(timeout=60)  # the nodes hold stderr too: they are gone
    finally:
        if proc.poll() is None:
            os.killpg(proc.pid, signal.SIGKILL)
            proc.wait()
    assert "Traceback" not in err, err
    assert proc.returncode == status, err
    assert not any((Path("/proc") / pid).exists() for pid in nodes)
