"""Alignment on simulated static sensors (sensor_errors presets) against the error theory."""

import numpy as np
import pytest

from ins_gnss_ros.nav import alignment as al
from ins_gnss_ros.nav import sensor_errors as se
from ins_gnss_ros.nav.earth import WGS84, earth_rate_enu, normal_gravity
from ins_gnss_ros.nav.rotations import (quat_conj, quat_from_euler, quat_mul, quat_to_dcm,
                                        quat_to_euler, quat_to_rotvec)

DEG = np.pi / 180.0
LAT = 50.0 * DEG
TRUE_RPY = (2.0 * DEG, -3.0 * DEG, 40.0 * DEG)


def static_increments(duration, dt, rpy=TRUE_RPY, lat=LAT):
    """Ideal increments of an IMU at rest: f_b = C^T [0,0,g], ω_b = C^T ω_ie."""
    C = quat_to_dcm(quat_from_euler(*rpy))
    n = int(round(duration / dt))
    f_b = C.T @ np.array([0.0, 0.0, normal_gravity(lat, 0.0)])
    w_b = C.T @ earth_rate_enu(lat)
    return np.tile(w_b * dt, (n, 1)), np.tile(f_b * dt, (n, 1)), C


def heading_theory(eps_n, b_n, lat=LAT):
    """Yaw error predicted geometrically from the realised mean sensor errors (ENU).

    The computed up axis is the measured specific force g e_z + b_n, the computed North the
    measured rate ω_ie + ε_n made horizontal w.r.t. that up axis; the yaw error is the
    clockwise angle of the computed North from the true North (yaw counts anticlockwise).
    """
    up = np.array([0.0, 0.0, normal_gravity(lat, 0.0)]) + b_n
    up /= np.linalg.norm(up)
    w = earth_rate_enu(lat) + eps_n
    north = w - (w @ up) * up
    return np.arctan2(north[0], north[1])


def yaw_error(q_est, q_true):
    """Clockwise angle of the computed North axis from the true North (Euler-free)."""
    north = quat_to_dcm(q_true) @ quat_to_dcm(q_est).T @ np.array([0.0, 1.0, 0.0])
    return np.arctan2(north[0], north[1])


def phi_of(q_est, q_true):
    """Attitude error φ with C̃ = (I - [φ×]) C (error_model convention)."""
    return -quat_to_rotvec(quat_mul(q_est, quat_conj(q_true)))


def realised(grade, duration, dt, runs, seed):
    dth, dvs, C = static_increments(duration, dt)
    sim = se.ImuErrorSimulator(grade, dt, np.random.default_rng(seed), runs)
    dth_m, dv_m = sim.corrupt(dth, dvs)
    # Realised mean sensor errors in ENU (everything the theory needs to know).
    eps_n = (dth_m - dth).sum(axis=1) / duration @ C.T
    b_n = (dv_m - dvs).sum(axis=1) / duration @ C.T
    return dth_m, dv_m, eps_n, b_n


@pytest.mark.parametrize("grade,duration", [(se.TACTICAL, 600.0), (se.MEMS_ADIS16405, 120.0)],
                         ids=["tactical", "mems"])
def test_levelling_error_is_accel_error_over_g(grade, duration):
    dt, runs = 0.1, 12
    dth_m, dv_m, eps_n, b_n = realised(grade, duration, dt, runs, 11)
    g = normal_gravity(LAT, 0.0)
    q_true = quat_from_euler(*TRUE_RPY)
    for r in range(runs):
        res = al.coarse_alignment(dth_m[r], dv_m[r], dt, LAT, grade)
        roll, pitch, _ = quat_to_euler(res.q_nb)
        bound = np.linalg.norm(b_n[r, :2]) / g
        assert abs(roll - TRUE_RPY[0]) <= 1.5 * bound
        assert abs(pitch - TRUE_RPY[1]) <= 1.5 * bound
        # Theory: the computed up axis is f̃/|f̃|, tilted by the horizontal b_n / g (i.e.
        # φ_E = -b_N/g, φ_N = b_E/g); compared heading-independently through the up axis.
        C_est, C_true = quat_to_dcm(res.q_nb), quat_to_dcm(q_true)
        tilt_n = C_true @ (C_est[2] - C_true[2])
        np.testing.assert_allclose(tilt_n[:2], b_n[r, :2] / g, rtol=0.02, atol=1e-7)


