"""``trial replay``: the graph of a profile over a bag, in-process on the bus and as processes.

Truth: the simulated trajectory (truth/state of the bag), the outage protocol worked out by
hand, and the bag's own stamps for the once-per-second diagnostics.
"""
import json
import math
from pathlib import Path

import numpy as np
import pytest
import yaml
from conftest import REPO

from ins_gnss_ros import io as bagio
from ins_gnss_ros.io import messages_equal
from ins_gnss_ros.trial import contract_messages as msgs
from ins_gnss_ros.trial.cli import main
from ins_gnss_ros.trial.inputs import InputTopicsError
from ins_gnss_ros.trial.offline import replay_offline
from ins_gnss_ros.trial.outages import gnss_windows, in_outage
from ins_gnss_ros.trial.processes import replay_processes
from ins_gnss_ros.trial.profile import ProfileError, load_profile, profile_with_truth_init
from ins_gnss_ros.trial.replay import replay
from ins_gnss_ros.trial.simulate import SimOptions, simulate

DURATION = 6.0
PROFILE = """
/**:
  ros__parameters:
    use_sim_time: false
strapdown:
  ros__parameters:
    init.latitude_deg: 0.0
    init.longitude_deg: 0.0
    publish_every: 2
ekf_not_written_yet:
  ros__parameters:
    anything: 1
"""


@pytest.fixture(scope="module")
def car_bag(tmp_path_factory):
    # Navigation-grade IMU increments: the strapdown alone must follow the truth closely.
    return simulate("car", DURATION, 11, tmp_path_factory.mktemp("replay") / "car",
                    SimOptions(imu_topic="delta", imu_grade="navigation"))


@pytest.fixture(scope="module")
def profile(tmp_path_factory):
    path = tmp_path_factory.mktemp("profile") / "strapdown.yaml"
    path.write_text(PROFILE)
    return path


@pytest.fixture(scope="module")
def first_run(car_bag, profile, tmp_path_factory):
    out = tmp_path_factory.mktemp("run") / "a"
    summary = replay(car_bag, profile, out, init_from_truth=True)
    return out, summary


def _states(out):
    return [m.msg for m in bagio.read_bag(out / "bag", ["ins/state"])]


def test_graph_is_the_registry_nodes_with_a_section(profile):
    p = load_profile(profile)
    assert p.graph == ("strapdown",) and p.ignored == ("ekf_not_written_yet",)


def test_strapdown_on_the_bus_follows_the_truth(first_run, car_bag):
    out, summary = first_run
    assert summary["graph"] == ["strapdown"] and summary["mode"] == "in-process"
    states = _states(out)
    n_delta = sum(1 for m in bagio.read_bag(car_bag, ["imu/delta"]))
    assert len(states) == n_delta // 2  # publish_every: 2 from the profile
    # The node stamps from float seconds: match the truth to the millisecond.
    truth = {round(m.t_ns / 1e6): m.msg for m in bagio.read_bag(car_bag, ["truth/state"])}
    compared = 0
    for s in states:
        t = truth.get(round(bagio.msg_stamp_ns(s) / 1e6))
        if t is None:
            continue
        compared += 1
        north = (s.latitude - t.latitude) * 6.36e6
        east = (s.longitude - t.longitude) * 6.39e6 * math.cos(t.latitude)
        assert math.hypot(north, east) < 0.05
        assert abs(s.velocity.x - t.velocity.x) < 0.02 and abs(s.velocity.y - t.velocity.y) < 0.02
        dq = abs(s.orientation.w * t.orientation.w + s.orientation.x * t.orientation.x
                 + s.orientation.y * t.orientation.y + s.orientation.z * t.orientation.z)
        assert 2 * math.acos(min(1.0, dq)) < math.radians(0.01)
    assert compared > 50


