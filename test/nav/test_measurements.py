"""Measurement matrices against numerical differentiation of the non-linear measurement functions.

The error state is injected into a true NavState with strapdown.apply_correction (the inverse of
the filter's feedback: a computed state with errors dx is apply_correction(true, -dp, -dv, -phi)
to first order), sensor residuals are added to the quantities they corrupt, and the measurement
residual z is differentiated by central differences. A sign error in any H block fails here.
"""
import numpy as np
import pytest

from ins_gnss_ros.magnetic.compass import magnetic_azimuth
from ins_gnss_ros.nav import measurements as M
from ins_gnss_ros.nav.earth import earth_rate_enu, ecef_to_enu_matrix, geodetic_to_ecef
from ins_gnss_ros.nav.ekf import ExtraState, StateSpace
from ins_gnss_ros.nav.error_model import make_layout
from ins_gnss_ros.nav.lever_arm import lever_arm_position, lever_arm_velocity
from ins_gnss_ros.nav.rotations import quat_conj, quat_from_euler, quat_from_rotvec, quat_mul, \
    quat_to_dcm, quat_to_euler, skew
from ins_gnss_ros.nav.sensor_errors import MEMS_ADIS16405, filter_noise
from ins_gnss_ros.nav.strapdown import NavState, apply_correction

NOISE = filter_noise(MEMS_ADIS16405, "rw")
SPACE = StateSpace(make_layout("24", NOISE), {"td": ExtraState(1, 0.1), "mag": ExtraState(1, 0.1),
                                              "nhc": ExtraState(2, 0.01),
                                              "log": ExtraState(3, 0.1),
                                              "wheel": ExtraState(1, 0.02)})
TRUE = NavState(np.deg2rad(40.1), np.deg2rad(-105.1), 1600.0, np.array([6.0, -8.0, 0.3]),
                quat_from_euler(0.1, -0.2, 2.5), 0.0)
OMEGA = np.array([0.05, -0.1, 0.3])  # true angular rate, FLU rad/s
LEVER = np.array([0.8, -0.4, 1.2])   # FLU m


def perturbed(dx):
    """Computed state and the residual sensor errors encoded in the error vector dx."""
    S = SPACE
    state = apply_correction(TRUE, -dx[S["pos"]], -dx[S["vel"]], -dx[S["att"]])
    return state, {name: dx[S[name]] for name in ("bg", "clock", "mag", "nhc", "log", "wheel")}


def numerical_H(z_of, dx_scale):
    """Central-difference Jacobian of z_of(dx) at dx = 0 with per-state steps."""
    z0 = z_of(np.zeros(SPACE.size))
    H = np.zeros((len(z0), SPACE.size))
    for i in range(SPACE.size):
        e = np.zeros(SPACE.size)
        e[i] = dx_scale[i]
        H[:, i] = (z_of(e) - z_of(-e)) / (2 * dx_scale[i])
    return H


STEPS = np.full(SPACE.size, 1e-4)
STEPS[SPACE["pos"]] = 1e-2
STEPS[SPACE["clock"]] = 1e-2


def check(model, z_of, atol):
    H_num = numerical_H(z_of, STEPS)
    np.testing.assert_allclose(model.H, H_num, atol=atol)


def test_gnss_position_with_lever_arm():
    meas = lever_arm_position(TRUE.lat, TRUE.lon, TRUE.h, TRUE.q_nb, LEVER)
    cov = np.eye(3) * 0.01
    model = M.gnss_position(SPACE, TRUE, *meas, cov, LEVER)
    np.testing.assert_allclose(model.z, 0.0, atol=1e-6)

    def z_of(dx):
        st, _ = perturbed(dx)
        return M.gnss_position(SPACE, st, *meas, cov, LEVER).z
    H_num = numerical_H(z_of, STEPS)
    cols = np.r_[SPACE["pos"].start:SPACE["att"].stop]
    np.testing.assert_allclose(model.H[:, cols], H_num[:, cols], atol=2e-6)