def test_gyrocompass_tactical_within_theory():
    dt, runs, duration = 0.1, 12, 600.0
    dth_m, dv_m, eps_n, b_n = realised(se.TACTICAL, duration, dt, runs, 5)
    rate = WGS84.omega * np.cos(LAT)
    g = normal_gravity(LAT, 0.0)
    q_true = quat_from_euler(*TRUE_RPY)
    for r in range(runs):
        res = al.coarse_alignment(dth_m[r], dv_m[r], dt, LAT, se.TACTICAL)
        yaw_err = quat_to_euler(res.q_nb)[2] - TRUE_RPY[2]
        tilt_term = abs(b_n[r, 0] / g * np.tan(LAT))
        assert abs(yaw_err) <= 1.5 * abs(eps_n[r, 0]) / rate + tilt_term
        assert yaw_error(res.q_nb, q_true) == pytest.approx(heading_theory(eps_n[r], b_n[r]),
                                                            rel=1e-6, abs=1e-9)


def test_gyrocompass_mems_fails_as_theory_predicts():
    """MEMS bias (≈180 °/h) exceeds the Earth rate: heading is the direction of ω_ie + ε."""
    dt, runs, duration = 0.1, 12, 120.0
    dth_m, dv_m, eps_n, b_n = realised(se.MEMS_ADIS16405, duration, dt, runs, 7)
    rate = WGS84.omega * np.cos(LAT)
    errs = []
    for r in range(runs):
        res = al.coarse_alignment(dth_m[r], dv_m[r], dt, LAT, se.MEMS_ADIS16405)
        yaw_err = yaw_error(res.q_nb, quat_from_euler(*TRUE_RPY))
        assert yaw_err == pytest.approx(heading_theory(eps_n[r], b_n[r]), rel=1e-6, abs=1e-9)
        errs.append(yaw_err)
        assert res.cov_phi[2, 2] == pytest.approx(al.UNIFORM_HEADING_VAR)
    assert np.sqrt(np.mean(np.square(errs))) > 30 * DEG
    # The linear bound ε_E/(Ω cos L) is far beyond one radian: no heading information.
    assert se.MEMS_ADIS16405.gyro.bias_sigma / rate > 10


def test_covariance_matches_monte_carlo_spread():
    """Tactical: RMS of φ over runs vs the predicted σ (χ² 99 % band for 40 runs)."""
    dt, runs, duration = 0.2, 40, 600.0
    dth_m, dv_m, _, _ = realised(se.TACTICAL, duration, dt, runs, 3)
    q_true = quat_from_euler(*TRUE_RPY)
    phis = []
    for r in range(runs):
        res = al.coarse_alignment(dth_m[r], dv_m[r], dt, LAT, se.TACTICAL)
        phis.append(phi_of(res.q_nb, q_true))
    ratio = np.mean(np.square(phis), axis=0) / np.diag(res.cov_phi)
    # χ²(40) 0.5 % and 99.5 % quantiles / 40.
    assert np.all(ratio > 20.7 / 40) and np.all(ratio < 66.8 / 40), ratio


def test_in_motion_heading_sources():
    yaw, sig = al.yaw_from_velocity([10.0, 10.0, 0.2], np.eye(3) * 0.1 ** 2)
    assert yaw == pytest.approx(45 * DEG) and sig == pytest.approx(0.1 / np.sqrt(200))
    # Only the cross-track error turns the course: 0.1 m/s north across an eastward 10 m/s.
    _, sig = al.yaw_from_velocity([10.0, 0.0, 0.0], np.diag([4.0, 0.01, 9.0]))
    assert sig == pytest.approx(0.01)
    # Azimuth 30° (clockwise from North) is yaw 60°; a baseline pointing left (+90° in
    # body axes) means the body points 90° clockwise of it.
    yaw, sig = al.yaw_from_heading(30 * DEG, 0.01)
    assert yaw == pytest.approx(60 * DEG) and sig == 0.01
    yaw, _ = al.yaw_from_heading(30 * DEG, 0.01, baseline_yaw_b=90 * DEG)
    assert yaw == pytest.approx(-30 * DEG)
    res = al.initial_attitude(0.01, -0.02, yaw, 1e-3, 0.01)
    np.testing.assert_allclose(quat_to_euler(res.q_nb), [0.01, -0.02, -30 * DEG], atol=1e-12)
    np.testing.assert_allclose(np.sqrt(np.diag(res.cov_phi)), [1e-3, 1e-3, 0.01])


@pytest.mark.parametrize("method,max_iter", [("cp", 22), ("mp", 18)])
def test_steepest_descent_converges_to_closed_form(method, max_iter):
    """Seed 002 start (60°, 60°, 45° from the truth): converge within the paper's counts."""
    dth, dvs, _ = static_increments(10.0, 0.1)
    init = np.array(TRUE_RPY) + np.array([60.0, 60.0, 45.0]) * DEG
    res = al.steepest_descent_alignment(dth, dvs, 0.1, init, method=method,
                                        tol=np.radians(0.01))
    assert res.iterations <= max_iter
    err = phi_of(res.q_nb, quat_from_euler(*TRUE_RPY))
    assert np.abs(err).max() < np.radians(0.01)
    exact = al.steepest_descent_alignment(dth, dvs, 0.1, init, method=method, tol=1e-12)
    assert np.abs(phi_of(exact.q_nb, quat_from_euler(*TRUE_RPY))).max() < 1e-9