def test_truth_init_goes_to_the_nodes_that_declare_it_without_yaml_aliases(car_bag, tmp_path):
    # The ekf has init.* parameters of its own (sigmas): it must not be handed the strapdown's
    # position, and the written file must be one rcl accepts (no YAML anchors/aliases).
    path = tmp_path / "p.yaml"
    path.write_text("strapdown:\n  ros__parameters:\n    init.latitude_deg: 0.0\n"
                    "ekf:\n  ros__parameters:\n    init.position_sigma_m: 2.0\n")
    written = profile_with_truth_init(load_profile(path), car_bag, tmp_path / "derived.yaml")
    text = written.read_text()
    assert "&" not in text and "*id" not in text
    sections = yaml.safe_load(text)
    truth = next(bagio.iter_bag(car_bag, ["truth/state"])).msg
    strapdown = sections["/strapdown"]["ros__parameters"]
    assert strapdown["init.latitude_deg"] == pytest.approx(math.degrees(truth.latitude))
    assert len(strapdown["init.velocity_enu"]) == 3
    assert sections["/ekf"]["ros__parameters"] == {"init.position_sigma_m": 2.0}


def test_diagnostics_once_per_second_of_bag_time(first_run, car_bag):
    out, _ = first_run
    diag = bagio.read_bag(out / "bag", ["/diagnostics"])
    t0 = bagio.read_bag(car_bag)[0].t_ns
    stamps = [m.t_ns for m in diag]
    assert stamps == [t0 + k * 1_000_000_000 for k in range(1, len(stamps) + 1)]
    assert len(stamps) == int(DURATION)
    assert diag[0].msg.status[0].name.endswith("strapdown")


def test_replay_is_deterministic(first_run, car_bag, profile, tmp_path):
    out, _ = first_run
    replay(car_bag, profile, tmp_path / "b", init_from_truth=True)
    a, b = bagio.read_bag(out / "bag"), bagio.read_bag(tmp_path / "b" / "bag")
    assert len(a) == len(b) > 0
    assert all(x.topic == y.topic and x.t_ns == y.t_ns and messages_equal(x.msg, y.msg)
               for x, y in zip(a, b))


def test_outage_windows_follow_the_protocol():
    t0 = 1_000_000_000_000
    msgs = [bagio.BagMessage("/gnss/fix", t0 + k * 1_000_000_000, None) for k in range(101)]
    windows = gnss_windows(msgs, "5:20:10")
    # First GNSS at t0, last at t0 + 100 s; starts 10, 30, 50, 70 s (none after 100 - 30 s).
    expected = [[t0 + s * 10**9, t0 + (s + 5) * 10**9] for s in (10, 30, 50, 70)]
    assert windows.tolist() == expected
    assert gnss_windows(msgs, None).shape == (0, 2)


def test_outages_withhold_gnss_and_are_recorded(tmp_path, profile):
    """A synthetic 60 s bag: increments at 10 Hz, one fix per second; 5 s outages every 15 s
    from 10 s withhold exactly the fixes stamped inside [10, 15), [25, 30)."""
    t0 = 1_767_225_600 * 10**9
    with bagio.BagWriter(tmp_path / "bag") as writer:
        for k in range(1, 601):
            writer.write("imu/delta", msgs.delta_msg(t0 + k * 10**8, [0, 0, 0],
                                                      [0, 0, 0.981], 0.1))
        for k in range(61):
            writer.write("gnss/fix", msgs.fix_msg(t0 + k * 10**9, 0.1, 0.2, 3.0, [1, 1, 1]))
    summary = replay(tmp_path / "bag", profile, tmp_path / "out", outages="5:15:10")
    assert summary["gnss_withheld"] == 10
    saved = json.loads((tmp_path / "out" / "replay.json").read_text())
    assert saved["outage_windows_ns"] == [[t0 + 10 * 10**9, t0 + 15 * 10**9],
                                          [t0 + 25 * 10**9, t0 + 30 * 10**9]]
    assert saved["outages"] == "5:15:10"
    # What went in and came out, per topic: the outputs as the output bag holds them.
    counts = saved["messages"]
    assert counts["/imu/delta"] == {"in": 600, "withheld": 0, "out": 0}
    assert counts["/gnss/fix"] == {"in": 51, "withheld": 10, "out": 0}
    recorded = bagio.read_bag(tmp_path / "out" / "bag")
    outputs = {t for t in counts if counts[t]["out"]}
    assert outputs == {m.topic for m in recorded} == {"/ins/state", "/diagnostics"}
    assert all(counts[t]["out"] == sum(m.topic == t for m in recorded) for t in outputs)
    assert counts["/diagnostics"]["out"] == 60  # once per second of bag time


