"""Truth trajectories and ideal IMU outputs (ins_gnss_ros.sim.trajectory).

Independent truths: analytic kinematics (circle geometry, a vehicle at rest senses gravity and
Earth rate), pymap3d for geodetic geometry, pyins.sim.generate_imu for the sensed rates, and the
project's strapdown mechanisation, which must reproduce the truth from the ideal increments.
"""
import numpy as np
import pymap3d
import pytest
from scipy.integrate import cumulative_trapezoid, quad

from ins_gnss_ros.nav import coning, conventions, earth, strapdown
from ins_gnss_ros.nav.rotations import (quat_angle_between, quat_conj, quat_mul, quat_to_dcm,
                                        quat_to_rotvec)
from ins_gnss_ros.sim import scenarios
from ins_gnss_ros.sim import trajectory as tr

LAT0, LON0, H0 = np.deg2rad(59.9), np.deg2rad(30.3), 20.0


@pytest.fixture(scope="module")
def car():
    return scenarios.car(duration=300.0, seed=3).trajectory


@pytest.fixture(scope="module")
def sea():
    return scenarios.sea(duration=300.0, seed=3).trajectory


def test_smoothstep_shape():
    x = np.linspace(0.0, 1.0, 2001)
    s, ds, si = tr._smoothstep(x)
    assert s[0] == 0.0 and s[-1] == pytest.approx(1.0) and ds[0] == 0.0 and ds[-1] == 0.0
    np.testing.assert_allclose(np.gradient(s, x), ds, atol=1e-5)
    assert si[-1] == pytest.approx(quad(lambda u: tr._smoothstep(u)[0], 0.0, 1.0)[0])
    assert ds.max() == pytest.approx(tr.SMOOTHSTEP_PEAK_RATE)


def test_smooth_steps_integral_and_rate():
    p = tr.SmoothSteps(1.0)
    p.add(1.0, 2.0, 3.0)
    p.add(2.5, 0.5, -1.5)
    t = np.linspace(0.0, 6.0, 60001)
    integral, value, rate = p.evaluate(t)
    np.testing.assert_allclose(np.gradient(value, t), rate, atol=1e-5)
    np.testing.assert_allclose(cumulative_trapezoid(value, t, initial=0.0), integral, atol=1e-7)
    assert value[-1] == pytest.approx(p.final_value()) == pytest.approx(2.5)


def _enu(traj, k0=0):
    e, n, u = pymap3d.geodetic2enu(traj.lat, traj.lon, traj.h, traj.lat[k0], traj.lon[k0],
                                   traj.h[k0], deg=False)
    return np.stack([e, n, u], -1)


def test_turn_heading_and_circle_radius():
    speed, a_lat = 9.0, 6.0
    route = tr.Route(yaw0=0.4, speed0=speed).hold(2.0).turn(np.pi / 2, radius=20.0).hold(2.0)
    t_circle = route.t + route.ramp
    route.circle(lateral_accel=a_lat, direction=-1).hold(2.0)
    t_end_hold = route.t - 2.0 - route.ramp
    traj = tr.generate(tr.CarMotion(route), LAT0, LON0, H0, route.t, rate=100.0)
    # Heading after the 90° left turn, and back to it after the full right circle.
    k = np.searchsorted(traj.t, t_circle - route.ramp - 1.0)  # inside the 2 s hold
    assert traj.rpy[k, 2] == pytest.approx(0.4 + np.pi / 2, abs=1e-9)
    assert traj.rpy[-1, 2] == pytest.approx(0.4 + np.pi / 2 - 2 * np.pi, abs=1e-9)
    # Constant-rate part of the circle: points lie on a circle of radius v²/a (pymap3d ENU).
    sel = (traj.t > t_circle) & (traj.t < t_end_hold)
    p = _enu(traj)[sel, :2]
    # Algebraic circle fit: x² + y² = 2 a x + 2 b y + c.
    A = np.c_[2 * p, np.ones(len(p))]
    (a, b, c), *_ = np.linalg.lstsq(A, np.sum(p * p, 1), rcond=None)
    radius = np.sqrt(c + a * a + b * b)
    assert radius == pytest.approx(speed ** 2 / a_lat, abs=2e-3)
    assert route.max_lateral_accel == pytest.approx(a_lat)


def test_figure_eight_restores_heading():
    route = tr.Route(yaw0=-1.0, speed0=8.0).figure_eight(radius=12.0, laps=2).hold(1.0)
    traj = tr.generate(tr.CarMotion(route), LAT0, LON0, H0, route.t, rate=100.0)
    assert traj.rpy[-1, 2] == pytest.approx(-1.0, abs=1e-9)
    # Both senses of rotation are flown: a full turn left, then right.
    assert np.ptp(traj.rpy[:, 2]) > 2 * np.pi


def test_position_follows_velocity(car):
    k = np.arange(0, len(car) - 1, 97)
    e, n, u = pymap3d.geodetic2enu(car.lat[k + 1], car.lon[k + 1], car.h[k + 1], car.lat[k],
                                   car.lon[k], car.h[k], deg=False)
    v_mid = 0.5 * (car.v_enu[k] + car.v_enu[k + 1])
    np.testing.assert_allclose(np.stack([e, n, u], -1) / car.dt, v_mid, atol=2e-4)