def test_steepest_descent_fixes_180_degree_heading():
    dth, dvs, _ = static_increments(10.0, 0.1)
    init = np.array(TRUE_RPY) + np.array([0.0, 0.0, 170.0]) * DEG
    res = al.steepest_descent_alignment(dth, dvs, 0.1, init, method="cp", tol=1e-10)
    assert quat_to_euler(res.q_nb)[2] == pytest.approx(TRUE_RPY[2], abs=1e-8)


def test_steepest_descent_equals_coarse_with_sensor_errors():
    dt = 0.1
    dth_m, dv_m, _, _ = realised(se.TACTICAL, 300.0, dt, 1, 2)
    coarse = al.coarse_alignment(dth_m[0], dv_m[0], dt, LAT)
    it = al.steepest_descent_alignment(dth_m[0], dv_m[0], dt, (0.3, -0.3, 1.0), tol=1e-12)
    assert np.abs(phi_of(it.q_nb, coarse.q_nb)).max() < 1e-9


def test_navigator_heading_alignment_from_motion_and_heading_fix():
    q0 = np.array([1.0, 0.0, 0.0, 0.0])  # body x east, yaw 0
    # INS velocity 30 deg clockwise of the GNSS course: turn the solution by +30 deg.
    v_gnss = np.array([10.0 * np.cos(60 * DEG), 10.0 * np.sin(60 * DEG), 0.0])
    v_ins = np.array([10.0 * np.cos(30 * DEG), 10.0 * np.sin(30 * DEG), 0.0])
    cov = np.eye(3) * 0.1 ** 2
    delta, sigma, gain = al.yaw_error_from_motion(v_gnss, cov, v_ins, q0)
    assert delta == pytest.approx(30 * DEG) and sigma == pytest.approx(0.01)
    # d course / d v at the INS velocity: across it, over its speed
    np.testing.assert_allclose(gain, [-np.sin(30 * DEG) / 10, np.cos(30 * DEG) / 10, 0.0])
    # Too slow an INS (motion started before the filter): the body x axis is compared, with
    # the side slip it may have.
    delta, sigma, gain = al.yaw_error_from_motion(v_gnss, cov, 0.1 * v_ins, q0)
    assert delta == pytest.approx(60 * DEG) and gain is None
    assert sigma == pytest.approx(np.hypot(0.01, al.SIDE_SLIP_SIGMA))
    delta, sigma = al.yaw_error_from_heading(0.0, 1e-4, q0)  # heading north
    assert delta == pytest.approx(90 * DEG) and sigma == pytest.approx(0.01)


def test_levelled_start_and_yaw_rotation():
    from ins_gnss_ros.nav.ekf import StateSpace
    from ins_gnss_ros.nav.error_model import make_layout

    f_b = quat_to_dcm(quat_from_euler(0.02, -0.01, 0.0)).T @ [0.0, 0.0, 9.8]
    levelling = al.Levelling().add(np.zeros((100, 3)), np.tile(f_b * 0.01, (100, 1)), 0.01)
    assert levelling.time == pytest.approx(1.0)
    lever = np.zeros(3)
    st = al.levelled_state(levelling, 0.8, 0.1, 10.0, lever, 2.0, 5.0)
    np.testing.assert_allclose(quat_to_euler(st.q_nb), [0.02, -0.01, 0.0], atol=1e-12)
    np.testing.assert_allclose(np.linalg.norm(st.v_enu), 2.0)  # moving along body x
    assert st.v_enu[2] == 0.0  # over the ground: the receiver's speed is horizontal
    noise = se.filter_noise(se.MEMS_ADIS16405, "rw")
    space = StateSpace(make_layout("15", noise))
    P = al.initial_covariance(space, noise, 1.0, 0.1, 0.02)
    assert P[space["att"], space["att"]][2, 2] == 0.0  # yaw out of the filter
    st2, P2 = al.rotate_yaw(st, P, space, 90 * DEG, 0.001, 0.02)
    np.testing.assert_allclose(quat_to_euler(st2.q_nb)[2], 90 * DEG, atol=1e-9)
    assert P2[space["att"].stop - 1, space["att"].stop - 1] == pytest.approx(0.02 ** 2)