def test_satellite_windows_are_recorded_with_the_satellites_kept(tmp_path, profile):
    """The bundled walk's GNSS beside synthetic increments: --satellites 3:20:40:30 withholds
    the receiver's fixes and velocities in the windows (test_outages.py checks the thinning)
    and records the windows and the satellites kept in replay.json."""
    from ins_gnss_ros.trial.inputs import read_inputs

    gnss = [m for m in read_inputs(REPO / "bags" / "walk_0827") if m.topic.startswith("/gnss/")]
    with bagio.BagWriter(tmp_path / "bag") as writer:
        for m in gnss:
            writer.write(m.topic, m.msg, m.t_ns)
        for t in range(gnss[0].t_ns, gnss[-1].t_ns, 10**8):
            writer.write("imu/delta", msgs.delta_msg(t, [0, 0, 0], [0, 0, 0.981], 0.1))
    summary = replay(tmp_path / "bag", profile, tmp_path / "out", satellites="3:20:40:30")
    windows = gnss_windows(gnss, "20:40:30")
    saved = json.loads((tmp_path / "out" / "replay.json").read_text())
    assert saved["satellites"] == "3:20:40:30" and saved["outage_windows_ns"] == []
    assert saved["satellite_windows_ns"] == windows.tolist()
    assert np.allclose(saved["satellite_windows_s"], windows * 1e-9)
    assert [len(k) for k in saved["satellites_kept"]] == [3, 3]
    assert all(s[0] in "GE" for k in saved["satellites_kept"] for s in k)
    inside = sum(m.topic == "/gnss/fix" and bool(in_outage(m.t_ns, windows)) for m in gnss)
    assert saved["messages"]["/gnss/fix"]["withheld"] == inside > 0
    assert summary["gnss_withheld"] == 2 * inside  # with as many velocities


def test_relative_topic_names_replay_like_absolute_ones(first_run, car_bag, profile, tmp_path,
                                                        relative_copy):
    """A bag recorded as ``imu/delta`` (no leading ``/``) gives the identical outputs, under
    fully qualified names, in-process (truth init included) and offline."""
    bag = relative_copy(car_bag, tmp_path / "relative")
    out, summary = first_run
    again = replay(bag, profile, tmp_path / "r", init_from_truth=True)
    assert again["messages"] == summary["messages"]
    a, b = bagio.read_bag(out / "bag"), bagio.read_bag(tmp_path / "r" / "bag")
    assert len(a) == len(b) > 0 and {m.topic for m in b} == {"/ins/state", "/diagnostics"}
    assert all(x.topic == y.topic and x.t_ns == y.t_ns and messages_equal(x.msg, y.msg)
               for x, y in zip(a, b))
    offline = tmp_path / "offline.yaml"
    offline.write_text(PROFILE + "ekf:\n  ros__parameters:\n    imu_grade: navigation\n")
    replay_offline(car_bag, offline, tmp_path / "oa")
    replay_offline(bag, offline, tmp_path / "or")
    a, b = bagio.read_bag(tmp_path / "oa" / "bag"), bagio.read_bag(tmp_path / "or" / "bag")
    assert len(a) == len(b) > 0
    assert all(x.topic == y.topic and x.t_ns == y.t_ns and messages_equal(x.msg, y.msg)
               for x, y in zip(a, b))


def test_a_bag_under_other_names_replays_with_remap(first_run, car_bag, profile, tmp_path):
    """The trial with its increments recorded as a driver's ``/imu_driver/delta``: `trial
    replay --remap` gives the outputs of the original bag."""
    bag = tmp_path / "renamed"
    with bagio.BagWriter(bag) as writer:
        for m in bagio.read_bag(car_bag):
            writer.write("/imu_driver/delta" if m.topic == "/imu/delta" else m.topic, m.msg,
                         m.t_ns)
    with pytest.raises(InputTopicsError, match="names: --remap /imu_driver/delta:=/imu/delta"):
        replay(bag, profile, tmp_path / "n")
    assert main(["replay", str(bag), "--config", str(profile), "--out", str(tmp_path / "r"),
                 "--init-from-truth", "--remap", "/imu_driver/delta:=/imu/delta"]) == 0
    out, _ = first_run
    a, b = bagio.read_bag(out / "bag"), bagio.read_bag(tmp_path / "r" / "bag")
    assert len(a) == len(b) > 0
    assert all(x.topic == y.topic and x.t_ns == y.t_ns and messages_equal(x.msg, y.msg)
               for x, y in zip(a, b))


