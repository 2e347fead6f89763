"""The LEN:PERIOD[:FIRST] GNSS outage protocol."""
import numpy as np
import pytest
from conftest import REPO, shared_path

from ins_gnss_ros.trial.outages import (OBSERVATIONS_TOPIC, OutageSpec, SatelliteSpec,
                                        gnss_mask, gnss_windows, highest_satellites, in_outage,
                                        outage_windows, parse_outage_spec, parse_satellite_spec,
                                        reduce_constellation)
from ins_gnss_ros.trial.rtklib import read_pos


def test_parse():
    assert parse_outage_spec("15:45:40") == OutageSpec(15.0, 45.0, 40.0)
    assert parse_outage_spec(" 10:60 ") == OutageSpec(10.0, 60.0, 50.0)
    assert str(parse_outage_spec("15:45:40")) == "15:45:40"


@pytest.mark.parametrize("spec, message", [
    ("15", "LEN:PERIOD"), ("1:2:3:4", "LEN:PERIOD"), ("a:45", "numbers"), ("nan:45", "finite"),
    ("0:45", "LEN must"), ("45:45", "PERIOD must"), ("15:45:-1", "FIRST must"),
])
def test_parse_errors(spec, message):
    with pytest.raises(ValueError, match=message):
        parse_outage_spec(spec)


def test_windows_and_mask():
    windows = outage_windows("10:30:5", 0.0, 100.0)
    # Starts 5, 35, 65; 95 would start within the final 30 s.
    assert np.allclose(windows, [[5, 15], [35, 45], [65, 75]])
    t = np.arange(0.0, 100.0 + 1e-9, 0.25)
    keep = gnss_mask(t, windows)
    assert np.sum(~keep) == 3 * 10 * 4
    assert not keep[t == 5.0][0] and keep[t == 15.0][0] and keep[t == 4.75][0]
    assert in_outage(40.0, windows) and not in_outage(50.0, windows)
    assert in_outage(np.array([[5.0, 15.0]]), windows).tolist() == [[True, False]]


def test_windows_clip_and_empty():
    assert np.allclose(outage_windows("50:60:0", 0.0, 100.0, end_margin=0.0), [[0, 50], [60, 100]])
    assert outage_windows("10:30:80", 0.0, 100.0).shape == (0, 2)
    assert not in_outage(np.arange(3.0), np.empty((0, 2))).any()


def test_car_drive_protocol():
    sol = read_pos(shared_path("data", "car_drive_0708", "gnss_1934_sf.pos"))
    windows = outage_windows("15:45:40", sol.time[0], sol.time[-1])
    # The source's protocol gives 11 outages over the 549 s drive.
    assert len(windows) == 11
    assert windows[0, 0] - sol.time[0] == pytest.approx(40.0)
    assert np.allclose(np.diff(windows[:, 0]), 45.0)
    assert np.allclose(windows[:, 1] - windows[:, 0], 15.0)
    assert windows[-1, 0] <= sol.time[-1] - 30.0
    # 4 Hz epochs: 60 per 15 s window are withheld.
    assert np.sum(~gnss_mask(sol.time, windows)) == 11 * 60


# -- reduced constellations (trial replay --satellites) ---------------------------------------
WALK_BAG = REPO / "bags" / "walk_0827"


@pytest.fixture(scope="module")
def walk_gnss():
    from ins_gnss_ros.trial.inputs import read_inputs

    return [m for m in read_inputs(WALK_BAG) if m.topic.startswith("/gnss/")]


def test_parse_satellite_spec():
    assert parse_satellite_spec("3:20:40:30") == SatelliteSpec(3, OutageSpec(20.0, 40.0, 30.0))
    assert str(parse_satellite_spec(" 0:10:60")) == "0:10:60:50"
    for spec, message in (("x:20:40", "whole number"), ("-1:20:40", ">= 0"),
                          ("3:20", "LEN:PERIOD"), ("3:50:40", "PERIOD must")):
        with pytest.raises(ValueError, match=message):
            parse_satellite_spec(spec)


def test_the_highest_satellites_stay_and_the_receiver_solution_is_withheld(walk_gnss):
    """On the real walk: the kept satellites are the N highest GPS/Galileo ones with an
    ephemeris (elevations from pymap3d at the receiver's fix), every epoch inside a window
    has only them, its fixes and velocities are withheld, everything outside is untouched."""
    import pymap3d

    from ins_gnss_ros.gnss.ephemeris import sat_position
    from ins_gnss_ros.nodes.gnss_messages import kepler_from_msg

    windows = gnss_windows(walk_gnss, "20:40:30")
    kept = highest_satellites(walk_gnss, windows, 3)
    assert len(windows) == len(kept) == 2 and all(len(k) == 3 for k in kept)
    start = windows[0][0]
    epoch = next(m.msg for m in walk_gnss if m.topic == OBSERVATIONS_TOPIC and m.t_ns >= start)
    fix = [m.msg for m in walk_gnss if m.topic == "/gnss/fix" and m.t_ns <= start][-1]
    t_gps = epoch.gps_week * 604800.0 + epoch.time_of_week
    ephemerides = {(m.msg.system, m.msg.prn): m.msg for m in walk_gnss
                   if m.topic == "/gnss/ephemeris" and m.t_ns <= start}
    elevation = {}
    for sat in set(zip(epoch.system, epoch.prn)) & set(ephemerides):
        if sat[0] in (0, 2):  # GPS, Galileo
            xyz = sat_position(kepler_from_msg(ephemerides[sat], t_gps), t_gps)[0]
            elevation[sat] = pymap3d.ecef2aer(*xyz, fix.latitude, fix.longitude, fix.altitude)[1]
    assert kept[0] == sorted(elevation, key=elevation.get, reverse=True)[:3]

    played, withheld = reduce_constellation(walk_gnss, windows, kept)
    inside = [in_outage(m.t_ns, windows) for m in walk_gnss]
    assert withheld == {t: sum(m.topic == t and i for m, i in zip(walk_gnss, inside))
                        for t in ("/gnss/fix", "/gnss/vel")}
    assert all(m.topic not in ("/gnss/fix", "/gnss/vel") for m in played
               if in_outage(m.t_ns, windows))
    for m in played:
        k = np.searchsorted(windows[:, 0], m.t_ns, side="right") - 1
        if m.topic == OBSERVATIONS_TOPIC and in_outage(m.t_ns, windows):
            assert set(zip(m.msg.system, m.msg.prn)) <= set(kept[k])
            assert len(m.msg.pseudorange) == len(m.msg.system) == len(m.msg.cn0)
    untouched = [m for m, i in zip(walk_gnss, inside) if not i]
    assert [m for m in played if not in_outage(m.t_ns, windows)] == untouched