def test_a_start_on_the_move_levelled_on_an_acceleration_starts_level():
    """Levelled while speeding up at 1 m/s^2, the body x axis comes out pitched by about 5.8
    deg: the start's velocity is still the receiver's speed over the ground, along that axis's
    horizontal direction, not 1 m/s up or down it (the filter took such a climb for 160 mg of
    z accelerometer bias)."""
    f_b = np.array([1.0, 0.0, 9.8])  # level, accelerating forward
    levelling = al.Levelling().add(np.zeros((100, 3)), np.tile(f_b * 0.01, (100, 1)), 0.01)
    st = al.levelled_state(levelling, 0.8, 0.1, 10.0, np.zeros(3), 10.0, 5.0)
    assert abs(quat_to_euler(st.q_nb)[1]) == pytest.approx(np.arctan2(1.0, 9.8))
    x = quat_to_dcm(st.q_nb)[:, 0]
    np.testing.assert_allclose(st.v_enu, 10.0 * np.append(x[:2] / np.hypot(*x[:2]), 0.0),
                               atol=1e-12)


def test_a_start_on_the_move_up_a_grade_climbs_as_the_receiver_says():
    """At 10 m/s up an 8 % grade, levelled at a steady speed: the body x axis pitches with the
    road, and the start climbs at the receiver's 0.8 m/s (it was held level: 8 sigma of the
    start's 0.1 m/s)."""
    grade = np.arctan(0.08)
    f_b = 9.8 * np.array([np.sin(grade), 0.0, np.cos(grade)])  # gravity's share along x
    levelling = al.Levelling().add(np.zeros((100, 3)), np.tile(f_b * 0.01, (100, 1)), 0.01)
    st = al.levelled_state(levelling, 0.8, 0.1, 10.0, np.zeros(3), 9.97, 5.0, climb=0.8)
    assert quat_to_euler(st.q_nb)[1] == pytest.approx(-grade)  # REP-103: nose up
    x = quat_to_dcm(st.q_nb)[:, 0]
    np.testing.assert_allclose(st.v_enu, np.append(9.97 * x[:2] / np.hypot(*x[:2]), 0.8),
                               atol=1e-12)


def test_the_start_couples_the_imus_place_to_an_uncertain_lever_arm():
    """The IMU starts at the first fix less C l: with the lever arm uncertain (consider blocks,
    true minus configured), its position errs by the start's own error plus C dl, so the
    start's covariance of (position, lever arm) is that of (e + C dl, dl)."""
    from ins_gnss_ros.nav.ekf import ExtraState, StateSpace
    from ins_gnss_ros.nav.error_model import make_layout

    noise = se.filter_noise(se.MEMS_ADIS16405, "rw")
    space = StateSpace(make_layout("15", noise), {
        "lever_x": ExtraState(1, 0.3, consider=True), "lever_z": ExtraState(1, 1.0, consider=True)})
    q = quat_from_euler(0.1, -0.2, 0.7)
    P = al.initial_covariance(space, noise, 0.5, 0.1, 0.02)
    al.couple_start_to_lever_arm(P, space, q)
    C = quat_to_dcm(q)
    # (e, dl_x, dl_z) independent, position error e + C[:, 0] dl_x + C[:, 2] dl_z
    A = np.hstack([np.eye(3), C[:, [0]], C[:, [2]]])
    expected = A @ np.diag([0.25, 0.25, 0.25, 0.09, 1.0]) @ A.T
    pos, x, z = space["pos"], space["lever_x"].start, space["lever_z"].start
    np.testing.assert_allclose(P[pos, pos], expected, atol=1e-15)
    np.testing.assert_allclose(P[pos, x], 0.09 * C[:, 0], atol=1e-15)
    np.testing.assert_allclose(P[pos, z], C[:, 2], atol=1e-15)
    np.testing.assert_array_equal(P, P.T)
    assert np.linalg.eigvalsh(P).min() > -1e-12