def test_a_bag_topic_no_node_reads_is_named_with_its_remap(car_bag, tmp_path, capsys):
    """The trial's fixes recorded as a driver's ``/fix`` beside its increments: the replay
    runs on the increments and says which topic no node read, and the remapping that feeds it
    (the filter would otherwise only say that no gnss/fix arrives)."""
    bag = tmp_path / "fix"
    with bagio.BagWriter(bag) as writer:
        for m in bagio.read_bag(car_bag):
            writer.write("/fix" if m.topic == "/gnss/fix" else m.topic, m.msg, m.t_ns)
    offline = tmp_path / "offline.yaml"
    offline.write_text(PROFILE + "ekf:\n  ros__parameters:\n    imu_grade: navigation\n")
    note = "/fix (sensor_msgs/msg/NavSatFix) is read by no node: --remap /fix:=/gnss/fix"
    assert main(["replay", str(bag), "--config", str(offline), "--offline", "--out",
                 str(tmp_path / "o")]) == 0
    assert f"warning: {note}" in capsys.readouterr().err.splitlines()
    assert json.loads((tmp_path / "o" / "replay.json").read_text())["unread_topics"] == [note]


@pytest.fixture
def magnetometer_bag(tmp_path):
    """A bag whose only topic (imu/mag) neither the strapdown nor the offline filter reads."""
    t0 = 1_767_225_600 * 10**9
    with bagio.BagWriter(tmp_path / "mag_only") as writer:
        for k in range(10):
            writer.write("imu/mag", msgs.mag_msg(t0 + k * 10**8, [2e-5, 0.0, -4e-5], 1e-14))
    return tmp_path / "mag_only"


def test_a_bag_matching_no_input_is_refused(magnetometer_bag, profile, tmp_path, capsys):
    with pytest.raises(InputTopicsError, match="/imu/mag.*/imu/delta"):
        replay(magnetometer_bag, profile, tmp_path / "a")
    offline = tmp_path / "offline.yaml"
    offline.write_text(PROFILE + "ekf:\n  ros__parameters:\n    imu_grade: navigation\n")
    with pytest.raises(InputTopicsError, match="/imu/mag.*/gnss/fix"):
        replay_offline(magnetometer_bag, offline, tmp_path / "b")
    assert main(["replay", str(magnetometer_bag), "--config", str(profile), "--out",
                 str(tmp_path / "c")]) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith("trial: error: ") and "\n" not in err and "/imu/mag" in err


def test_a_bag_of_another_type_on_an_input_is_refused(tmp_path, profile, capsys):
    """Magnetometer samples recorded as imu/delta: one line naming the topic and both types,
    not a traceback from the strapdown reading them as increments."""
    t0 = 1_767_225_600 * 10**9
    with bagio.BagWriter(tmp_path / "wrong") as writer:
        for k in range(10):
            writer.write("imu/delta", msgs.mag_msg(t0 + k * 10**8, [2e-5, 0.0, -4e-5], 1e-14))
    with pytest.raises(InputTopicsError, match="/imu/delta: sensor_msgs/msg/MagneticField "
                                               "published where ins_gnss_msgs/msg/ImuDelta is"):
        replay(tmp_path / "wrong", profile, tmp_path / "a")
    assert main(["replay", str(tmp_path / "wrong"), "--config", str(profile), "--out",
                 str(tmp_path / "b")]) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith("trial: error: ") and "\n" not in err


def test_a_bag_matching_no_input_is_refused_by_the_processes(magnetometer_bag, profile,
                                                              tmp_path):
    """The node processes' subscriptions, found by graph queries, are the inputs."""
    with pytest.raises(InputTopicsError, match="/imu/mag.*/imu/delta"):
        replay_processes(magnetometer_bag, profile, tmp_path / "p", rate=1.0)


