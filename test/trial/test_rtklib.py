"""RTKLIB .pos and .tag readers against the recorded files and hand-made files."""
import struct
from datetime import datetime

import numpy as np
import pytest
from conftest import shared_path

from ins_gnss_ros.trial.rtklib import (Q_FIX, Q_FLOAT, gps_seconds_from_calendar, read_pos,
                                       read_time_tag)

HEADER = ("%  GPST                  latitude(deg) longitude(deg)  height(m)   Q  ns"
          "   sdn(m)   sde(m)   sdu(m)  sdne(m)  sdeu(m)  sdun(m) age(s)  ratio")
LINE = ("2025/07/08 19:34:18.499   40.096626800 -105.147448300  1601.4740   1  21"
        "   0.3000   0.4000   0.5000  -0.2000   0.1000   0.0000   0.00    7.5")


def _gps(*calendar):
    """GPS seconds of a GPST calendar instant by datetime arithmetic from 1980-01-06."""
    return (datetime(*calendar) - datetime(1980, 1, 6)).total_seconds()


def test_car_drive_solution():
    sol = read_pos(shared_path("data", "car_drive_0708", "gnss_1934_sf.pos"))
    # README: 2,197 epochs at 4 Hz, 2,189 RTK-fixed, the rest float.
    assert len(sol) == 2197
    assert np.sum(sol.quality == Q_FIX) == 2189
    assert np.sum(sol.quality == Q_FLOAT) == 8
    assert sol.time[0] == pytest.approx(_gps(2025, 7, 8, 19, 34, 18, 499000), abs=1e-6)
    # GPS week 2374 began on Sunday 2025-07-06; the first epoch is Tuesday 19:34:18.499.
    assert sol.time[0] // 604800 == 2374
    assert sol.time[0] % 604800 == pytest.approx(2 * 86400 + 19 * 3600 + 34 * 60 + 18.499, abs=1e-6)
    assert np.allclose(np.diff(sol.time), 0.25, atol=1e-6)
    assert np.degrees(sol.lat[0]) == pytest.approx(40.0966268, abs=1e-10)
    assert np.degrees(sol.lon[0]) == pytest.approx(-105.1474483, abs=1e-10)
    assert sol.height[0] == pytest.approx(1601.474)
    assert sol.num_sats[0] == 21
    # First line: vn 0.010, ve -0.002, vu 0.009 -> ENU order.
    assert np.allclose(sol.vel_enu[0], [-0.002, 0.010, 0.009])
    assert np.allclose(np.sqrt(np.diagonal(sol.pos_cov_enu[0])), [0.0098995, 0.0098995, 0.01])
    assert np.allclose(np.sqrt(np.diagonal(sol.vel_cov_enu[0])), 0.0586899)


def test_walk_solution():
    sol = read_pos(shared_path("data", "walk_0827", "gnss_1730_sf.pos"))
    assert len(sol) == 536
    assert sol.time[-1] - sol.time[0] == pytest.approx(133.75, abs=1e-6)
    assert set(np.unique(sol.quality)) == {Q_FIX, Q_FLOAT}
    assert sol.time[0] == pytest.approx(_gps(2025, 8, 28, 17, 30, 39, 749000), abs=1e-6)


def test_header_comments_optional_columns_and_covariance(tmp_path):
    path = tmp_path / "a.pos"
    path.write_text("% program   : RTKLIB ver.demo5\n"
                    "% obs start : 2025/07/08 19:34:18.5 GPST (week2374 243258.5s)\n"
                    "%\n" + HEADER + "\n" + LINE + "\n\n")
    sol = read_pos(path)
    assert len(sol) == 1 and sol.vel_enu is None and sol.vel_cov_enu is None
    assert sol.ratio[0] == 7.5 and sol.age[0] == 0.0
    cov = sol.pos_cov_enu[0]
    # RTKLIB writes off-diagonals as sign(c) sqrt|c|: sdne = -0.2 -> c_en = -0.04.
    expected = np.array([[0.16, -0.04, 0.01], [-0.04, 0.09, 0.0], [0.01, 0.0, 0.25]])
    assert np.allclose(cov, expected)