def test_the_levelled_tilt_errs_with_the_accelerometer_biases():
    """Levelling on a standing IMU whose accelerometers err by b takes the attitude that makes
    the measured specific force vertical: its tilt error (nav_error of the levelled against
    the true attitude) is the biases', drawn here from the grade and compared with the start's
    covariance of (tilt, bias)."""
    from ins_gnss_ros.nav.ekf import StateSpace
    from ins_gnss_ros.nav.error_model import make_layout, nav_error
    from ins_gnss_ros.nav.strapdown import NavState

    noise = se.filter_noise(se.MEMS_ADIS16405_DATASHEET, "rw")  # 50 mg
    space = StateSpace(make_layout("15", noise))
    att, ba = space["att"], space["ba"]
    tilt = slice(att.start, att.start + 2)
    lat, g = 0.9, normal_gravity(0.9, 0.0)
    true_q = quat_from_euler(0.03, -0.05, 2.0)  # a vehicle standing on a slope, yawed
    rng = np.random.default_rng(8)
    sigma_level = 1.0 * DEG
    draws = []
    for _ in range(4000):
        b = noise.blocks["ba"].sigma0 * rng.standard_normal(3)
        f_b = quat_to_dcm(true_q).T @ [0.0, 0.0, g] + b
        levelling = al.Levelling().add(np.zeros((1, 3)), f_b[None, :], 1.0)
        est = al.levelled_state(levelling, lat, 0.1, 0.0, np.zeros(3), 0.0, 0.0)
        # the levelled attitude carries no yaw: compare with the truth turned to its yaw
        true = NavState(lat, 0.1, 0.0, np.zeros(3), quat_mul(
            quat_from_euler(0.0, 0.0, -quat_to_euler(true_q)[2]), true_q), 0.0)
        phi = nav_error(est, true)[2]
        draws.append(np.concatenate([phi[:2] + sigma_level * rng.standard_normal(2), b]))
    # the filter's bias state is the bias the estimate (zero) lacks: b
    f_b = quat_to_dcm(true_q).T @ [0.0, 0.0, g]
    est = al.levelled_state(al.Levelling().add(np.zeros((1, 3)), f_b[None, :], 1.0),
                            lat, 0.1, 0.0, np.zeros(3), 0.0, 0.0)
    P = al.initial_covariance(space, noise, 1.0, 0.1, sigma_level)
    al.couple_tilt_to_accelerometers(P, space, est, f_b, sigma_level)
    sample = np.cov(np.array(draws).T)
    model = np.block([[P[tilt, tilt], P[tilt, ba]], [P[ba, tilt], P[ba, ba]]])
    np.testing.assert_allclose(np.sqrt(np.diag(sample)), np.sqrt(np.diag(model)), rtol=0.05)
    corr = sample[:2, 2:4] / np.sqrt(np.outer(np.diag(sample)[:2], np.diag(sample)[2:4]))
    corr_model = model[:2, 2:4] / np.sqrt(np.outer(np.diag(model)[:2], np.diag(model)[2:4]))
    np.testing.assert_allclose(corr, corr_model, atol=0.05)
    assert abs(corr_model).max() > 0.9  # the tilt is the biases' to within the levelling's 1 deg
    assert np.linalg.eigvalsh(P).min() > -1e-12


def test_yaw_rotation_correlates_the_turned_velocity_and_distance_with_the_yaw():
    """An INS that ran from rest with its yaw off by a: turning it by a + eps (a slightly
    wrong alignment) leaves velocity and position errors that the covariance predicts from
    the yaw error phi_U = -eps (its regression on phi_U: P[x, yaw] / P[yaw, yaw])."""
    from ins_gnss_ros.nav.ekf import StateSpace
    from ins_gnss_ros.nav.error_model import make_layout
    from ins_gnss_ros.nav.measurements import position_residual_enu
    from ins_gnss_ros.nav.strapdown import NavState, apply_correction

    noise = se.filter_noise(se.MEMS_ADIS16405, "rw")
    space = StateSpace(make_layout("15", noise))
    P = al.initial_covariance(space, noise, 0.3, 0.1, 0.02)
    a, eps, sigma = 150 * DEG, 0.03, 0.03
    v_true, d_true = np.array([6.0, -3.0, 0.0]), np.array([15.0, -8.0, 0.0])
    turn = quat_to_dcm(quat_from_euler(0.0, 0.0, -a))
    rest = NavState(0.8, 0.1, 10.0, np.zeros(3), quat_from_euler(0.0, 0.0, 0.0), 0.0)
    ins = apply_correction(rest, -turn @ d_true, np.zeros(3), np.zeros(3))
    ins = NavState(ins.lat, ins.lon, ins.h, turn @ v_true, quat_from_euler(0.0, 0.0, -a), 5.0)
    st, P2 = al.rotate_yaw(ins, P, space, a + eps, sigma, 0.0, (rest.lat, rest.lon, rest.h))
    k = space["att"].stop - 1
    phi_u = -eps
    predicted = P2[:, k] / P2[k, k] * phi_u
    np.testing.assert_allclose(st.v_enu - v_true, predicted[space["vel"]], atol=0.01)
    d = position_residual_enu(st.lat, st.lon, st.h, rest.lat, rest.lon, rest.h)
    np.testing.assert_allclose(d - d_true, predicted[space["pos"]], atol=0.02)
    assert np.linalg.norm(d - d_true) > 0.4  # the test sees the turned distance's error