def test_bad_profiles_are_one_line_errors(tmp_path, car_bag):
    cases = {
        "none.yaml": "other:\n  ros__parameters:\n    a: 1\n",
        "range.yaml": "strapdown:\n  ros__parameters:\n    init.latitude_deg: 123.0\n",
        "type.yaml": "strapdown:\n  ros__parameters:\n    history_s: fast\n",
        "syntax.yaml": "strapdown: [\n",
    }
    for name, text in cases.items():
        path = tmp_path / name
        path.write_text(text)
        with pytest.raises(ProfileError) as info:
            replay(car_bag, path, tmp_path / ("out_" + name))
        assert "\n" not in str(info.value) and name in str(info.value)


def test_offline_compass_errors_are_profile_errors(tmp_path, car_bag):
    """--offline builds the graph's compass where the ekf fuses its headings: a calibration
    file that does not read is a one-line error naming the section, as the node's would be."""
    path = tmp_path / "compass.yaml"
    path.write_text(PROFILE + "ekf:\n  ros__parameters:\n    use_magnetic_heading: true\n"
                    "mag_compass:\n  ros__parameters:\n    calibration_file: /nonexistent.yaml\n")
    with pytest.raises(ProfileError, match="mag_compass: parameter 'calibration_file'") as info:
        replay_offline(car_bag, path, tmp_path / "out")
    assert "\n" not in str(info.value)


def test_nodes_as_processes_on_dds(car_bag, profile, tmp_path):
    """--rate 2 --processes: the strapdown as a console-script process with use_sim_time, the
    bag played at 2x on DDS. DDS on a loaded 2-core machine may drop increments (a reader's
    KEEP_LAST history overflowing, discovery finishing after the first messages), so this
    checks that the graph ran and followed the standing car, not bit-identity."""
    summary = replay_processes(car_bag, profile, tmp_path / "p", rate=2.0, init_from_truth=True)
    assert summary["mode"] == "processes" and summary["graph"] == ["strapdown"]
    states = _states(tmp_path / "p")
    n_delta = sum(1 for m in bagio.read_bag(car_bag, ["imu/delta"]))
    assert 0.5 * n_delta // 2 < len(states) <= n_delta // 2
    truth = bagio.read_bag(car_bag, ["truth/state"])[-1].msg
    last = states[-1]
    assert abs(bagio.msg_stamp_ns(last) - bagio.msg_stamp_ns(truth)) <= 20_000_000  # played to the end
    assert abs(last.latitude - truth.latitude) * 6.36e6 < 0.5


def test_offline_filter_path_records_states_and_covariances(car_bag, tmp_path):
    """--offline: the ekf section's filter over the bag without the graph; the standing car's
    GNSS-aided position stays within the 0.5 m fix noise, nav/odom carries a positive-definite
    pose covariance, and the outputs are the graph's topics."""
    profile = tmp_path / "offline.yaml"
    profile.write_text(PROFILE + "ekf:\n  ros__parameters:\n    imu_grade: navigation\n"
                       "    lever_arm: [0.0, 0.0, 1.5]\n")
    summary = replay_offline(car_bag, profile, tmp_path / "o")
    assert summary["mode"] == "offline"
    assert set(summary["topics"]) == {"/ins/state", "/nav/odom", "/nav/fix", "/nav/status",
                                      "/tf", "/tf_static"}
    states = _states(tmp_path / "o")
    truth = bagio.read_bag(car_bag, ["truth/state"])[-1].msg
    last = states[-1]
    north = (last.latitude - truth.latitude) * 6.36e6
    east = (last.longitude - truth.longitude) * 6.39e6 * math.cos(truth.latitude)
    assert math.hypot(north, east) < 0.5 and abs(last.altitude - truth.altitude) < 1.0
    odom = bagio.read_bag(tmp_path / "o" / "bag", ["nav/odom"])[-1].msg
    pose = np.reshape(odom.pose.covariance, (6, 6))
    assert np.all(np.linalg.eigvalsh(pose) > 0) and pose[0, 0] < 0.5 ** 2
    bad = tmp_path / "bad.yaml"
    bad.write_text(PROFILE + "ekf:\n  ros__parameters:\n    imu_grade: potato\n")
    with pytest.raises(ProfileError, match="imu_grade"):
        replay_offline(car_bag, bad, tmp_path / "bad")


