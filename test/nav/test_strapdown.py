"""Strapdown mechanisation and lever arm against analytic solutions.

Truth sources: a body at rest on the rotating Earth; level flight along the equator, whose
specific force follows from inertial kinematics (centripetal acceleration (Omega + ve/r)^2 r
and gravitation = normal gravity + Omega^2 r); the Schuler and vertical-channel error
equations; rigid-body finite differences in ECEF.
"""
import numpy as np
import pymap3d
import pytest
from scipy.optimize import curve_fit

from ins_gnss_ros.nav import earth
from ins_gnss_ros.nav.coning import to_navigation_rate
from ins_gnss_ros.nav.earth import WGS84
from ins_gnss_ros.nav.lever_arm import lever_arm_position, lever_arm_velocity
from ins_gnss_ros.nav.rotations import (quat_angle_between, quat_from_euler,
                                        quat_from_rotvec, quat_mul, quat_to_dcm)
from ins_gnss_ros.nav.strapdown import (NavState, Strapdown, VerticalDamping, apply_correction,
                                        correction_to, run, strapdown_step)
from ins_gnss_ros.sim import imu_truth


def _horizontal_error_m(res, lat0, lon0, i=-1):
    rm, rn = earth.radii(lat0)
    return np.hypot((res["lat"][i] - lat0) * rm, (res["lon"][i] - lon0) * rn * np.cos(lat0))


def test_stationary_two_hours_at_60_deg():
    lat, lon, h, dt = np.deg2rad(60.0), 0.5, 100.0, 0.02  # 50 Hz
    q0 = quat_from_euler(0.02, -0.03, 1.1)
    n_sub = 2
    dth, dv = imu_truth.stationary(lat, h, q0, dt / n_sub, int(7200 / dt) * n_sub)
    phi, dvn = to_navigation_rate(dth, dv, n_sub)
    res = run(NavState(lat, lon, h, np.zeros(3), q0), phi, dvn, dt)
    assert res["t"][-1] == pytest.approx(7200.0)
    assert _horizontal_error_m(res, lat, lon) < 0.1
    assert np.max(np.abs(res["v_enu"][:, :2])) < 1e-4
    assert quat_angle_between(res["q_nb"][-1], q0) < 1e-6
    # Free vertical channel: amplified round-off only (it grows as cosh(t / 571 s)).
    assert abs(res["h"][-1] - h) < 1.0


def test_step_matches_batch_and_class():
    lat, h, dt = 0.7, 10.0, 0.01
    q0 = quat_from_euler(0.1, 0.2, 0.3)
    dth, dv = imu_truth.stationary(lat, h, q0, dt, 5)
    dth = dth + 1e-4
    dv = dv + 0.01
    s0 = NavState(lat, 0.1, h, [1.0, 2.0, 0.1], q0)
    res = run(s0, dth, dv, dt)
    nav = Strapdown(s0)
    for k in range(5):
        s = strapdown_step(s0 if k == 0 else s, dth[k], dv[k], dt)
        nav.step(dth[k], dv[k], dt)
    for st in (s, nav.state):
        np.testing.assert_allclose([st.lat, st.lon, st.h], [res["lat"][-1], res["lon"][-1],
                                                            res["h"][-1]], rtol=0, atol=1e-15)
        np.testing.assert_allclose(st.v_enu, res["v_enu"][-1], atol=1e-15)
        assert st.t == pytest.approx(5 * dt)


def test_a_compensated_step_is_compensate_then_step_bit_for_bit():
    """The strapdown node's one compiled call per increment (Strapdown.step_compensated) gives
    the bits of SensorErrors.compensate followed by Strapdown.step."""
    from ins_gnss_ros.nav.increments import SensorErrors
    lat, h, dt = 0.7, 10.0, 0.01
    q0 = quat_from_euler(0.1, 0.2, 0.3)
    dth, dv = imu_truth.stationary(lat, h, q0, dt, 5)
    errors = SensorErrors(np.array([1e-4, -2e-4, 3e-5]), np.array([0.02, -0.01, 0.03]),
                          np.array([1e-3, -2e-3, 5e-4]), np.array([-1e-3, 2e-4, 3e-3]))
    s0 = NavState(lat, 0.1, h, [1.0, 2.0, 0.1], q0, 0.0)
    fused, separate = Strapdown(s0), Strapdown(s0)
    for k in range(5):
        comp = fused.step_compensated(dth[k], dv[k], dt, errors)
        expected = errors.compensate(dth[k], dv[k], dt)
        separate.step(*expected, dt)
        assert np.array_equal(comp, np.array(expected))
        a, b = fused.state, separate.state
        assert (a.lat, a.lon, a.h, a.t) == (b.lat, b.lon, b.h, b.t)
        assert np.array_equal(a.v_enu, b.v_enu) and np.array_equal(a.q_nb, b.q_nb)


