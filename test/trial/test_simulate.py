"""``trial simulate``: seeded, and the sensors agree with the truth by independent computations.

Independent truth: pymap3d for the antenna position (ENU offset of the lever arm about the true
IMU position), the WMM via pygeomag directly for the field magnitude, Somigliana normal gravity
for the static specific force, and the closed-form yaw of a quaternion for the heading.
"""
import math

import numpy as np
import pymap3d
import pytest
from pygeomag import GeoMag

from ins_gnss_ros import io as bagio
from ins_gnss_ros.io import messages_equal
from ins_gnss_ros.trial.simulate import SIM_EPOCH_NS, SimOptions, simulate

DURATION = 8.0


@pytest.fixture(scope="module")
def car(tmp_path_factory):
    path = simulate("car", DURATION, 7, tmp_path_factory.mktemp("sim") / "car")
    return bagio.read_bag(path)


@pytest.fixture(scope="module")
def sea(tmp_path_factory):
    path = simulate("sea", DURATION, 3, tmp_path_factory.mktemp("sim") / "sea",
                    SimOptions(imu_topic="delta"))
    return bagio.read_bag(path)


def _by_topic(messages, topic):
    return [m.msg for m in messages if m.topic == topic]


def _quat(msg):
    o = msg.orientation
    return np.array([o.w, o.x, o.y, o.z])


def test_same_seed_identical_bag_other_seed_differs(tmp_path, car):
    again = bagio.read_bag(simulate("car", DURATION, 7, tmp_path / "again"))
    assert len(again) == len(car)
    assert all(a.topic == b.topic and a.t_ns == b.t_ns and messages_equal(a.msg, b.msg)
               for a, b in zip(car, again))
    other = bagio.read_bag(simulate("car", DURATION, 8, tmp_path / "other"))
    assert not messages_equal(_by_topic(other, "/gnss/fix")[3], _by_topic(car, "/gnss/fix")[3])


def test_topics_rates_and_epoch(car, sea):
    topics = {m.topic for m in car}
    assert topics == {"/imu/data_raw", "/imu/mag_raw", "/gnss/fix", "/gnss/vel",
                      "/truth/state", "/truth/heading"}
    assert {"/imu/delta", "/log/speed"} <= {m.topic for m in sea}
    imu_t = np.array([m.t_ns for m in car if m.topic == "/imu/data_raw"])
    assert np.all(np.diff(imu_t) == 5_000_000)  # 200 Hz exactly, in ns
    fix_t = np.array([m.t_ns for m in car if m.topic == "/gnss/fix"])
    assert fix_t[0] == SIM_EPOCH_NS and np.all(np.diff(fix_t) == 200_000_000)
    assert len(_by_topic(car, "/truth/state")) == int(DURATION * 20) + 1


def test_gnss_fix_is_truth_at_the_antenna_plus_noise(car):
    lever = np.array(SimOptions().antenna_lever_arm)
    truth = {bagio.msg_stamp_ns(m): m for m in _by_topic(car, "/truth/state")}
    errors = []
    for fix in _by_topic(car, "/gnss/fix"):
        tr = truth[bagio.msg_stamp_ns(fix)]
        # Lever arm to ENU with scipy's rotation (scalar-last), then pymap3d to geodetic.
        from scipy.spatial.transform import Rotation
        q = _quat(tr)
        d_enu = Rotation.from_quat([q[1], q[2], q[3], q[0]]).apply(lever)
        lat, lon, h = pymap3d.enu2geodetic(*d_enu, tr.latitude, tr.longitude, tr.altitude,
                                           deg=False)
        errors.append(pymap3d.geodetic2enu(fix.latitude, fix.longitude, fix.altitude,
                                           math.degrees(lat), math.degrees(lon), h))
    errors = np.array(errors)
    n = len(errors)
    sigma = np.array([0.5, 0.5, 1.0])
    assert np.all(np.abs(errors.mean(axis=0)) < 4 * sigma / math.sqrt(n))
    assert np.all(errors.std(axis=0) < 1.6 * sigma) and np.all(errors.std(axis=0) > 0.5 * sigma)