def test_generic_graph_with_the_imu_preprocessor(tmp_path):
    """Whatever nodes the registry holds: raw IMU -> imu_preprocessor -> imu/delta ->
    strapdown -> ins/state, with no replay code naming either node."""
    from ins_gnss_ros.nodes.registry import NODES

    if "imu_preprocessor" not in NODES:
        pytest.skip("imu_preprocessor not registered yet")
    bag = simulate("car", 3.0, 2, tmp_path / "raw", SimOptions(imu_grade="navigation"))
    profile = tmp_path / "p.yaml"
    profile.write_text(PROFILE + "imu_preprocessor:\n  ros__parameters:\n    rate_hz: 200.0\n"
                       "    nav_rate_hz: 100.0\n")
    summary = replay(bag, profile, tmp_path / "out", init_from_truth=True)
    assert summary["graph"] == ["imu_preprocessor", "strapdown"]
    assert {"/imu/delta", "/ins/state"} <= set(summary["topics"])
    states = _states(tmp_path / "out")
    truth = bagio.read_bag(bag, ["truth/state"])[-1].msg
    assert len(states) > 100
    assert abs(states[-1].latitude - truth.latitude) * 6.36e6 < 0.5


@pytest.fixture(scope="module")
def default_drive(tmp_path_factory):
    """A simulated drive replayed through config/default.yaml by the graph and offline."""
    root = tmp_path_factory.mktemp("default_drive")
    bag = simulate("car", 60.0, 3, root / "drive")
    profile = Path(__file__).resolve().parents[2] / "config" / "default.yaml"
    replay(bag, profile, root / "graph")
    replay_offline(bag, profile, root / "offline")
    return bag, profile, root / "graph", root / "offline"


def test_offline_agrees_with_the_graph(default_drive):
    """--offline runs the graph's cores without the graph: on a simulated drive through
    config/default.yaml, its horizontal RMS after the start is within 10 % of the graph's."""
    from ins_gnss_ros.trial.report import evaluate_run

    _, _, graph_out, offline_out = default_drive
    graph, _ = evaluate_run(graph_out, plots=False, skip_s=35.0)
    offline, _ = evaluate_run(offline_out, plots=False, skip_s=35.0)
    a, b = graph.stats["horizontal_m"].rms, offline.stats["horizontal_m"].rms
    assert a < 0.3 and abs(b - a) <= 0.1 * a, (a, b)
    # Both ins/state carry the sensor errors the solution was compensated with, and they come
    # out alike (the graph's strapdown applies the ekf's corrections a little later).
    (graph_gyro, graph_accel), (gyro, accel) = [
        ((m.gyro_bias.x, m.gyro_bias.y, m.gyro_bias.z), (m.accel_bias.x, m.accel_bias.y,
                                                         m.accel_bias.z))
        for m in (_states(out)[-1] for out in (graph_out, offline_out))]
    assert np.all(np.abs(gyro) > 0.0) and np.all(np.abs(accel) > 0.0)
    assert np.allclose(gyro, graph_gyro, atol=2e-4) and np.allclose(accel, graph_accel, atol=5e-3)


