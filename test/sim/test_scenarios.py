"""Named scenarios (ins_gnss_ros.sim.scenarios): seed 004 Lab 1 car and Lab 2 sea trials."""
import numpy as np
import pytest

from ins_gnss_ros.sim import scenarios


@pytest.fixture(scope="module")
def car():
    return scenarios.car(duration=400.0, seed=2, rate=100.0)


@pytest.fixture(scope="module")
def sea():
    return scenarios.sea(duration=300.0, seed=2, rate=100.0)


def _centripetal(traj):
    """|v × a| / |v| in the horizontal plane, from finite differences of the truth velocity."""
    v = traj.v_enu[:, :2]
    a = np.gradient(v, traj.dt, axis=0)
    speed = np.linalg.norm(v, axis=1)
    cross = np.abs(v[:, 0] * a[:, 1] - v[:, 1] * a[:, 0])
    return np.where(speed > 1.0, cross / np.maximum(speed, 1e-9), 0.0)


def test_car_manoeuvres(car):
    traj = car.trajectory
    assert traj.t[-1] == pytest.approx(400.0)
    np.testing.assert_allclose([traj.lat[0], traj.lon[0]], np.deg2rad([59.9, 30.3]))
    a_c = _centripetal(traj)
    # Circles and figure-eights at the handling limit, as commanded.
    assert a_c.max() == pytest.approx(scenarios.CAR_TEST_LATERAL_ACCEL, rel=0.02)
    assert car.max_lateral_accel == pytest.approx(scenarios.CAR_TEST_LATERAL_ACCEL)
    yaw_rate = np.gradient(traj.rpy[:, 2], traj.dt)
    assert yaw_rate.max() > 0.5 and yaw_rate.min() < -0.5  # hard turns both ways
    speed = np.linalg.norm(traj.v_enu, axis=1)
    assert np.all(speed[traj.t < 30.0] == 0.0)  # alignment standstill
    assert speed.max() < 15.0
    moving = speed > 0.0
    assert np.count_nonzero(np.diff(moving.astype(int)) == -1) >= 1  # stops after moving


def test_car_shading_schedule(car):
    sh = car.shading
    assert [w.max_satellites for w in sh[:4]] == [6, 4, 3, 2]
    assert all(0.0 <= w.t_start < w.t_end <= 400.0 for w in sh)
    assert all(a.t_end <= b.t_start for a, b in zip(sh, sh[1:]))


def test_sea_trial(sea):
    traj = sea.trajectory
    np.testing.assert_allclose([traj.lat[0], traj.lon[0]], np.deg2rad([60.8, 31.5]))
    speed = np.linalg.norm(traj.v_enu[:, :2], axis=1)
    assert 6.0 <= speed.min() and speed.max() <= 10.0
    roll, pitch = np.rad2deg(np.abs(traj.rpy[:, 0])), np.rad2deg(np.abs(traj.rpy[:, 1]))
    assert 3.0 < roll.max() < 12.0
    assert 1.0 < pitch.max() < 4.0
    heave = traj.h - traj.h.mean()
    assert 0.4 < np.abs(heave).max() < 2.0
    assert 0.0 < np.linalg.norm(sea.water_current_enu) <= 0.3
    assert sea.shading == []


def test_robot_runs_slowly_and_turns_square():
    traj = scenarios.robot(duration=200.0, seed=2, rate=50.0).trajectory
    speed = np.linalg.norm(traj.v_enu[:, :2], axis=1)
    assert np.all(speed[traj.t < 30.0] == 0.0)  # the standstill
    moving = traj.t > 40.0
    assert 0.4 < speed[moving].min() and speed.max() < 1.6
    # 90 deg turns: the heading, once straight between them, on a square grid
    yaw = np.unwrap(np.arctan2(traj.v_enu[moving, 1], traj.v_enu[moving, 0]))
    turned = np.degrees(yaw - yaw[0])
    straight = np.abs(np.gradient(yaw, traj.t[moving])) < 1e-3
    assert np.allclose(turned[straight] / 90.0, np.round(turned[straight] / 90.0), atol=0.02)
    assert np.ptp(np.round(turned[straight] / 90.0)) >= 1


def test_seed_determinism():
    a = scenarios.car(duration=60.0, seed=5, rate=50.0).trajectory
    b = scenarios.car(duration=60.0, seed=5, rate=50.0).trajectory
    c = scenarios.car(duration=60.0, seed=6, rate=50.0).trajectory
    np.testing.assert_array_equal(a.dtheta, b.dtheta)
    np.testing.assert_array_equal(a.lat, b.lat)
    assert not np.allclose(a.q_nb, c.q_nb)
    assert set(scenarios.SCENARIOS) == {"car", "robot", "sea", "aircraft"}
    d = scenarios.aircraft(duration=60.0, seed=5, rate=50.0).trajectory
    np.testing.assert_array_equal(d.lat, scenarios.aircraft(duration=60.0, seed=5,
                                                            rate=50.0).trajectory.lat)