@pytest.mark.parametrize("ve", [250.0, -250.0])
def test_level_flight_along_equator(ve):
    """Heading east (or west) at constant height: body rate and specific force are constant."""
    h, dt, T = 3000.0, 0.01, 600.0
    r = WGS84.a + h
    w_in = WGS84.omega + ve / r  # inertial rate of the ENU frame about North
    g = earth.normal_gravity(0.0, h)
    # Specific force = inertial acceleration - gravitation; gravitation = g + Omega^2 r.
    f_up = (g + WGS84.omega ** 2 * r) - w_in ** 2 * r
    yaw = 0.0 if ve > 0 else np.pi
    q0 = quat_from_euler(0.0, 0.0, yaw)
    C_bn = quat_to_dcm(q0).T
    n = int(T / dt)
    w_b = C_bn @ np.array([0.0, w_in, 0.0])
    f_b = C_bn @ np.array([0.0, 0.0, f_up])
    phi, dvn = to_navigation_rate(np.tile(w_b * dt / 2, (2 * n, 1)),
                                  np.tile(f_b * dt / 2, (2 * n, 1)), 2)
    res = run(NavState(0.0, 0.2, h, [ve, 0.0, 0.0], q0), phi, dvn, dt)
    lon_truth = 0.2 + ve / r * T
    assert abs(res["lon"][-1] - lon_truth) * r < 0.05
    assert abs(res["lat"][-1]) * r < 0.05
    assert abs(res["h"][-1] - h) < 0.05
    np.testing.assert_allclose(res["v_enu"][-1], [ve, 0.0, 0.0], atol=1e-3)
    assert quat_angle_between(res["q_nb"][-1], q0) < 1e-7


def _schuler_run(phi0_north, dt=1.0, T=10200.0, h=0.0):
    lat, lon = 0.0, 0.0
    q_true = quat_from_euler(0.0, 0.0, 0.4)
    # Attitude error convention: C_computed = (I - [phi x]) C_true, i.e. q(-phi) ⊗ q_true.
    q_comp = quat_mul(quat_from_rotvec([0.0, -phi0_north, 0.0]), q_true)
    n = int(T / dt)
    dth, dv = imu_truth.stationary(lat, h, q_true, dt, n)
    phi, dvn = to_navigation_rate(dth, dv, 1, "one_sample")
    # A stiff vertical loop: the Coriolis coupling 2 w_ie x dv between the East and vertical
    # channels otherwise shifts the Schuler frequency (by 0.2 % with omega0 = 0.01 rad/s).
    damping = VerticalDamping.from_bandwidth(0.1)
    res = run(NavState(lat, lon, h, np.zeros(3), q_comp), phi, dvn, dt, h_ref=h, damping=damping)
    east = res["lon"] * (WGS84.a + h)
    return res["t"], east, res