def test_offline_publishes_what_the_graph_does(default_drive):
    """--offline writes the nodes' outputs at their rates: ins/state at every IMU increment
    from the filter's start (the strapdown's; at an increment with updates, the state before
    them), nav/fix and nav/odom at the ekf's output_rate_hz (10 Hz) with the covariance of
    the epoch before. Its velocity maxima and NEES agree with the graph's to 2 % (with the
    states of its epochs alone: velocity maxima 0.90, NEES 0.94 of the graph's on the 600 s
    drive, docs/results/product_path.md "2026-12-05 (session 23)")."""
    from ins_gnss_ros.trial.report import evaluate_run

    _, _, graph_out, offline_out = default_drive
    graph, offline = (bagio.bag_message_counts(out / "bag") for out in (graph_out, offline_out))
    assert 0.97 * graph["/ins/state"] <= offline["/ins/state"] <= graph["/ins/state"]
    for topic in ("/nav/odom", "/nav/fix"):
        assert abs(offline[topic] - graph[topic]) <= 0.03 * graph[topic], topic
    odom = bagio.read_bag(offline_out / "bag", ["/nav/odom"])
    assert np.min(np.diff([bagio.msg_stamp_ns(m.msg) for m in odom])) >= 0.1e9 - 1e3
    metrics = [evaluate_run(out, plots=False, skip_s=35.0)[1] for out in (graph_out, offline_out)]
    for name in ("velocity_horizontal_max_mps", "velocity_vertical_max_mps",
                 "nees_position_mean", "nees_velocity_mean", "nees_attitude_mean"):
        assert abs(metrics[1][name] - metrics[0][name]) <= 0.02 * metrics[0][name], name


def test_offline_fuses_the_compass_as_the_graph_does(default_drive, tmp_path):
    """--offline runs mag_compass's front end, levelled with the filter's attitude at each
    sample: on the simulated drive with the magnetometer taken as calibrated (no field fit to
    wait for), it fuses the headings the graph's mag_compass publishes (to 3 %: the offline
    nav/status, once a second, leaves out the last second's), and their heading errors after
    the start agree to 5 % (0.423 / 0.426 deg; 0.470 / 0.416 before the offline path timed its
    increments as the messages do and the alignment rebuilt the system matrix,
    docs/results/product_path.md)."""
    from ins_gnss_ros.trial.report import evaluate_run

    bag, profile, _, _ = default_drive
    sections = yaml.safe_load(profile.read_text())
    sections["mag_compass"]["ros__parameters"]["online_calibration.enabled"] = False
    calibrated = tmp_path / "calibrated.yaml"
    calibrated.write_text(yaml.safe_dump(sections))
    replay(bag, calibrated, tmp_path / "graph")
    summary = replay_offline(bag, calibrated, tmp_path / "offline")
    assert summary["graph"] == ["imu_preprocessor", "mag_compass", "ekf (filter only)"]
    assert "magnetometer not calibrated yet: heading withheld" not in summary["events"]
    published = len(bagio.read_bag(tmp_path / "graph" / "bag", ["mag/heading"]))
    fused = sum(u.name == "mag_heading" and u.accepted for m in
                bagio.read_bag(tmp_path / "offline" / "bag", ["nav/status"])
                for u in m.msg.updates)
    assert published > 2000 and abs(fused - published) <= 0.03 * published, (fused, published)
    graph, _ = evaluate_run(tmp_path / "graph", plots=False, skip_s=35.0)
    offline, _ = evaluate_run(tmp_path / "offline", plots=False, skip_s=35.0)
    a, b = graph.stats["heading_deg"].rms, offline.stats["heading_deg"].rms
    assert max(a, b) < 0.5 and abs(b - a) <= 0.05 * a, (a, b)


def _walk(tree, static, frame, root):
    """(translation, rotation matrix) of ``frame`` in ``root`` through the transforms
    child -> (parent, translation, rotation): REP-105's tree walked up from the leaf."""
    from ins_gnss_ros.nav.rotations import quat_to_dcm

    t, c = np.zeros(3), np.eye(3)
    while frame != root:
        tf = tree.get(frame) or static[frame]
        r = tf.transform.rotation
        c_parent = quat_to_dcm([r.w, r.x, r.y, r.z])
        v = tf.transform.translation
        t, c = c_parent @ t + np.array([v.x, v.y, v.z]), c_parent @ c
        frame = tf.header.frame_id
    return t, c