def test_gnss_velocity_with_lever_arm_and_gyro_bias():
    meas = lever_arm_velocity(TRUE.v_enu, TRUE.q_nb, OMEGA, LEVER, TRUE.lat)
    model = M.gnss_velocity(SPACE, TRUE, meas, np.eye(3), OMEGA, LEVER)
    np.testing.assert_allclose(model.z, 0.0, atol=1e-12)

    def z_of(dx):
        st, res = perturbed(dx)
        # residual gyro error: compensated rate = true + residual
        return M.gnss_velocity(SPACE, st, meas, np.eye(3), OMEGA + res["bg"], LEVER).z
    check(model, z_of, 1e-6)


LEVER_SPACE = StateSpace(make_layout("15", NOISE), {
    name: ExtraState(1, 1.0, consider=True) for name in ("lever_x", "lever_y", "lever_z")})


@pytest.mark.parametrize("kind", ["position", "velocity"])
def test_lever_arm_columns(kind):
    # The "lever_*" blocks are the true lever arm minus the configured one: the measurement is made
    # at the true antenna, the model predicts it at the configured one.
    S = LEVER_SPACE

    def model(dx):
        state = apply_correction(TRUE, -dx[S["pos"]], -dx[S["vel"]], -dx[S["att"]])
        lever_true = LEVER + dx[S["lever_x"].start:S["lever_z"].stop]
        if kind == "position":
            meas = lever_arm_position(TRUE.lat, TRUE.lon, TRUE.h, TRUE.q_nb, lever_true)
            return M.gnss_position(S, state, *meas, np.eye(3), LEVER)
        meas = lever_arm_velocity(TRUE.v_enu, TRUE.q_nb, OMEGA, lever_true, TRUE.lat)
        return M.gnss_velocity(S, state, meas, np.eye(3), OMEGA, LEVER)

    H_num = np.zeros((3, S.size))
    for i in range(S.size):
        e = np.zeros(S.size)
        e[i] = 1e-2 if i in range(S.size)[S["pos"]] else 1e-4
        H_num[:, i] = (model(e).z - model(-e).z) / (2 * e[i])
    cols = np.r_[S["pos"].start:S["att"].stop, S["lever_x"].start:S["lever_z"].stop]
    # (the gyro columns: test_gnss_velocity_with_lever_arm_and_gyro_bias)
    # (the position's lever columns to 1e-5: lever_arm_position resolves a metre-long arm on
    # the ellipsoid, the model as a straight vector)
    np.testing.assert_allclose(model(np.zeros(S.size)).H[:, cols], H_num[:, cols], atol=1e-5)


def test_lever_attitude_second_order_term():
    # The filter linearises at its estimate: the "lever_*" columns are -C of the estimated
    # attitude, and the true C carries the lever arm's error as well. Over random attitude
    # errors and errors of the configured lever arm the residual's remainder beyond that
    # first-order model is the product -[phi x] C dl, whose covariance the fix's R gains
    # (measurements._lever_attitude_variance).
    S, rng = LEVER_SPACE, np.random.default_rng(7)
    att, lever = S["att"], slice(S["lever_x"].start, S["lever_z"].stop)
    P = np.eye(S.size) * 1e-8
    P[att, att] = [[4e-4, 1e-4, 0.0], [1e-4, 2.5e-4, -5e-5], [0.0, -5e-5, 9e-4]]
    P[lever, lever] = np.diag([0.3, 0.5, 1.0]) ** 2
    dx = np.zeros((4000, S.size))
    dx[:, att] = rng.multivariate_normal(np.zeros(3), P[att, att], len(dx))
    dx[:, lever] = rng.multivariate_normal(np.zeros(3), P[lever, lever], len(dx))
    remainder = []
    for d in dx:
        estimate = apply_correction(TRUE, np.zeros(3), np.zeros(3), -d[att])
        meas = lever_arm_position(TRUE.lat, TRUE.lon, TRUE.h, TRUE.q_nb, LEVER + d[lever])
        model = M.gnss_position(S, estimate, *meas, np.eye(3), LEVER, P=P)
        remainder.append(model.z - model.H @ d)
    exact = (TRUE.lat, TRUE.lon, TRUE.h, np.eye(3), LEVER)
    # 4,000 samples: each (co)variance to a few per cent
    np.testing.assert_allclose(np.cov(np.transpose(remainder)),
                               M.gnss_position(S, TRUE, *exact, P=P).R - np.eye(3),
                               rtol=0.1, atol=1e-5)
    # without P: the first-order model's R
    assert np.array_equal(M.gnss_position(S, TRUE, *exact).R, np.eye(3))


