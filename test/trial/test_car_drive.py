"""The car drive reader against the recorded data: counts, timing and the IMU installation.

The mounting rotation and the time offset are checked against physics seen by the RTK solution:
gravity along body up while parked, the road grade and the speed change in the forward axis, the
centripetal acceleration (and nothing of the speed change) in the lateral axis, and the body yaw
rate against the rate of the RTK course.
"""
import numpy as np
import pytest
from conftest import shared_path
from scipy.signal import savgol_filter

from ins_gnss_ros.nav.earth import normal_gravity
from ins_gnss_ros.trial.car_drive import load_car_drive, read_imu_csv

RTK_DT = 0.25  # s, the .pos rate


@pytest.fixture(scope="module")
def car():
    return load_car_drive(shared_path("data", "car_drive_0708"))


@pytest.fixture(scope="module")
def motion(car):
    """RTK-derived motion at the fixed epochs and the IMU averaged over each 0.25 s epoch."""
    truth = car.truth
    speed = np.hypot(truth.vel_enu[:, 0], truth.vel_enu[:, 1])
    # Course as ENU yaw (counter-clockwise), unwrapped, so its rate compares with gyro z (FLU).
    yaw = np.unwrap(np.arctan2(truth.vel_enu[:, 1], truth.vel_enu[:, 0]))
    smooth = dict(window_length=9, polyorder=2, deriv=1, delta=RTK_DT)
    kernel = np.ones(25) / 25  # 0.25 s of 100 Hz samples
    imu = {name: np.interp(truth.time, car.imu_time_gnss, np.convolve(values, kernel, "same"))
           for name, values in (("fx", car.accel_flu[:, 0]), ("fy", car.accel_flu[:, 1]),
                                ("wz", car.gyro_flu[:, 2]))}
    inside = (truth.time > car.imu_time_gnss[0] + 1) & (truth.time < car.imu_time_gnss[-1] - 1)
    return dict(time=truth.time, speed=speed, dv=savgol_filter(speed, **smooth),
                yaw_rate=savgol_filter(yaw, **smooth),
                grade=truth.vel_enu[:, 2] / np.maximum(speed, 1e-3),
                moving=inside & (speed > 3.0), **imu)


def test_counts_and_timing(car):
    # README: 54,860 rows at 100 Hz (this copy has no header line and a complete last line).
    assert len(car.imu_time) == 54860
    assert car.accel_flu.shape == car.gyro_flu.shape == (54860, 3)
    assert car.imu_time[-1] - car.imu_time[0] == pytest.approx(548.731, abs=1e-6)
    assert np.median(np.diff(car.imu_time)) == pytest.approx(0.01, abs=1e-4)
    assert np.all(np.diff(car.imu_time) > 0)
    assert car.imu_time_offset == -0.125
    assert np.allclose(car.imu_time_gnss - car.imu_time, -0.125)
    # The GNSS solution starts 3.2 s before the IMU log and ends 3.0 s before it.
    overlap = min(car.gnss.time[-1], car.imu_time_gnss[-1]) - max(car.gnss.time[0],
                                                                   car.imu_time_gnss[0])
    assert overlap == pytest.approx(545.77, abs=0.01)
    assert len(car.truth) == 2189 and len(car.truth_course) == 2189


def test_lever_arms(car):
    assert np.allclose(car.imu_offset_flu, [0.0, 0.0, 0.65])
    assert np.allclose(car.antenna_offset_flu, [0.0, 0.05, 0.65])
    assert np.allclose(car.antenna_lever_arm_flu, [0.0, 0.05, 0.0])


def test_raw_ubx_missing_but_tag_present():
    folder = shared_path("data", "car_drive_0708")
    assert (folder / "gnss_1934.ubx.tag").exists() and not (folder / "gnss_1934.ubx").exists()


def test_static_start_gravity(car):
    truth = car.truth
    parked = truth.time[np.hypot(truth.vel_enu[:, 0], truth.vel_enu[:, 1]) > 0.2][0]
    assert parked - truth.time[0] > 30.0
    static = car.imu_time_gnss < parked - 2.0
    f = car.accel_flu[static].mean(axis=0)
    g = normal_gravity(truth.lat[0], truth.height[0])
    # Specific force at rest points up (+z in FLU) with magnitude g (cheap IMU: 2 % scale).
    assert np.linalg.norm(f) == pytest.approx(g, rel=0.02)
    roll, pitch = np.arctan2(f[1], f[2]), np.arctan2(-f[0], np.hypot(f[1], f[2]))
    assert abs(np.degrees(roll)) < 3.0 and abs(np.degrees(pitch)) < 3.0
    assert np.all(np.abs(np.degrees(car.gyro_flu[static].mean(axis=0))) < 0.5)


def test_forward_and_lateral_axes(motion):
    m = motion["moving"]
    g = 9.80
    basis = np.column_stack([motion["dv"][m], motion["speed"][m] * motion["yaw_rate"][m],
                             g * motion["grade"][m], np.ones(m.sum())])
    fx = np.linalg.lstsq(basis, motion["fx"][m], rcond=None)[0]
    fy = np.linalg.lstsq(basis, motion["fy"][m], rcond=None)[0]
    # Forward: f_x = dv/dt + g sin(grade); a wrong pitch or yaw mounting sign breaks this.
    assert fx[0] == pytest.approx(1.0, abs=0.15) and fx[2] == pytest.approx(1.0, abs=0.15)
    assert abs(fx[1]) < 0.1
    # Left: f_y = v * yaw rate (centripetal, positive turning left); no forward leakage
    # (a 5.35 deg yaw mounting error of the wrong sign would leak 0.19 of dv/dt).
    assert fy[1] == pytest.approx(1.0, abs=0.15) and abs(fy[0]) < 0.1


def test_straight_driving_lateral_mean(motion):
    straight = motion["moving"] & (np.abs(motion["yaw_rate"]) < 0.02)
    assert straight.sum() > 100
    assert abs(np.mean(motion["fy"][straight])) < 0.15


def test_yaw_rate_matches_course_rate(car, motion):
    m = motion["moving"]
    assert np.corrcoef(motion["wz"][m], motion["yaw_rate"][m])[0, 1] > 0.9
    # The course over ground turns clockwise (azimuth) when the body turns left (+z in FLU).
    course_rate = savgol_filter(np.unwrap(car.truth_course[m]), 9, 2, deriv=1, delta=RTK_DT)
    assert np.corrcoef(motion["wz"][m], -course_rate)[0, 1] > 0.8


def test_csv_header_and_incomplete_last_line(tmp_path):
    path = tmp_path / "imu.csv"
    path.write_text("ax,ay,az,gx,gy,gz,t\n0.1,0,1,0,0,0.5,100\n0.1,0,1,0,0,0.5,110\n0.1,0,1")
    values, tick = read_imu_csv(path)
    assert values.shape == (2, 6) and list(tick) == [100.0, 110.0]
    path.write_text("0.1,0,1,0,0,0.5,100\n0.1,0,x,0,0,0.5,110\n0.1,0,1,0,0,0.5,120\n")
    with pytest.raises(ValueError, match=":2:"):
        read_imu_csv(path)