def test_attitude_follows_angular_rate(car):
    """q̇ = ½ q ⊗ ω_nb with ω_nb = ω_ib − C_bn(ω_ie + ω_en) from nav.earth, per sample."""
    k = np.arange(0, len(car) - 1, 101)
    w_fd = quat_to_rotvec(quat_mul(quat_conj(car.q_nb[k]), car.q_nb[k + 1])) / car.dt
    w_nb = []
    for i in k:
        j = (i, i + 1)
        w_in = [earth.earth_rate_enu(car.lat[m]) + earth.transport_rate_enu(
            car.lat[m], car.h[m], car.v_enu[m]) for m in j]
        w_nb.append(np.mean([car.omega_ib_b[m] - quat_to_dcm(car.q_nb[m]).T @ w_in[c]
                             for c, m in enumerate(j)], axis=0))
    # Midpoint finite difference: O(dt²·ω'') ≈ 1e-5 rad/s in the turn entries; a sign error of
    # the Earth rate would be 1e-4.
    np.testing.assert_allclose(w_fd, np.array(w_nb), atol=2e-5)


def test_at_rest_senses_gravity_and_earth_rate():
    route = tr.Route(yaw0=0.7).hold(2.0).set_pitch(0.05, 1.0).set_bank(-0.1, 1.0).hold(3.0)
    traj = tr.generate(tr.CarMotion(route), LAT0, LON0, H0, route.t, rate=100.0)
    assert np.abs(traj.v_enu).max() == 0.0
    np.testing.assert_allclose(np.linalg.norm(traj.f_b, axis=1),
                               earth.normal_gravity(LAT0, H0), rtol=1e-12)
    np.testing.assert_allclose(np.linalg.norm(traj.omega_ib_b[-50:], axis=1), 7.292115e-5,
                               rtol=1e-9)
    # Levelled accelerometers read +g up; the gyro vertical component is Ω sin(lat).
    np.testing.assert_allclose(traj.f_b[0], [0, 0, earth.normal_gravity(LAT0, H0)], atol=1e-12)
    assert traj.omega_ib_b[0, 2] == pytest.approx(7.292115e-5 * np.sin(LAT0), rel=1e-12)


def test_rates_match_pyins():
    """pyins.sim.generate_imu (NED/FRD, splines) senses the same rates and specific force."""
    pyins_sim = pytest.importorskip("pyins.sim")
    traj = scenarios.car(duration=200.0, seed=1, rate=100.0).trajectory
    roll, pitch, yaw = conventions.euler_enu_to_ned(*traj.rpy.T)
    rph = np.rad2deg(np.c_[roll, pitch, np.unwrap(yaw)])
    lla = np.c_[np.rad2deg(traj.lat), np.rad2deg(traj.lon), traj.h]
    _, imu = pyins_sim.generate_imu(traj.t, lla, rph, conventions.enu_to_ned(traj.v_enu))
    gyro = conventions.frd_to_flu(imu[["gyro_x", "gyro_y", "gyro_z"]].to_numpy())
    accel = conventions.frd_to_flu(imu[["accel_x", "accel_y", "accel_z"]].to_numpy())
    s = slice(100, -100)  # spline end effects in pyins
    rms = lambda d: np.sqrt(np.mean(d[s] ** 2, axis=0))  # noqa: E731
    # A sign error in the Earth or transport rate would show at ~1e-4 rad/s, in the Coriolis
    # term at ~2e-3 m/s².
    assert np.all(rms(gyro - traj.omega_ib_b) < 1e-6)
    assert np.all(rms(accel - traj.f_b) < 1e-3)


@pytest.mark.parametrize("name", ["car", "sea"])
def test_strapdown_reproduces_truth(name, request):
    """KEY TEST: the project's pipeline — two-sample coning/sculling from 200 Hz to 100 Hz
    (nav.coning) and the mechanisation (nav.strapdown) — run on the ideal increments returns
    the truth after 300 s of turns and figure-eights, or of ship motion in waves."""
    traj = request.getfixturevalue(name)
    phi, dv = coning.to_navigation_rate(traj.dtheta, traj.dv, 2, "two_sample")
    s0 = strapdown.NavState(traj.lat[0], traj.lon[0], traj.h[0], traj.v_enu[0], traj.q_nb[0])
    out = strapdown.run(s0, phi, dv, 2 * traj.dt)
    k = slice(None, None, 2)
    lat, lon, h = traj.lat[k], traj.lon[k], traj.h[k]
    rm, rn = earth.radii(lat)
    err = np.stack([(out["lon"] - lon) * (rn + h) * np.cos(lat), (out["lat"] - lat) * (rm + h),
                    out["h"] - h], -1)
    assert traj.t[-1] == pytest.approx(300.0)
    assert np.abs(err).max() < 0.5
    assert quat_angle_between(out["q_nb"], traj.q_nb[k]).max() < 1e-4
    assert np.abs(out["v_enu"] - traj.v_enu[k]).max() < 0.01


def test_rate_option_1200hz():
    route = tr.Route(speed0=5.0).turn(1.0, radius=10.0)
    traj = tr.generate(tr.CarMotion(route), LAT0, LON0, H0, 2.0, rate=1200.0, oversample=2)
    assert len(traj) == 2401 and traj.dt == pytest.approx(1 / 1200)
    with pytest.raises(ValueError):
        tr.generate(tr.CarMotion(route), LAT0, LON0, H0, 2.0, oversample=3)


def test_decimation_to_a_sensor_rate():
    route = tr.Route(speed0=5.0).hold(1.0)
    traj = tr.generate(tr.CarMotion(route), LAT0, LON0, H0, 1.0, rate=200.0)
    assert traj.decimation(200.0) == 1 and traj.decimation(50.0) == 4
    assert traj.decimation(0.5) == 400
    for rate in (30.0, 400.0):
        with pytest.raises(ValueError, match=f"{rate:g} Hz does not divide the trajectory rate "
                                             "200 Hz"):
            traj.decimation(rate)