@pytest.mark.parametrize("axis_yaw", [0.0, 0.7])
def test_heading(axis_yaw):
    x = np.cos(axis_yaw), np.sin(axis_yaw), 0.0
    az, _ = M.azimuth_of_axis(TRUE.q_nb, x)
    model = M.heading(SPACE, TRUE, az, 1e-4, axis_yaw)
    assert model.z[0] == pytest.approx(0.0, abs=1e-12)

    def z_of(dx):
        st, _ = perturbed(dx)
        return M.heading(SPACE, st, az, 1e-4, axis_yaw).z
    check(model, z_of, 1e-7)


def test_heading_level_vehicle_is_phi_up():
    # Seed 004: z_K = K_pr - K_ext = phi_h (H = +1 on the vertical attitude error).
    level = NavState(0.7, 0.1, 0.0, np.zeros(3), quat_from_euler(0.0, 0.0, 0.4))
    model = M.heading(SPACE, level, 0.0, 1.0)
    np.testing.assert_allclose(model.H[0, SPACE["att"]], [0.0, 0.0, 1.0], atol=1e-12)


def test_magnetic_heading_with_bias_state():
    az, _ = M.azimuth_of_axis(TRUE.q_nb)
    bias_true = 0.05
    model = M.biased_heading(SPACE, TRUE, az + bias_true, 1e-4, bias=bias_true)
    assert model.z[0] == pytest.approx(0.0, abs=1e-12)

    def z_of(dx):
        st, res = perturbed(dx)
        # residual = true bias - estimate, so the estimate is true - residual
        return M.biased_heading(SPACE, st, az + bias_true, 1e-4, bias_true - res["mag"][0]).z
    check(model, z_of, 1e-7)


def test_magnetic_heading_levelled_with_the_ins_attitude():
    # A compass that levels the body field with the INS's roll and pitch (mag_compass's
    # attitude_source ins_state) errs by the INS's tilt error times tan(inclination): the
    # reading is recomputed from the true body field at every perturbed INS attitude.
    decl, incl = np.deg2rad(10.0), np.deg2rad(72.0)
    field = np.array([np.cos(incl) * np.sin(decl), np.cos(incl) * np.cos(decl), -np.sin(incl)])
    mag_b = quat_to_dcm(TRUE.q_nb).T @ field

    def reading(st):
        roll, pitch, _ = quat_to_euler(st.q_nb)
        return magnetic_azimuth(mag_b, roll, pitch) + decl

    model = M.biased_heading(SPACE, TRUE, reading(TRUE), 1e-4, field_enu=field)
    assert model.z[0] == pytest.approx(0.0, abs=1e-12)

    def z_of(dx):
        st, res = perturbed(dx)
        return M.biased_heading(SPACE, st, reading(st), 1e-4, -res["mag"][0],
                                field_enu=field).z
    check(model, z_of, 1e-7)
    tilt = model.H[0, SPACE["att"]][:2]
    assert np.hypot(*tilt) == pytest.approx(np.tan(incl), rel=1e-9)
    # taken as a yaw alone (a compass levelling itself) the tilt columns are the x axis'
    yaw_only = M.biased_heading(SPACE, TRUE, reading(TRUE), 1e-4).H[0, SPACE["att"]]
    assert np.hypot(*yaw_only[:2]) < 0.3