def _moving_ins(space, noise, v_ins, P_vv):
    """A levelled INS moving at v_ins (ENU) whose velocity covariance is P_vv, and its P."""
    from ins_gnss_ros.nav.strapdown import NavState

    P = al.initial_covariance(space, noise, 0.3, 0.1, 0.02)
    P[space["vel"], space["vel"]] = P_vv
    return NavState(0.8, 0.1, 10.0, np.asarray(v_ins, float),
                    quat_from_euler(0.0, 0.0, 0.0), 5.0), P


def test_motion_alignment_yaw_sigma_carries_both_velocities():
    """Course east at 5 m/s from a velocity of sigma s1, INS velocity north of sigma s2: the
    yaw's sigma is sqrt(s1^2 + s2^2) / 5, each velocity's cross-track error over the speed."""
    from ins_gnss_ros.nav.ekf import StateSpace
    from ins_gnss_ros.nav.error_model import make_layout

    noise = se.filter_noise(se.MEMS_ADIS16405, "rw")
    space = StateSpace(make_layout("15", noise))
    s1, s2 = 0.3, 0.2
    ins, P = _moving_ins(space, noise, [0.0, 5.0, 0.0], np.eye(3) * s2 ** 2)
    delta, sigma, gain = al.yaw_error_from_motion([5.0, 0.0, 0.0], np.eye(3) * s1 ** 2,
                                                  ins.v_enu, ins.q_nb)
    assert delta == pytest.approx(-90 * DEG) and sigma == pytest.approx(s1 / 5.0)
    _, P2 = al.rotate_yaw(ins, P, space, delta, sigma, 0.0, velocity_gain=gain)
    k = space["att"].stop - 1
    assert np.sqrt(P2[k, k]) == pytest.approx(np.hypot(s1, s2) / 5.0)
    # The turned INS velocity points along the course: its cross-track (north) error is the
    # course's, its along-track (east) error the INS's own.
    vel = space["vel"]
    np.testing.assert_allclose(np.diag(P2[vel, vel])[:2], [s2 ** 2, s1 ** 2])
    # The floor tops the yaw up, no further.
    _, P3 = al.rotate_yaw(ins, P, space, delta, sigma, 0.2, velocity_gain=gain)
    assert np.sqrt(P3[k, k]) == pytest.approx(0.2)


def test_motion_alignment_covariance_matches_monte_carlo_errors():
    """Against truth: INS velocity errors and GNSS velocity noise drawn from their
    covariances, an arbitrary true yaw; the yaw, velocity and cross-correlation errors after
    the motion alignment scatter as rotate_yaw's covariance says."""
    from ins_gnss_ros.nav.ekf import StateSpace
    from ins_gnss_ros.nav.error_model import make_layout

    noise = se.filter_noise(se.MEMS_ADIS16405, "rw")
    space = StateSpace(make_layout("15", noise))
    rng = np.random.default_rng(11)
    v_true = np.array([4.0, 3.0, 0.0])                       # 5 m/s, true yaw along it
    S_g = np.array([[0.09, 0.03, 0.0], [0.03, 0.05, 0.0], [0.0, 0.0, 0.2]])
    P_vv = np.array([[0.02, -0.01, 0.0], [-0.01, 0.06, 0.0], [0.0, 0.0, 0.01]])
    true_yaw = np.arctan2(v_true[1], v_true[0])
    idx = [space["att"].stop - 1, space["vel"].start, space["vel"].start + 1]
    errors, claimed = [], []
    for _ in range(4000):
        wrong = rng.uniform(-np.pi, np.pi)                   # the INS's yaw before alignment
        # the INS's velocity error is P_vv in the true axes, turned with its yaw
        turn = quat_to_dcm(quat_from_euler(0.0, 0.0, wrong - true_yaw))
        v_ins = turn @ (v_true + rng.multivariate_normal(np.zeros(3), P_vv))
        v_gnss = v_true + rng.multivariate_normal(np.zeros(3), S_g)
        ins, P = _moving_ins(space, noise, v_ins, turn @ P_vv @ turn.T)
        ins = ins.__class__(ins.lat, ins.lon, ins.h, v_ins, quat_from_euler(0.0, 0.0, wrong),
                            ins.t)
        delta, sigma, gain = al.yaw_error_from_motion(v_gnss, S_g, v_ins, ins.q_nb)
        st, P2 = al.rotate_yaw(ins, P, space, delta, sigma, 0.0, velocity_gain=gain)
        phi_u = -np.angle(np.exp(1j * (quat_to_euler(st.q_nb)[2] - true_yaw)))
        errors.append([phi_u, *(st.v_enu - v_true)[:2]])
        claimed.append(P2[np.ix_(idx, idx)])
    errors, claimed = np.array(errors), np.array(claimed)
    nees = np.einsum("ni,ni->n", errors, np.linalg.solve(claimed, errors[:, :, None])[:, :, 0])
    # chi-square of 3 degrees of freedom, mean of 4000: 3 +- 0.04 (1 sigma)
    assert 2.85 < nees.mean() < 3.15, nees.mean()
    mean = claimed.mean(axis=0)
    sd = np.sqrt(np.diag(mean))
    np.testing.assert_allclose(np.cov(errors.T) / np.outer(sd, sd), mean / np.outer(sd, sd),
                               atol=0.06)


