"""The compass front end without ROS: the WMM field seen by a tilted vehicle gives its true
azimuth; every withheld sample and ignored input is counted with why; the position follows the
INS until a fix and the fix after it."""

from __future__ import annotations

from collections import Counter

import numpy as np
import pytest

from ins_gnss_ros.magnetic.compass_front_end import PARAMS, CompassFrontEnd
from ins_gnss_ros.magnetic.wmm import field_elements
from ins_gnss_ros.nav.conventions import azimuth_from_yaw, wrap_pi
from ins_gnss_ros.nav.rotations import quat_conj, quat_from_euler, quat_rotate
from ins_gnss_ros.params import ParameterError, resolve

DEG = np.pi / 180
YEAR = 2026.5
LAT, LON, H = 59.9 * DEG, 30.3 * DEG, 22.0


def front_end(**overrides):
    events = Counter()
    p = resolve(PARAMS, {"decimal_year": YEAR, **overrides})
    return CompassFrontEnd(p, lambda text, log=True: events.update([text])), events


def body_field(roll, pitch, yaw, lat=LAT, lon=LON, h=H):
    """The WMM field in FLU body axes of a vehicle at that attitude, T."""
    field_n = field_elements(lat, lon, h, YEAR).enu
    return quat_rotate(quat_conj(quat_from_euler(roll, pitch, yaw)), field_n)


@pytest.mark.parametrize("yaw_deg", [-150.0, 0.0, 35.0, 100.0])
def test_tilted_vehicle_reads_its_true_azimuth(yaw_deg):
    compass, events = front_end()
    roll, pitch, yaw = 8 * DEG, -5 * DEG, yaw_deg * DEG
    compass.ins_state(10.0, quat_from_euler(roll, pitch, yaw), (LAT, LON, H), False, 0)
    reading = compass.mag(10.05, body_field(roll, pitch, yaw))
    assert reading is not None and not events
    assert abs(wrap_pi(reading.true_azimuth - azimuth_from_yaw(yaw))) < 1e-6
    assert abs(wrap_pi(reading.true_azimuth - reading.magnetic_azimuth -
                       reading.declination)) < 1e-12
    # The tilt sigma of the filter, larger than the parameters' floor, widens the variance.
    compass.tilt_std(1.0 * DEG, 0.5 * DEG)
    wider = compass.mag(10.1, body_field(roll, pitch, yaw))
    assert wider.variance > 10 * reading.variance


def test_withheld_samples_and_ignored_inputs_are_counted():
    compass, events = front_end()
    q, m = quat_from_euler(0.0, 0.0, 0.3), body_field(0.0, 0.0, 0.3)
    assert compass.mag(1.0, m) is None                       # no attitude yet
    compass.ins_state(1.0, q, (LAT, LON, H), True, 0)          # a strapdown no filter corrected
    assert compass.mag(1.1, m) is None
    compass.ins_state(1.2, q, (LAT, LON, H), False, 0)
    assert compass.mag(1.2, m) is not None
    assert compass.mag(1.2, m) is None                       # same stamp again
    assert compass.mag(1.3, [np.nan, 0.0, 0.0]) is None
    assert compass.mag(2.0, m) is None                       # attitude 0.8 s old
    compass.ins_state(2.0, [1.0, 0.0, 0.0, 0.5], (LAT, LON, H), False, 0)
    compass.fix(np.nan, 30.0, 0.0, True)
    compass.fix(59.0, 30.0, 0.0, False)
    assert events == {
        "no roll/pitch within max_attitude_age_s: heading withheld": 2,
        "ins/state not corrected by a filter yet (roll/pitch unknown): heading withheld": 1,
        "magnetometer sample rejected: stamp not after the previous one": 1,
        "magnetometer sample rejected: non_finite": 1,
        "invalid ins/state ignored": 1,
        "gnss/fix without a valid position ignored": 2}
    compass.fix(59.0, 30.0, np.nan, True)  # a 2-D fix: the WMM at sea level
    assert compass.position == pytest.approx((np.radians(59.0), np.radians(30.0), 0.0))


def test_a_filtered_ins_waits_for_the_filters_tilt_sigma():
    """A strapdown our filter corrects (corrections > 0) is as level as that filter knows:
    nothing before its tilt sigma comes (nav/status), then a variance with it."""
    compass, events = front_end()
    q, m = quat_from_euler(0.0, 0.0, 0.3), body_field(0.0, 0.0, 0.3)
    compass.ins_state(1.0, q, (LAT, LON, H), True, 3)
    assert compass.mag(1.0, m) is None
    assert events == {"no roll/pitch error from the filter yet (nav/status): heading "
                      "withheld": 1}
    compass.tilt_std(1.0 * DEG, 1.0 * DEG)
    reading = compass.mag(1.02, m)
    own, _ = front_end()                               # an INS of its own: the parameters'
    own.ins_state(1.0, q, (LAT, LON, H), False, 0)
    assert reading.variance > 10 * own.mag(1.02, m).variance


def test_position_from_the_ins_until_a_fix():
    compass, _ = front_end()
    assert compass.position == pytest.approx((LAT, LON, 0.0))  # the parameters
    q = quat_from_euler(0.0, 0.0, 0.0)
    compass.ins_state(1.0, q, (0.5, 0.2, 100.0), False, 0)
    assert compass.position == (0.5, 0.2, 100.0)
    compass.fix(10.0, 20.0, 5.0, True)
    compass.ins_state(2.0, q, (0.5, 0.2, 100.0), False, 0)
    assert compass.position == pytest.approx((10 * DEG, 20 * DEG, 5.0))


def test_levelled_from_the_specific_force_where_no_ins_runs():
    compass, _ = front_end(attitude_source="imu_data", level_time_constant_s=0.0)
    roll, pitch, yaw = 4 * DEG, 3 * DEG, 1.0
    q = quat_from_euler(roll, pitch, yaw)
    compass.ins_state(1.0, q, (LAT, LON, H), True, 0)  # position only: no attitude withheld
    compass.imu(1.0, quat_rotate(quat_conj(q), [0.0, 0.0, 9.81]))
    reading = compass.mag(1.01, body_field(roll, pitch, yaw))
    assert abs(wrap_pi(reading.true_azimuth - azimuth_from_yaw(yaw))) < 1e-6


def test_a_calibration_given_twice_is_refused(tmp_path):
    path = tmp_path / "cal.yaml"
    path.write_text("mag_calibration:\n  hard_iron: [0, 0, 0]\n  soft_iron: [[1, 0, 0], "
                    "[0, 1, 0], [0, 0, 1]]\n")
    with pytest.raises(ParameterError, match="either as a file or as calibration"):
        front_end(calibration_file=str(path), **{"calibration.hard_iron": [1e-6, 0.0, 0.0]})