def test_horizontal_acceleration_is_the_tilts_and_accelerometers_share_of_gravity():
    """The INS's computed horizontal acceleration less the vehicle's: its Jacobian in the tilt
    and accelerometer-bias columns by central differences of the strapdown's own
    C (f + b) - g; the yaw column left out (a yaw error turns the vehicle's unknown
    acceleration), the position and velocity ones too."""
    from ins_gnss_ros.nav.earth import normal_gravity

    g_n = np.array([0.0, 0.0, normal_gravity(TRUE.lat, TRUE.h)])
    a_true = np.array([0.8, -0.5, 0.1])
    f_b = M.quat_to_dcm(TRUE.q_nb).T @ (a_true + g_n)
    model = M.horizontal_acceleration(SPACE, TRUE, a_true, OMEGA, 1.0)
    np.testing.assert_allclose(model.z, a_true[:2])
    np.testing.assert_allclose(model.R, np.eye(2))

    def z_of(dx):
        st, _ = perturbed(dx)
        return (M.quat_to_dcm(st.q_nb) @ (f_b + dx[SPACE["ba"]]) - g_n)[:2]
    H = numerical_H(z_of, STEPS)
    att, ba = SPACE["att"], SPACE["ba"]
    tilt = slice(att.start, att.start + 2)
    np.testing.assert_allclose(model.H[:, tilt], H[:, tilt], atol=1e-6)
    np.testing.assert_allclose(model.H[:, ba], H[:, ba], atol=1e-6)
    assert not model.H[:, att.start + 2].any()
    assert not model.H[:, SPACE["pos"]].any() and not model.H[:, SPACE["vel"]].any()


def test_nonholonomic_and_zupt_zaru():
    # A state that satisfies the constraint at the point `arm` of vehicle axes turned by
    # `bore` (pitch, yaw) from the IMU axes.
    arm = np.array([-1.5, 0.2, -1.0])
    bore = np.array([0.02, -0.03])
    c_vb = M.quat_to_dcm(quat_from_euler(0.0, bore[0], bore[1])).T  # IMU -> vehicle axes
    v_b = c_vb.T @ np.array([9.0, 0.0, 0.0]) - np.cross(OMEGA, arm)
    state = NavState(TRUE.lat, TRUE.lon, TRUE.h, M.quat_to_dcm(TRUE.q_nb) @ v_b, TRUE.q_nb)
    model = M.nonholonomic(SPACE, state, 0.1, 0.1, OMEGA, arm, bore)
    np.testing.assert_allclose(model.z, 0.0, atol=1e-2)  # small-angle boresight model

    def z_of(dx):
        st, res = perturbed(dx)
        st = NavState(st.lat, st.lon, st.h, st.v_enu + state.v_enu - TRUE.v_enu, st.q_nb)
        return M.nonholonomic(SPACE, st, 0.1, 0.1, OMEGA + res["bg"], arm,
                              bore - res["nhc"]).z
    check(model, z_of, 1e-6)

    # The same vehicle with the IMU in its own axes (yawed 175 deg, pitched -7 deg from it):
    # the vehicle axes given to the model, the small boresight about them.
    c_bs = M.quat_to_dcm(quat_from_euler(0.0, np.radians(-7.0), np.radians(175.0)))
    axes = c_bs  # rows: the vehicle's forward, lateral, vertical axes in the IMU's axes
    turned = NavState(TRUE.lat, TRUE.lon, TRUE.h, state.v_enu,
                      quat_mul(TRUE.q_nb, quat_from_euler(0.0, np.radians(-7.0),
                                                          np.radians(175.0))))
    model = M.nonholonomic(SPACE, turned, 0.1, 0.1, c_bs.T @ OMEGA, c_bs.T @ arm, bore, axes)
    np.testing.assert_allclose(model.z, 0.0, atol=1e-2)

    def z_axes(dx):
        st, res = perturbed(dx)
        # the attitude error of the IMU's frame is the same rotation in ENU
        q = quat_mul(quat_mul(st.q_nb, quat_conj(TRUE.q_nb)), turned.q_nb)
        st = NavState(st.lat, st.lon, st.h, st.v_enu + state.v_enu - TRUE.v_enu, q)
        return M.nonholonomic(SPACE, st, 0.1, 0.1, c_bs.T @ OMEGA + res["bg"], c_bs.T @ arm,
                              bore - res["nhc"], axes).z
    check(model, z_axes, 1e-6)

    def z_zupt(dx):
        st, _ = perturbed(dx)
        return M.zero_velocity(SPACE, st, 0.01).z
    check(M.zero_velocity(SPACE, TRUE, 0.01), z_zupt, 1e-9)

    still = NavState(TRUE.lat, TRUE.lon, TRUE.h, np.zeros(3), TRUE.q_nb)
    w_earth = M.quat_to_dcm(still.q_nb).T @ M.earth_rate_enu(still.lat)
    model = M.zero_angular_rate(SPACE, still, w_earth, 1e-4)
    np.testing.assert_allclose(model.z, 0.0, atol=1e-18)

    def z_zaru(dx):
        st, res = perturbed(dx)
        return M.zero_angular_rate(SPACE, st, w_earth + res["bg"], 1e-4).z
    # the attitude term (phi times the Earth rate, ~1e-4 of H) is neglected by design
    check(model, z_zaru, 1e-4)