def _chord(rng, v_true, a_true, sigma_fix, jerk_sigma):
    """Two fixes 2 s apart about the mid-epoch 0 of a vehicle at v_true, a_true and a drawn
    constant jerk (ENU), made into a course velocity by CourseFromFixes: the velocity, and the
    true position offsets of the fixes from the mid-epoch."""
    from ins_gnss_ros.nav.course import CourseFromFixes

    jerk = np.r_[jerk_sigma * rng.standard_normal(2), 0.0]
    course, out = CourseFromFixes(), None
    for t in (-1.0, 1.0):
        p = v_true * t + 0.5 * a_true * t * t + jerk * t ** 3 / 6.0
        out = course.add(t, *_geodetic(p + sigma_fix * rng.standard_normal(3)),
                         np.eye(3) * sigma_fix ** 2)
    return out


def _geodetic(enu):
    """lat, lon, h (rad, rad, m) of a point ENU (m) about ORIGIN."""
    from ins_gnss_ros.nav.earth import ecef_to_geodetic, enu_to_ecef

    return tuple(float(x) for x in ecef_to_geodetic(enu_to_ecef(np.asarray(enu, float),
                                                                 *ORIGIN)))


#: lat, lon (rad), h (m) of the Monte Carlo vehicle's position at the mid-epoch
ORIGIN = (0.8, 0.1, 10.0)


def _chord_alignment(rng, space, noise, correlated):
    """One draw of the alignment on a course velocity (rotate_yaw on it, then its fixes,
    fixes_with_course; ``correlated=False`` treats them as independent fixes instead): the
    errors against truth after the update of [yaw, velocity E N, position E N] and their
    claimed covariance."""
    from ins_gnss_ros.nav.measurements import position_residual_enu
    from ins_gnss_ros.nav.strapdown import NavState

    v_true, a_true = np.array([8.0, 6.0, 0.0]), np.array([1.0, -0.5, 0.0])
    true_yaw = np.arctan2(v_true[1], v_true[0])
    m = _chord(rng, v_true, a_true, 0.5, al.EXTRAPOLATION_JERK)
    wrong = rng.uniform(-np.pi, np.pi)
    turn = quat_to_dcm(quat_from_euler(0.0, 0.0, wrong - true_yaw))
    P = al.initial_covariance(space, noise, 1.0, 0.1, 0.02)
    P_vv = np.diag([0.04, 0.04, 0.01])
    P[space["vel"], space["vel"]] = P_vv
    dp = np.r_[rng.standard_normal(2), 0.0]  # 1 m, isotropic: unchanged by the turn
    ins = NavState(*_geodetic(dp), turn @ (v_true + rng.multivariate_normal(np.zeros(3), P_vv)),
                   quat_from_euler(0.0, 0.0, wrong), 0.0)
    delta, sigma, gain = al.yaw_error_from_motion(m.v_enu, m.cov_enu, ins.v_enu, ins.q_nb)
    st, P2 = al.rotate_yaw(ins, P, space, delta, sigma, 0.0, velocity_gain=gain)
    G = al.course_error_gain(st, space, m.v_enu) if correlated else \
        np.zeros((space.size, 3))
    innov = al.fixes_with_course(space, st, P2, m.fixes, [f.t for f, _ in m.fixes], G, a_true,
                                 np.zeros(3), np.zeros(3))
    S = innov.H @ P2 @ innov.H.T + innov.R
    K = np.linalg.solve(S, innov.H @ P2).T
    dx, P3 = K @ innov.z, P2 - K @ S @ K.T
    # errors, estimate minus truth (the yaw's as phi_U: truth minus estimate), the estimated
    # errors dx taken off
    yaw_est = quat_to_euler(st.q_nb)[2]
    p_est = position_residual_enu(st.lat, st.lon, st.h, *ORIGIN)[:2]
    idx = [space["att"].stop - 1, *range(space["vel"].start, space["vel"].start + 2),
           *range(space["pos"].start, space["pos"].start + 2)]
    err = np.r_[-np.angle(np.exp(1j * (yaw_est - true_yaw))), (st.v_enu - v_true)[:2],
                p_est] - dx[idx]
    return err, P3[np.ix_(idx, idx)]