def test_week_tow_and_utc_time(tmp_path):
    week = tmp_path / "week.pos"
    week.write_text(HEADER + "\n" + LINE.replace("2025/07/08 19:34:18.499", "2374 243258.499")
                    + "\n")
    assert read_pos(week).time[0] == pytest.approx(_gps(2025, 7, 8, 19, 34, 18, 499000), abs=1e-6)
    utc = tmp_path / "utc.pos"
    utc.write_text(HEADER.replace("GPST", "UTC ") + "\n"
                   + LINE.replace("19:34:18.499", "19:34:00.499") + "\n")
    # GPST - UTC = 18 s since 2017-01-01.
    assert read_pos(utc).time[0] == pytest.approx(_gps(2025, 7, 8, 19, 34, 18, 499000), abs=1e-6)
    assert gps_seconds_from_calendar("1980/01/06 00:00:00") == 0.0


@pytest.mark.parametrize("bad, where", [
    (LINE.replace(" 1  21", " x  21"), ":2:"),
    (LINE.rsplit(" ", 1)[0], ":2:"),
    (LINE.replace("19:34:18.499", "19:74:18.499"), ":2:"),
])
def test_malformed_line_names_the_line(tmp_path, bad, where):
    path = tmp_path / "bad.pos"
    path.write_text(HEADER + "\n" + bad + "\n" + LINE + "\n")
    with pytest.raises(ValueError, match=where):
        read_pos(path)


def test_unsupported_headers(tmp_path):
    path = tmp_path / "x.pos"
    path.write_text(LINE + "\n")
    with pytest.raises(ValueError, match="before"):
        read_pos(path)
    path.write_text("% only a comment\n")
    with pytest.raises(ValueError, match="no"):
        read_pos(path)
    path.write_text("%  GPST      x-ecef(m)      y-ecef(m)      z-ecef(m)   Q  ns\n")
    with pytest.raises(ValueError, match="latitude"):
        read_pos(path)
    path.write_text(HEADER.replace("GPST", "JST ") + "\n")
    with pytest.raises(ValueError, match="JST"):
        read_pos(path)


def test_car_drive_time_tag():
    tag = read_time_tag(shared_path("data", "car_drive_0708", "imu_1934.csv.tag"))
    assert tag.header == "TIMETAG RTKLIB demo5"
    # time_time 1752003261 = 2025-07-08 19:34:21 counted like Unix time on the GPS scale.
    assert tag.start_time == pytest.approx(_gps(2025, 7, 8, 19, 34, 21, 854000), abs=1e-6)
    assert tag.end_time - tag.start_time == pytest.approx(548.731)
    assert np.all(np.diff(tag.ticks_ms.astype(np.int64)) >= 0)
    assert np.all(np.diff(tag.offsets.astype(np.int64)) > 0)


def test_synthetic_time_tag(tmp_path):
    path = tmp_path / "s.tag"
    body = b"TIMETAG RTKLIB EX".ljust(60, b"\0") + struct.pack("<IId", 7, 315964800 + 100, 0.25)
    path.write_bytes(body + struct.pack("<4I", 10, 64, 2010, 128))
    tag = read_time_tag(path)
    assert tag.header == "TIMETAG RTKLIB EX" and tag.tick_f == 7
    assert tag.start_time == 100.25 and tag.end_time == pytest.approx(102.26)
    assert list(tag.offsets) == [64, 128]
    path.write_bytes(body + b"\1\2\3")
    with pytest.raises(ValueError, match="8-byte"):
        read_time_tag(path)
    path.write_bytes(body[:40])
    with pytest.raises(ValueError, match="shorter"):
        read_time_tag(path)