@pytest.mark.parametrize("roll, yaw", [(0.0, 2.5), (np.pi / 2, -1.0)])
def test_vertical_rate_error_is_what_the_gyro_residual_turns_the_x_axis_azimuth_by(roll, yaw):
    """H dx: how fast a residual gyro bias turns the azimuth of the body x axis (what a run of
    fixes measures against, course.run_velocity), for a level body and for one rolled 90 deg,
    whose y axis is then up."""
    state = NavState(TRUE.lat, TRUE.lon, TRUE.h, TRUE.v_enu, quat_from_euler(roll, 0.0, yaw))
    model = M.vertical_rate_error(SPACE, state, 0.01, 1e-6)
    residual, dt = np.array([0.003, -0.02, 0.05]), 1e-6
    dx = np.zeros(SPACE.size)
    dx[SPACE["bg"]] = residual

    def azimuth(C):
        return np.arctan2(C[1, 0], C[0, 0])
    C = M.quat_to_dcm(state.q_nb)
    turned = C @ M.quat_to_dcm(quat_from_rotvec(residual * dt))
    assert model.H @ dx == pytest.approx([(azimuth(turned) - azimuth(C)) / dt], rel=1e-5)
    assert model.z == pytest.approx([0.01]) and model.R.ravel() == pytest.approx([1e-6])


def test_speed_log_with_current_and_scale():
    current, scale = np.array([0.3, -0.2]), 0.02
    r = M.quat_to_dcm(TRUE.q_nb)[:, 0]
    speed = (1 + scale) * r @ (TRUE.v_enu - np.r_[current, 0.0])
    model = M.speed_log(SPACE, TRUE, speed, 0.01, current, scale)
    assert model.z[0] == pytest.approx(0.0, abs=1e-12)

    def z_of(dx):
        st, res = perturbed(dx)
        return M.speed_log(SPACE, st, speed, 0.01, current - res["log"][:2],
                           scale - res["log"][2]).z
    check(model, z_of, 1e-6)


def test_wheel_velocity_with_lever_arm_and_scale():
    # The true state and the velocity the wheels of a non-skidding point at `arm` read.
    arm, scale = np.array([-1.2, 0.3, -0.5]), 0.01
    v_point = M.quat_to_dcm(TRUE.q_nb).T @ TRUE.v_enu + np.cross(OMEGA, arm)
    measured = np.array([(1 + scale) * v_point[0], v_point[1], v_point[2]])
    variance = np.array([0.04, 0.01, 0.01])
    model = M.wheel_velocity(SPACE, TRUE, measured, variance, OMEGA, arm, scale)
    np.testing.assert_allclose(model.z, 0.0, atol=1e-12)
    np.testing.assert_allclose(model.R, np.diag(variance))

    def z_of(dx):
        st, res = perturbed(dx)
        return M.wheel_velocity(SPACE, st, measured, variance, OMEGA + res["bg"], arm,
                                scale - res["wheel"][0]).z
    check(model, z_of, 1e-6)
    # an infinite variance leaves its axis out: forward speed only
    forward = M.wheel_velocity(SPACE, TRUE, measured, [0.04, np.inf, np.inf], OMEGA, arm, scale)
    np.testing.assert_allclose(forward.H, model.H[:1])


def test_speed_log_level_heading_terms():
    # A level vessel moving along its own axis: a small heading error changes the along-axis
    # speed only to second order (cos), so the heading column vanishes.
    level = NavState(0.7, 0.1, 0.0, np.array([0.0, 5.0, 0.0]), quat_from_euler(0, 0, np.pi / 2))
    model = M.speed_log(SPACE, level, 5.0, 0.01)
    assert model.z[0] == pytest.approx(0.0, abs=1e-12)
    assert model.H[0, SPACE["att"].start + 2] == pytest.approx(0.0, abs=1e-12)