def test_static_specific_force_is_normal_gravity(car):
    """The car stands still for its first 30 s: |f| = normal gravity (Somigliana) within the
    MEMS accelerometer bias (5 mg 1-sigma) and the averaged noise."""
    lat = math.radians(59.9)
    g = 9.7803253359 * (1 + 0.00193185265241 * math.sin(lat) ** 2) / math.sqrt(
        1 - 0.00669437999013 * math.sin(lat) ** 2) - 3.086e-6 * 22.0
    f = np.array([[m.linear_acceleration.x, m.linear_acceleration.y, m.linear_acceleration.z]
                  for m in _by_topic(car, "/imu/data_raw")])
    assert np.linalg.norm(f.mean(axis=0)) == pytest.approx(g, abs=0.2)
    assert f.mean(axis=0)[2] > 9.5  # up in FLU when level


def test_magnetometer_magnitude_is_the_wmm_field(car):
    first = _by_topic(car, "/truth/state")[0]
    model = GeoMag(coefficients_file="wmm/WMM_2025.COF")
    expected = model.calculate(glat=math.degrees(first.latitude),
                               glon=math.degrees(first.longitude), alt=first.altitude / 1000,
                               time=2026.0).f * 1e-9
    b = np.array([[m.magnetic_field.x, m.magnetic_field.y, m.magnetic_field.z]
                  for m in _by_topic(car, "/imu/mag_raw")])
    assert np.linalg.norm(b, axis=1).mean() == pytest.approx(expected, rel=2e-3)


def test_truth_heading_is_the_azimuth_of_the_truth_attitude(sea):
    states = _by_topic(sea, "/truth/state")
    headings = _by_topic(sea, "/truth/heading")
    for state, heading in zip(states[::17], headings[::17]):
        w, x, y, z = _quat(state)
        yaw = math.atan2(2 * (w * z + x * y), 1 - 2 * (y * y + z * z))
        assert heading.azimuth == pytest.approx((math.pi / 2 - yaw) % (2 * math.pi), abs=1e-9)
        assert 0.0 <= heading.azimuth < 2 * math.pi


def test_speed_log_reads_the_ship_speed(sea):
    speed = np.array([m.twist.twist.linear.x for m in _by_topic(sea, "/log/speed")])
    ground = np.array([math.hypot(m.velocity.x, m.velocity.y)
                       for m in _by_topic(sea, "/truth/state")])
    # Through-water speed differs from ground speed by the current (< 0.3 m/s) and wave motion.
    assert abs(speed.mean() - ground.mean()) < 0.6
    assert np.all(np.isnan([m.twist.twist.linear.y for m in _by_topic(sea, "/log/speed")]))


def test_bad_arguments():
    with pytest.raises(ValueError, match="scenario"):
        simulate("plane", 1.0, 0, "/nonexistent/x")
    with pytest.raises(ValueError, match="duration"):
        simulate("car", -1.0, 0, "/nonexistent/x")
    with pytest.raises(ValueError, match="grade"):
        simulate("car", 1.0, 0, "/nonexistent/x", SimOptions(imu_grade="potato"))


def test_the_raw_gnss_of_antennas_honours_fixes_only_and_refuses_the_fix_noise_options(
        tmp_path):
    """With antennas, gnss/fix and gnss/vel are the gnss_simulator node's solution: fixes only
    leave its velocity out (it was written all the same), and the options of the fixes as
    truth plus noise, which that solution does not take, are refused, not ignored."""
    path = simulate("car", 3.0, 1, tmp_path / "raw", SimOptions(antennas=1, gnss_rate=1.0,
                                                               gnss_velocity=False))
    topics = bagio.bag_topics(path)
    assert "/gnss/fix" in topics and "/gnss/observations" in topics
    assert "/gnss/vel" not in topics
    for wrong in ({"gnss_sigma_h": 2.0}, {"gnss_covariance": False},
                  {"gnss_latency": 0.1, "gnss_stamped_on_arrival": True}):
        with pytest.raises(ValueError, match=f"{next(iter(wrong))}.*raw GNSS of antennas"):
            simulate("car", 3.0, 1, tmp_path / "refused", SimOptions(antennas=2, **wrong))