@pytest.mark.parametrize("path", ["graph", "offline"])
def test_every_replay_bag_holds_the_tf_tree(default_drive, path):
    """/tf and /tf_static of a replay's bag: base_link and the sensor frames walked up to map
    at every /tf stamp give nav/odom's pose there; the static frames carry the profile's
    mounting and lever arm."""
    from ins_gnss_ros.nav.rotations import dcm_from_euler, quat_to_dcm

    _, profile, graph_out, offline_out = default_drive
    out = graph_out if path == "graph" else offline_out
    sections = load_profile(profile).sections
    rows = bagio.read_bag(out / "bag", ["/tf", "/tf_static", "nav/odom"])
    static = {tf.child_frame_id: tf for m in rows if m.topic == "/tf_static"
              for tf in m.msg.transforms}
    assert set(static) == {"imu_link", "gnss_0"}
    assert all(tf.header.frame_id == "base_link" for tf in static.values())
    odom = {bagio.msg_stamp_ns(m.msg): m.msg for m in rows if m.topic == "/nav/odom"}
    walked = 0
    for m in rows:
        if m.topic != "/tf":
            continue
        tree = {tf.child_frame_id: tf for tf in m.msg.transforms}
        stamp = bagio.msg_stamp_ns(tree["base_link"])
        pose = odom[stamp].pose.pose
        o = pose.orientation
        c_nb = quat_to_dcm([o.w, o.x, o.y, o.z])
        t, c = _walk(tree, static, "base_link", "map")
        np.testing.assert_allclose(t, [pose.position.x, pose.position.y, pose.position.z],
                                   atol=1e-9)
        np.testing.assert_allclose(c, c_nb, atol=1e-12)
        t, c = _walk(tree, static, "gnss_0", "map")
        lever = sections["ekf"].get("lever_arm", [0.0, 0.0, 0.0])
        np.testing.assert_allclose(t, [pose.position.x, pose.position.y, pose.position.z]
                                   + c_nb @ lever, atol=1e-9)
        _, c = _walk(tree, static, "imu_link", "map")
        mounting = sections["imu_preprocessor"].get("mounting_rpy_deg", [0.0, 0.0, 0.0])
        np.testing.assert_allclose(c, c_nb @ dcm_from_euler(*np.radians(mounting)), atol=1e-12)
        walked += 1
    assert walked == len(odom) > 100


def test_with_wheel_odometry_the_tree_is_map_odom_base_link_and_odom_is_continuous(tmp_path):
    """REP-105 with wheel odometry fused (config/sim_car_wheel.yaml, offline path): map ->
    odom -> base_link walks to nav/odom's pose, and odom -> base_link moves by no more than the
    velocity says between two epochs while map -> odom takes the GNSS corrections."""
    bag = simulate("car", 60.0, 4, tmp_path / "bag", SimOptions(wheel_odometry=True))
    replay_offline(bag, REPO / "config" / "sim_car_wheel.yaml", tmp_path / "out",
                   outages="15:30:30")
    rows = bagio.read_bag(tmp_path / "out" / "bag", ["/tf", "/tf_static", "nav/odom"])
    static = {tf.child_frame_id: tf for m in rows if m.topic == "/tf_static"
              for tf in m.msg.transforms}
    odom = {bagio.msg_stamp_ns(m.msg): m.msg for m in rows if m.topic == "/nav/odom"}
    trees = [{tf.child_frame_id: tf for tf in m.msg.transforms} for m in rows if m.topic == "/tf"]
    assert len(trees) == len(odom) > 100
    previous, corrections = None, []
    for tree in trees:
        assert tree["base_link"].header.frame_id == "odom"
        assert tree["odom"].header.frame_id == "map"
        msg = odom[bagio.msg_stamp_ns(tree["base_link"])]
        p = msg.pose.pose.position
        t, _ = _walk(tree, static, "base_link", "map")
        np.testing.assert_allclose(t, [p.x, p.y, p.z], atol=1e-9)
        v = tree["base_link"].transform.translation
        here = (bagio.msg_stamp_ns(msg) * 1e-9, np.array([v.x, v.y, v.z]),
                np.array([tree["odom"].transform.translation.x,
                          tree["odom"].transform.translation.y]))
        if previous is not None:
            dt = here[0] - previous[0]
            assert np.linalg.norm(here[1] - previous[1]) <= 40.0 * dt + 1e-6  # below 40 m/s
            corrections.append(np.linalg.norm(here[2] - previous[2]))
        previous = here
    assert max(corrections) > 0.0  # map -> odom moves: the GNSS corrections go there