def satellites():
    """Four satellites at GNSS distances above the test position, ECEF."""
    r = geodetic_to_ecef(TRUE.lat, TRUE.lon, TRUE.h)
    C = ecef_to_enu_matrix(TRUE.lat, TRUE.lon)
    dirs = np.array([[0.3, 0.4, 0.866], [-0.7, 0.1, 0.7], [0.1, -0.8, 0.6], [0.6, 0.6, 0.5]])
    dirs /= np.linalg.norm(dirs, axis=1)[:, None]
    pos = r + 2.2e7 * dirs @ C
    vel = np.array([[3000.0, -500.0, 1000.0], [-2000.0, 1500.0, 200.0],
                    [100.0, 2500.0, -2000.0], [-1500.0, -1500.0, 1500.0]])
    return pos, vel


def test_pseudoranges_and_range_rates():
    pos, vel = satellites()
    sat_clk = np.array([10.0, -20.0, 5.0, 0.0])
    clock = np.array([300.0, 2.0, 0.0])
    lat, lon, h = lever_arm_position(TRUE.lat, TRUE.lon, TRUE.h, TRUE.q_nb, LEVER)
    rho = np.linalg.norm(pos - geodetic_to_ecef(lat, lon, h), axis=1)
    pr = rho + clock[0] - sat_clk
    model = M.pseudoranges(SPACE, TRUE, pos, sat_clk, pr, 9.0, clock[0], LEVER)
    np.testing.assert_allclose(model.z, 0.0, atol=1e-6)

    def z_pr(dx):
        st, res = perturbed(dx)
        return M.pseudoranges(SPACE, st, pos, sat_clk, pr, 9.0, clock[0] - res["clock"][0],
                              LEVER).z
    H_num = numerical_H(z_pr, STEPS)
    # The attitude columns agree to ~4e-5 (relative 5e-4): second-order lever-arm terms
    # (1.5 m arm, 1e-4 rad steps) of no consequence next to pseudorange noise.
    np.testing.assert_allclose(model.H, H_num, atol=1e-4)

    drift = np.array([0.1, -0.2, 0.0, 0.05])
    v_ant = lever_arm_velocity(TRUE.v_enu, TRUE.q_nb, OMEGA, LEVER, TRUE.lat)
    u = (pos - geodetic_to_ecef(lat, lon, h)) / rho[:, None]
    v_ant_ecef = ecef_to_enu_matrix(TRUE.lat, TRUE.lon).T @ v_ant
    rr = np.einsum("ij,ij->i", u, vel - v_ant_ecef) + clock[1] - drift
    model = M.range_rates(SPACE, TRUE, pos, vel, drift, rr, 0.01, OMEGA, clock[1], LEVER)
    np.testing.assert_allclose(model.z, 0.0, atol=1e-6)

    def z_rr(dx):
        st, res = perturbed(dx)
        return M.range_rates(SPACE, st, pos, vel, drift, rr, 0.01, OMEGA + res["bg"],
                             clock[1] - res["clock"][1], LEVER).z
    H_num = numerical_H(z_rr, STEPS)
    # The line-of-sight change with the antenna position (relative satellite velocity / range
    # ~ 1.5e-4 per m of displacement, here from the position error or from the lever arm
    # turning with phi) is neglected: tolerance 5e-4 against H entries of order 1.
    cols = np.r_[SPACE["vel"].start:SPACE["att"].stop, SPACE["bg"].start:SPACE["bg"].stop,
                 SPACE["clock"].start:SPACE["clock"].stop]
    np.testing.assert_allclose(model.H[:, cols], H_num[:, cols], atol=5e-4)
    vel_cols = np.r_[SPACE["vel"].start:SPACE["vel"].stop, SPACE["clock"].start + 1]
    np.testing.assert_allclose(model.H[:, vel_cols], H_num[:, vel_cols], atol=1e-7)


def test_time_offset_column():
    # A measurement stamped t refers to t - td: predicting at t - td_est leaves dz/dt * residual.
    v_ant = np.array([5.0, -3.0, 0.2])
    model = M.gnss_position(SPACE, TRUE, TRUE.lat, TRUE.lon, TRUE.h, np.eye(3), dzdt=v_ant)
    np.testing.assert_array_equal(model.H[:, SPACE["td"].start], v_ant)