def test_any_sensor_rates_jittered_imu_stamps_and_fix_only_receivers(tmp_path):
    from sensor_msgs.msg import NavSatFix

    from ins_gnss_ros.trial.simulate import trajectory_rate

    options = SimOptions(imu_rate=30.0, gnss_rate=2.5, imu_stamp_jitter=0.003,
                         gnss_velocity=False, gnss_covariance=False)
    assert trajectory_rate(options, "car") == 300.0  # lcm of 30, 2.5, 50 (mag), 20 (truth)
    path = simulate("car", 20.0, 1, tmp_path / "bag", options)
    imu = bagio.read_bag(path, ["/imu/data_raw"])
    t = np.array([bagio.msg_stamp_ns(m.msg) for m in imu]) * 1e-9
    assert len(imu) == 600
    steps = np.diff(t)
    assert steps.min() > 0.0 and 0.027 < steps.min() < 0.0334 and steps.max() < 0.0394
    assert np.std(steps) > 1e-3  # jittered
    # the jitter is in the stamps only: a uniform grid fits them within the jitter
    grid = t[0] + (t[-1] - t[0]) * np.arange(len(t)) / (len(t) - 1)
    assert np.abs(t - grid).max() < 0.0061
    fixes = bagio.read_bag(path, ["/gnss/fix"])
    assert len(fixes) == 51 and "/gnss/vel" not in bagio.bag_topics(path)  # 0 s to 20 s
    assert {m.msg.position_covariance_type for m in fixes} == {NavSatFix.COVARIANCE_TYPE_UNKNOWN}


def test_wheel_odometry_is_added_and_leaves_the_other_sensors_as_they_were(tmp_path, car):
    path = simulate("car", DURATION, 7, tmp_path / "wheels", SimOptions(wheel_odometry=True))
    wheels = bagio.read_bag(path)
    odom = _by_topic(wheels, "/wheel/odom")
    assert len(odom) == DURATION * SimOptions.wheel_rate
    # 50 ms late, in the child frame, a multiple of one encoder count per 20 Hz interval
    first = odom[0].header.stamp
    assert (first.sec * 10 ** 9 + first.nanosec) - SIM_EPOCH_NS == pytest.approx(0.1e9, abs=1)
    assert odom[0].child_frame_id == "base_link"
    counts = np.array([m.twist.twist.linear.x for m in odom]) / (0.02 * 20.0)
    assert np.allclose(counts, np.round(counts), atol=1e-6)
    others = [m for m in wheels if m.topic != "/wheel/odom"]
    assert len(others) == len(car)
    assert all(a.topic == b.topic and messages_equal(a.msg, b.msg) for a, b in zip(others, car))


@pytest.mark.parametrize("on_arrival", [False, True])
def test_gnss_latency_delays_the_log_and_on_arrival_the_stamps_too(tmp_path, on_arrival):
    """A receiver's output latency (0.5-1.5 times the mean per epoch) delays the log times;
    a driver stamping on arrival puts it in the stamps too, which precede the log times by the
    transport."""
    path = simulate("car", 10.0, 1, tmp_path / "bag",
                    SimOptions(gnss_latency=0.1, gnss_stamped_on_arrival=on_arrival))
    for topic in ("/gnss/fix", "/gnss/vel"):
        msgs = bagio.read_bag(path, [topic])
        stamps = np.array([bagio.msg_stamp_ns(m.msg) for m in msgs])
        read = stamps if on_arrival else np.array([m.t_ns for m in msgs])
        late = ((read - SIM_EPOCH_NS) % 200_000_000) * 1e-9  # after the 5 Hz epochs (<= 0.15 s)
        assert late.min() >= 0.05 - 1e-9 and late.max() <= 0.15 + 1e-9 and np.std(late) > 0.01
        if on_arrival:
            transport = np.array([m.t_ns for m in msgs]) - stamps
            assert transport.min() >= 1e5 and transport.max() <= 1e6
        else:
            assert np.all((stamps - SIM_EPOCH_NS) % 200_000_000 == 0)
