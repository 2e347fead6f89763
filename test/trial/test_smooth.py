"""trial smooth and trial export on a simulated SAR flight (late GNSS), against the offline
replay of the same profile, the truth, and the export formats' own rules."""
import csv
import datetime as dt
import json
import re
import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np
import pytest

from ins_gnss_ros import io as bagio
from ins_gnss_ros.nav.earth import radii
from ins_gnss_ros.trial.cli import main
from ins_gnss_ros.trial.export import export_run
from ins_gnss_ros.trial.offline import replay_offline
from ins_gnss_ros.trial.report import evaluate_run
from ins_gnss_ros.trial.simulate import SimOptions, simulate
from ins_gnss_ros.trial.smooth import smooth

PROFILE = Path(__file__).resolve().parents[2] / "config" / "aircraft_sar.yaml"
POINT = (0.5, 0.0, -1.0)
#: GPST - UTC in 2026 (the simulated trials' epoch).
LEAP_S = 18


@pytest.fixture(scope="module")
def runs(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("smooth")
    bag = simulate("aircraft", 90.0, 3, tmp / "bag", SimOptions(gnss_latency=0.2))
    smoothed = tmp / "smoothed"
    summary = smooth(bag, PROFILE, smoothed, point=POINT, exports="csv,kml,pos")
    offline = tmp / "offline"
    replay_offline(bag, PROFILE, offline)
    return bag, smoothed, offline, summary


def test_the_forward_part_is_the_offline_replay_message_by_message(runs):
    _, smoothed, offline, _ = runs
    for topic in ("/ins/state", "/nav/fix", "/nav/odom", "/nav/status"):
        a = bagio.read_bag(offline / "bag", [topic])
        b = bagio.read_bag(smoothed / "bag", ["/forward" + topic])
        assert len(a) == len(b) > 0, topic
        for x, y in zip(a, b):
            assert x.t_ns == y.t_ns
            assert bagio.first_difference(x.msg, y.msg) is None, topic


def test_evaluate_reads_the_smoothed_run_and_it_beats_the_forward_one(runs):
    _, smoothed, offline, summary = runs
    assert summary["mode"] == "smooth"
    _, fwd = evaluate_run(offline, plots=False, skip_s=30.0)
    _, sm = evaluate_run(smoothed, plots=False, skip_s=30.0, point=POINT, apertures=(1.0,))
    _, fwd_point = evaluate_run(offline, plots=False, skip_s=30.0, point=POINT,
                                apertures=(1.0,))
    assert sm["horizontal_rms_m"] < fwd["horizontal_rms_m"]
    assert sm["aperture"][0]["rms_m"] < 0.5 * fwd_point["aperture"][0]["rms_m"]
    assert sm["aperture"][0]["rms_m"] < 0.005  # seed 003's 1 s requirement


def test_the_point_is_recorded_at_the_imu_rate(runs):
    bag, smoothed, _, _ = runs
    imu = bagio.read_bag(bag, ["/imu/data_raw"])
    point = bagio.read_bag(smoothed / "bag", ["/point/state"])
    stamps = np.array([bagio.msg_stamp_ns(m.msg) for m in point])
    imu_stamps = np.array([bagio.msg_stamp_ns(m.msg) for m in imu])
    # Stamps pass through float POSIX seconds (as the offline path's): 0.24 us resolution.
    assert np.all(np.abs(np.diff(stamps) - 5_000_000) < 1000)
    nearest = imu_stamps[np.clip(np.searchsorted(imu_stamps, stamps - 1000), 0, len(imu) - 1)]
    assert np.all(np.abs(nearest - stamps) < 1000)


def test_the_forward_point_is_the_forward_solution_at_the_lever_arm(runs):
    """forward/point/state is forward/ins/state (the pass's own, causal states at the samples)
    moved to the point: position by the lever arm, velocity by the body rate about it."""
    from ins_gnss_ros.nav.lever_arm import lever_arm_position

    _, smoothed, _, _ = runs
    msgs = bagio.read_bag(smoothed / "bag", ["/forward/ins/state", "/forward/point/state"])
    ins = [m.msg for m in msgs if m.topic == "/forward/ins/state"]
    point = [m.msg for m in msgs if m.topic == "/forward/point/state"]
    assert len(point) == len(ins) > 1000
    # the same samples (stamps rounded from the same seconds in two ways: within 1 us)
    assert np.max(np.abs(np.subtract([bagio.msg_stamp_ns(m) for m in point],
                                     [bagio.msg_stamp_ns(m) for m in ins]))) < 1000
    q = np.array([[m.orientation.w, m.orientation.x, m.orientation.y, m.orientation.z]
                  for m in ins])
    lat, lon, h = lever_arm_position(np.array([m.latitude for m in ins]),
                                     np.array([m.longitude for m in ins]),
                                     np.array([m.altitude for m in ins]), q,
                                     np.array(POINT, float))
    np.testing.assert_allclose([p.latitude for p in point], lat, rtol=0, atol=1e-12)
    np.testing.assert_allclose([p.longitude for p in point], lon, rtol=0, atol=1e-12)
    np.testing.assert_allclose([p.altitude for p in point], h, rtol=0, atol=1e-6)
    rate = np.array([[p.angular_velocity.x, p.angular_velocity.y, p.angular_velocity.z]
                     for p in point])
    assert np.all(np.isfinite(rate)) and np.max(np.abs(rate)) < 1.0  # rad/s of a flight


def _bag_solution(smoothed, topic="/ins/state"):
    msgs = bagio.read_bag(smoothed / "bag", [topic])
    return (np.array([bagio.msg_stamp_ns(m.msg) * 1e-9 for m in msgs]),
            np.array([[np.degrees(m.msg.latitude), np.degrees(m.msg.longitude),
                       m.msg.altitude] for m in msgs]),
            np.array([[m.msg.velocity.x, m.msg.velocity.y, m.msg.velocity.z] for m in msgs]))


def _close(lla, ref):
    """Within 1e-6 deg (lat/lon) and 1 mm (horizontal and height)."""
    assert np.max(np.abs(lla[:, :2] - ref[:, :2])) < 1e-6
    rm, rn = radii(np.radians(ref[:, 0]))
    north = np.radians(lla[:, 0] - ref[:, 0]) * rm
    east = np.radians(lla[:, 1] - ref[:, 1]) * rn * np.cos(np.radians(ref[:, 0]))
    assert np.max(np.hypot(north, east)) < 1e-3
    assert np.max(np.abs(lla[:, 2] - ref[:, 2])) < 1e-3


def test_the_exports_are_written_for_every_solution(runs):
    _, smoothed, _, summary = runs
    names = sorted(Path(p).name for p in summary["exports"])
    assert names == sorted(f"{s}.{f}" for s in ("smoothed", "forward", "smoothed_point",
                                               "forward_point") for f in ("csv", "kml", "pos"))


def test_kml_parses_as_kml_and_matches_the_bag(runs):
    _, smoothed, _, _ = runs
    t, lla, _ = _bag_solution(smoothed)
    root = ET.parse(smoothed / "export" / "smoothed.kml").getroot()
    ns = {"k": "http://www.opengis.net/kml/2.2"}
    assert root.tag == "{http://www.opengis.net/kml/2.2}kml"
    text = root.find("k:Document/k:Placemark/k:LineString/k:coordinates", ns).text
    tuples = np.array([[float(x) for x in c.split(",")] for c in text.split()])
    _close(tuples[:, [1, 0, 2]], lla)  # KML tuples are lon,lat,height


def test_rtklib_pos_follows_the_solution_format_and_matches_the_bag(runs):
    """RTKLIB manual, appendix B: '%' header lines; per epoch 'yyyy/mm/dd hh:mm:ss.sss' in
    GPST, lat, lon (deg), height (m), Q, ns, sdn, sde, sdu, sdne, sdeu, sdun, age, ratio,
    then vn, ve, vu and their six sigmas."""
    _, smoothed, _, _ = runs
    t, lla, vel = _bag_solution(smoothed)
    lines = (smoothed / "export" / "smoothed.pos").read_text().splitlines()
    header = [ln for ln in lines if ln.startswith("%")]
    assert any("GPST" in ln and "latitude(deg)" in ln for ln in header)
    rows = [ln for ln in lines if not ln.startswith("%")]
    pattern = re.compile(r"^(\d{4})/(\d\d)/(\d\d) (\d\d):(\d\d):(\d\d\.\d{3})((?:\s+\S+){22})$")
    times, values = [], []
    for ln in rows:
        m = pattern.match(ln)
        assert m, ln
        y, mo, d, h, mi = (int(x) for x in m.groups()[:5])
        gpst = dt.datetime(y, mo, d, h, mi) + dt.timedelta(seconds=float(m.group(6)))
        times.append((gpst - dt.datetime(1970, 1, 1)).total_seconds() - LEAP_S)
        values.append([float(x) for x in m.group(7).split()])
    values = np.array(values)
    assert np.max(np.abs(np.array(times) - t)) < 1e-3
    _close(values[:, :3], lla)
    assert set(values[:, 3]) <= {0.0, 5.0} and 5.0 in set(values[:, 3])
    assert np.all(values[:, 5:8] > 0)  # sdn, sde, sdu
    assert np.max(np.abs(values[:, 13:16] - vel[:, [1, 0, 2]])) < 1e-4  # vn, ve, vu


def test_csv_is_documented_and_matches_the_bag(runs):
    _, smoothed, _, _ = runs
    t, lla, vel = _bag_solution(smoothed, "/point/state")
    with open(smoothed / "export" / "smoothed_point.csv") as f:
        lines = f.read().splitlines()
    comments = [ln for ln in lines if ln.startswith("#")]
    rows = list(csv.DictReader(ln for ln in lines if not ln.startswith("#")))
    assert len(rows) == len(t)
    assert all(any(ln.startswith(f"# {name}:") for ln in comments) for name in rows[0])
    got = np.array([[float(r["lat_deg"]), float(r["lon_deg"]), float(r["height_m"])]
                    for r in rows])
    _close(got, lla)
    assert np.max(np.abs(np.array([float(r["time_s"]) for r in rows]) - t)) < 1e-6
    tow = np.array([float(r["gps_tow_s"]) for r in rows])
    assert np.allclose(np.diff(tow), np.diff(t), atol=1e-6)
    assert rows[0]["sigma_e_m"] == ""  # the point's solution has no covariance


def test_trial_export_of_an_offline_replay(runs, capsys):
    _, _, offline, _ = runs
    assert main(["export", str(offline), "--formats", "kml"]) == 0
    assert capsys.readouterr().out.strip().endswith("solution.kml")
    assert json.loads((offline / "replay.json").read_text())["mode"] == "offline"
    assert [p.name for p in export_run(offline, ["csv"])] == ["solution.csv"]


@pytest.mark.parametrize("args, message", [
    (["--point", "1,2"], "--point takes X,Y,Z"),
    (["--export", "csv,shp"], "unknown export format shp"),
])
def test_bad_smooth_arguments_are_one_line_errors(runs, tmp_path, capsys, args, message):
    bag = runs[0]
    status = main(["smooth", str(bag), "--config", str(PROFILE), "--out",
                   str(tmp_path / "o")] + args)
    err = capsys.readouterr().err
    assert status == 2 and message in err and len(err.strip().splitlines()) == 1
