"""The LEN:PERIOD[:FIRST] GNSS outage protocol."""
import numpy as np
import pytest
from conftest import shared_path

from ins_gnss_ros.trial.outages import (OutageSpec, gnss_mask, in_outage, outage_windows,
                                        parse_outage_spec)
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