def test_schuler_oscillation():
    """Tilt phi_N about North at the equator: the East channel is a pure Schuler loop
    (Foucault modulation omega_ie sin(lat) vanishes, the Earth rate is parallel to the tilt so
    -omega_ie x phi = 0). Analytic solution of d(dv_E)/dt = -g phi_N, d(phi_N)/dt = dv_E / R:
    dE(t) = -R phi0 (1 - cos(w_s t)), w_s = sqrt(g / R), R = a + h."""
    phi0 = 1e-4
    t, east, _ = _schuler_run(phi0)
    R, g = WGS84.a, earth.normal_gravity(0.0, 0.0)
    period_truth = 2 * np.pi * np.sqrt(R / g)
    assert period_truth / 60 == pytest.approx(84.4, abs=0.3)

    def model(t, amp, period):
        return -amp * (1 - np.cos(2 * np.pi * t / period))

    (amp, period), _ = curve_fit(model, t, east, p0=[500.0, 5000.0])
    assert period == pytest.approx(period_truth, rel=0.01)
    assert amp == pytest.approx(R * phi0, rel=0.05)
    # Sign of the convention: a positive phi_N first drives the position WEST.
    assert east[len(east) // 4] < -100.0
    # Against the analytic curve itself.
    assert np.max(np.abs(east - model(t, R * phi0, period_truth))) < 0.005 * R * phi0


def test_vertical_channel_divergence_and_damping():
    lat, h, dt, T = np.deg2rad(45.0), 0.0, 1.0, 1200.0
    q0 = quat_from_euler(0.0, 0.0, 0.0)
    n = int(T / dt)
    dth, dv = imu_truth.stationary(lat, h, q0, dt, n)
    phi, dvn = to_navigation_rate(dth, dv, 1, "one_sample")
    s0 = NavState(lat, 0.0, h + 1.0, np.zeros(3), q0)  # 1 m initial height error
    free = run(s0, phi, dvn, dt)
    # d^2(dh)/dt^2 = -dg_U/dh... = (2 g / R) dh (gravity gradient) -> dh = cosh(t / tau).
    tau = 1.0 / np.sqrt(earth.gravity_gradient_enu(lat, h)[2, 2])
    assert tau == pytest.approx(np.sqrt(6371e3 / (2 * 9.806)), rel=0.01)
    np.testing.assert_allclose(free["h"][::100] - h, np.cosh(free["t"][::100] / tau), rtol=0.02)
    damped = run(s0, phi, dvn, dt, h_ref=h, damping=VerticalDamping.from_bandwidth(0.02, lat))
    # Residual: the 1 Hz increments lack the third-order term w x (w x f) dt^3 / 6 of the true
    # velocity increment (~1e-8 m/s^2 bias, i.e. ~1e-5 m through the loop stiffness k2).
    assert abs(damped["h"][-1] - h) < 1e-4


def test_apply_correction_convention():
    lat, lon, h = 0.8, -1.2, 50.0
    q_true = quat_from_euler(0.1, -0.2, 2.0)
    phi = np.array([2e-3, -1e-3, 5e-3])
    dpos = np.array([3.0, -4.0, 1.5])
    dv = np.array([0.1, 0.2, -0.3])
    rm, rn = earth.radii(lat)
    q_comp = quat_mul(quat_from_rotvec(-phi), q_true)
    # The computed attitude carries the tilt C_computed = (I - [phi x]) C_true (to O(phi^2)).
    C_true = quat_to_dcm(q_true)
    np.testing.assert_allclose(quat_to_dcm(q_comp), (np.eye(3) - np.cross(np.eye(3), phi)) @ C_true,
                               atol=np.dot(phi, phi))
    computed = NavState(lat + dpos[1] / (rm + h), lon + dpos[0] / ((rn + h) * np.cos(lat)),
                        h + dpos[2], np.array([5.0, 1.0, 0.0]) + dv, q_comp)
    fixed = apply_correction(computed, dpos, dv, phi)
    assert quat_angle_between(fixed.q_nb, q_true) < 1e-15
    assert fixed.lat == pytest.approx(lat, abs=1e-12)
    assert fixed.lon == pytest.approx(lon, abs=1e-12)
    assert fixed.h == pytest.approx(h, abs=1e-9)
    np.testing.assert_allclose(fixed.v_enu, [5.0, 1.0, 0.0], atol=1e-12)
    # The specific force resolved with the computed attitude errs by -phi x f.
    f_b = np.array([0.3, -0.2, 9.8])
    f_err = quat_to_dcm(computed.q_nb) @ f_b - C_true @ f_b
    np.testing.assert_allclose(f_err, -np.cross(phi, C_true @ f_b), atol=10 * np.dot(phi, phi))


def _rigid_body(t):
    """A car-like motion: position and attitude analytic in time."""
    lat = 0.9 + 2e-6 * np.sin(0.3 * t)
    lon = 0.4 + 3e-6 * t
    h = 100.0 + 2.0 * np.sin(0.5 * t)
    q = quat_from_euler(0.1 * np.sin(1.1 * t), 0.05 * np.cos(0.7 * t), 0.3 * t)
    return lat, lon, h, q


def test_lever_arm_against_rigid_body_finite_difference():
    l_b = np.array([1.2, -0.4, 1.5])
    t0, d = 3.0, 1e-3
    ts = np.array([t0 - d, t0, t0 + d])
    lat, lon, h, q = _rigid_body(ts)
    # Antenna position: ENU offset of the antenna from the IMU equals C_nb l_b (pymap3d).
    la, lo, ha = lever_arm_position(lat, lon, h, q, l_b)
    e, n, u = pymap3d.geodetic2enu(la[1], lo[1], ha[1], lat[1], lon[1], h[1], deg=False)
    np.testing.assert_allclose([e, n, u], quat_to_dcm(q[1]) @ l_b, atol=1e-9)
    # Velocities by central differences of ECEF positions, resolved in ENU at t0.
    C_en = earth.ecef_to_enu_matrix(lat[1], lon[1])
    x_imu = earth.geodetic_to_ecef(lat, lon, h)
    x_ant = earth.geodetic_to_ecef(la, lo, ha)
    v_imu = C_en @ (x_imu[2] - x_imu[0]) / (2 * d)
    v_ant = C_en @ (x_ant[2] - x_ant[0]) / (2 * d)
    # Gyro output: omega_ib = omega_eb + C_be omega_ie, omega_eb from the rate of C_eb.
    C_eb = np.swapaxes(earth.ecef_to_enu_matrix(lat, lon), -1, -2) @ quat_to_dcm(q)
    dC = (C_eb[2] - C_eb[0]) / (2 * d)
    W = C_eb[1].T @ dC  # [omega_eb x] in body axes
    w_eb = np.array([W[2, 1], W[0, 2], W[1, 0]])
    w_ib = w_eb + C_eb[1].T @ np.array([0.0, 0.0, WGS84.omega])
    v = lever_arm_velocity(v_imu, q[1], w_ib, l_b, lat[1])
    np.testing.assert_allclose(v, v_ant, atol=1e-6)
    # The rotation term is not negligible here (|w x l| ~ 0.5 m/s).
    assert np.linalg.norm(v_ant - v_imu) > 0.3


def test_correction_to_lands_on_a_target_thousands_of_km_away():
    """A strapdown started at its parameters' position (59.9 N, 30.3 E) and the filter's first
    solution in Colorado: one correction puts it there (position against pymap3d's ECEF, the
    attitude relative to the local level, the velocity), and a small error is the error
    model's to first order."""
    q0 = quat_from_euler(0.02, -0.01, 2.5)
    start = NavState(np.deg2rad(59.9), np.deg2rad(30.3), 0.0, [0.3, -0.1, 0.0], q0)
    target = NavState(np.deg2rad(40.0966), np.deg2rad(-105.1474), 1601.5, [4.0, -2.0, 0.1],
                      quat_from_euler(-0.03, 0.05, -1.2))
    landed = apply_correction(start, *correction_to(start, target))
    got = pymap3d.geodetic2ecef(landed.lat, landed.lon, landed.h, deg=False)
    want = pymap3d.geodetic2ecef(target.lat, target.lon, target.h, deg=False)
    assert np.linalg.norm(np.subtract(got, want)) < 1e-6
    np.testing.assert_allclose(landed.v_enu, target.v_enu, atol=1e-12)
    assert quat_angle_between(landed.q_nb, target.q_nb) < 1e-12
    near = apply_correction(target, [3.0, -2.0, 1.5], [0.1, 0.0, 0.0], [1e-3, 0.0, 2e-3])
    from ins_gnss_ros.nav.error_model import nav_error
    # second order: the radii at latitudes 2 m apart (here 1.5 um)
    np.testing.assert_allclose(np.concatenate(correction_to(near, target)),
                               np.concatenate(nav_error(near, target)), atol=1e-5)