def test_alignment_on_a_course_from_fixes_matches_monte_carlo_errors():
    """Against truth: two noisy fixes of a vehicle accelerating with a drawn jerk make the
    course (nav/course.py) an INS of arbitrary yaw is turned onto; its fixes then update it
    (fixes_with_course). The yaw, velocity and position errors after that scatter as the
    covariance says (NEES of 5 states ~5); taking the same fixes as independent of the course
    (the old treatment) claims a yaw far better than it is."""
    from ins_gnss_ros.nav.ekf import StateSpace
    from ins_gnss_ros.nav.error_model import make_layout

    noise = se.filter_noise(se.MEMS_ADIS16405, "rw")
    space = StateSpace(make_layout("15", noise))
    for correlated, seed in ((True, 5), (False, 5)):
        rng = np.random.default_rng(seed)
        draws = [_chord_alignment(rng, space, noise, correlated) for _ in range(2000)]
        errors = np.array([e for e, _ in draws])
        claimed = np.array([c for _, c in draws])
        yaw_z = np.sqrt(np.mean(errors[:, 0] ** 2 / claimed[:, 0, 0]))
        nees = np.einsum("ni,ni->n", errors,
                         np.linalg.solve(claimed, errors[:, :, None])[:, :, 0]).mean()
        if correlated:
            # chi-square of 5 degrees of freedom, mean of 2000: 5 +- 0.07 (1 sigma)
            assert 4.75 < nees < 5.25 and 0.93 < yaw_z < 1.07, (nees, yaw_z)
        else:
            assert nees > 5.5 and yaw_z > 1.2, (nees, yaw_z)


def test_restart_on_a_course_keeps_the_velocity_correlated_with_the_yaw():
    """Against truth: a start on the move without a receiver speed (the INS velocity
    uninformed) takes both the yaw (body x on the course, a drawn side-slip) and the velocity
    from one course velocity: their errors scatter as the covariance after rotate_yaw and
    restart_velocity says (NEES of yaw and horizontal velocity ~3), which needs the
    correlation of the two."""
    from ins_gnss_ros.nav.ekf import StateSpace
    from ins_gnss_ros.nav.error_model import make_layout
    from ins_gnss_ros.nav.strapdown import NavState

    noise = se.filter_noise(se.MEMS_ADIS16405, "rw")
    space = StateSpace(make_layout("15", noise))
    rng = np.random.default_rng(3)
    v_true = np.array([-6.0, 8.0, 0.0])
    idx = [space["att"].stop - 1, space["vel"].start, space["vel"].start + 1]
    errors, claimed = [], []
    for _ in range(3000):
        m = _chord(rng, v_true, np.zeros(3), 0.5, al.EXTRAPOLATION_JERK)
        true_yaw = np.arctan2(v_true[1], v_true[0]) + al.SIDE_SLIP_SIGMA * rng.standard_normal()
        P = al.initial_covariance(space, noise, 1.0, 30.0, 0.02)
        ins = NavState(*ORIGIN, np.zeros(3), quat_from_euler(0.0, 0.0, rng.uniform(-3, 3)), 0.0)
        delta, sigma = al.yaw_error_from_course(m.v_enu, m.cov_enu, ins.q_nb)
        st, P2 = al.rotate_yaw(ins, P, space, delta, sigma, 0.0)
        gain = al.course_error_gain(st, space, m.v_enu, restarted=True)
        st, P2 = al.restart_velocity(st, P2, space, m.v_enu, m.cov_enu, gain)
        errors.append([-np.angle(np.exp(1j * (quat_to_euler(st.q_nb)[2] - true_yaw))),
                       *(st.v_enu - v_true)[:2]])
        claimed.append(P2[np.ix_(idx, idx)])
    errors, claimed = np.array(errors), np.array(claimed)
    nees = np.einsum("ni,ni->n", errors, np.linalg.solve(claimed, errors[:, :, None])[:, :, 0])
    # chi-square of 3 degrees of freedom, mean of 3000: 3 +- 0.045 (1 sigma)
    assert 2.85 < nees.mean() < 3.15, nees.mean()
    # the mean NEES does not see a correlation left out; the correlation matrix does (the
    # yaw's with the cross-track velocity is about -0.6 here)
    mean = claimed.mean(axis=0)
    sd = np.sqrt(np.diag(mean))
    np.testing.assert_allclose(np.cov(errors.T) / np.outer(sd, sd), mean / np.outer(sd, sd),
                               atol=0.06)