def test_a_stamps_scatter_adds_its_rate_times_it_to_the_noise():
    # A stamp off its epoch by a random e (sigma s) moves the fix by v e and the velocity by a e.
    v_ant, a_ant, s = np.array([5.0, -3.0, 0.2]), np.array([1.0, 2.0, 0.0]), 0.05
    fix = M.gnss_position(SPACE, TRUE, TRUE.lat, TRUE.lon, TRUE.h, np.eye(3), dzdt=v_ant,
                          stamp_sigma=s)
    np.testing.assert_allclose(fix.R, np.eye(3) + s ** 2 * np.outer(v_ant, v_ant))
    vel = M.gnss_velocity(SPACE, TRUE, TRUE.v_enu, np.eye(3), OMEGA, dzdt=a_ant, stamp_sigma=s)
    np.testing.assert_allclose(vel.R, np.eye(3) + s ** 2 * np.outer(a_ant, a_ant))
    assert np.array_equal(M.gnss_position(SPACE, TRUE, TRUE.lat, TRUE.lon, TRUE.h, np.eye(3),
                                          dzdt=v_ant).R, np.eye(3))


#: Two baselines of a 4-antenna array (body FLU, m) and the line-of-sight differences e_ref - e_i
#: of three satellite pairs (ENU).
DD_BASELINES = np.array([[-2.7, 0.0, 0.0], [0.0, -1.2, 0.0], [-2.7, -1.2, 0.05]])
DD_GEOMETRY = np.array([[0.3, -0.8, 0.4], [-0.5, 0.2, 0.6], [0.1, 0.9, -0.3]])


def test_phase_double_differences_jacobian():
    C = quat_to_dcm(TRUE.q_nb)
    value = np.einsum("ij,ij->i", DD_GEOMETRY, DD_BASELINES @ C.T)
    cov = 1e-6 * (np.eye(3) + 0.5)          # correlated through the reference satellite

    def z_of(dx):
        state, _ = perturbed(dx)
        return M.phase_differences(SPACE, state, DD_BASELINES, DD_GEOMETRY, value, cov).z

    model = M.phase_differences(SPACE, TRUE, DD_BASELINES, DD_GEOMETRY, value, cov)
    np.testing.assert_allclose(model.z, 0.0, atol=1e-12)   # the true attitude predicts them
    np.testing.assert_array_equal(model.R, cov)
    check(model, z_of, 1e-7)
    # The sign of the attitude error written out: C_computed = (I - [phi x]) C_true to first
    # order, so a computed attitude rotated by -phi predicts z = H phi.
    phi = np.array([2e-4, -1e-4, 3e-4])
    computed = NavState(TRUE.lat, TRUE.lon, TRUE.h, TRUE.v_enu,
                        quat_mul(quat_from_rotvec(-phi), TRUE.q_nb), TRUE.t)
    z = M.phase_differences(SPACE, computed, DD_BASELINES, DD_GEOMETRY, value, cov).z
    np.testing.assert_allclose(z, model.H[:, SPACE["att"]] @ phi, rtol=1e-3, atol=1e-12)
    assert np.all(model.H[:, np.r_[0:SPACE["att"].start, SPACE["att"].stop:SPACE.size]] == 0.0)


def test_the_lever_arm_columns_take_the_rate_they_are_given():
    # A smoothed rate for the consider columns (navigator.LEVER_RATE_TAU): with a zero one only
    # the Earth-rate term is left; the prediction and the other columns keep the measured rate.
    S = LEVER_SPACE
    meas = lever_arm_velocity(TRUE.v_enu, TRUE.q_nb, OMEGA, LEVER, TRUE.lat)
    given = M.gnss_velocity(S, TRUE, meas, np.eye(3), OMEGA, LEVER, lever_rate=np.zeros(3))
    measured = M.gnss_velocity(S, TRUE, meas, np.eye(3), OMEGA, LEVER)
    C = quat_to_dcm(TRUE.q_nb)
    cols = slice(S["lever_x"].start, S["lever_z"].stop)
    np.testing.assert_allclose(given.H[:, cols], skew(earth_rate_enu(TRUE.lat)) @ C, atol=1e-15)
    np.testing.assert_array_equal(given.z, measured.z)
    np.testing.assert_array_equal(given.H[:, :cols.start], measured.H[:, :cols.start])
