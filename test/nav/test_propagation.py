"""The navigator's time update of a segment (nav/propagation.py): its compiled loop
(_kernels.mech_segment) against the two modules it stands for, SensorErrors.compensate (then
the "nz" cross-axis terms taken out) and strapdown.run, the compiled sum of its steps against
numpy's, the whole compiled step (_kernels.time_update) against that loop and the filter's own
prediction (ErrorStateEKF.predict), and the attitude variance of a turn (turn_noise) against
the errors of drawn gyro triads."""
import numpy as np

from ins_gnss_ros.nav import _kernels
from ins_gnss_ros.nav.earth import WGS84
from ins_gnss_ros.nav.ekf import ErrorStateEKF, ExtraState, StateSpace
from ins_gnss_ros.nav.error_model import make_layout
from ins_gnss_ros.nav.imu_gaps import BridgedGaps
from ins_gnss_ros.nav.increments import SensorErrors
from ins_gnss_ros.nav.propagation import TURN_TIME, propagate, turn_noise
from ins_gnss_ros.nav.rewind import RunState
from ins_gnss_ros.nav.sensor_errors import GRADES, error_matrix, filter_noise
from ins_gnss_ros.nav.strapdown import NavState, run


def test_the_compiled_segment_equals_compensation_then_mechanisation():
    rng = np.random.default_rng(7)
    start = NavState(0.9, 0.5, 120.0, np.array([12.0, -3.0, 0.4]),
                     np.array([0.9, 0.1, -0.2, 0.37]) / np.linalg.norm([0.9, 0.1, -0.2, 0.37]),
                     0.0)
    n = 20
    dts = 0.005 + 1e-4 * rng.standard_normal(n)
    th = rng.normal(0.0, 2e-3, (n, 3))
    dv = rng.normal(0.0, 5e-2, (n, 3)) + np.array([0.0, 0.0, 9.8]) * dts[:, None]
    cth, cdv = rng.normal(0.0, 1e-7, (n, 3)), rng.normal(0.0, 1e-6, (n, 3))
    errors = SensorErrors(gyro_bias=np.array([1e-3, -2e-3, 5e-4]),
                          accel_bias=np.array([0.05, -0.02, 0.1]),
                          gyro_scale=np.array([1e-3, -5e-4, 2e-3]),
                          accel_scale=np.array([-1e-3, 2e-3, 5e-4]))
    cross_z = np.array([0.02, -0.015])  # the z accelerometer reading x and y ("nz")
    dt = float(dts.sum()) / n

    c_th, c_dv = errors.compensate(th, dv, dts)
    c_dv[:, 2] -= c_dv[:, :2] @ cross_z
    ref = run(start, c_th + cth, c_dv + cdv, dt)

    v, q, sums = start.v_enu.copy(), start.q_nb.copy(), np.empty((2, 3))
    track = np.full((n - 1, 10), np.nan)  # the solution after each sample but the last
    lat, lon, h = _kernels.mech_segment(start.lat, start.lon, start.h, v, q, th, dv, cth, cdv,
                                        dts, errors.gyro_bias, errors.gyro_scale,
                                        errors.accel_bias, errors.accel_scale, cross_z,
                                        dt, WGS84.kernel_params, sums, track)
    np.testing.assert_allclose([lat, lon], [ref["lat"][-1], ref["lon"][-1]], rtol=0, atol=1e-14)
    assert len(ref["lat"]) == n + 1  # the start, then after each sample
    np.testing.assert_allclose(track[:, :2], np.column_stack([ref["lat"], ref["lon"]])[1:n],
                               rtol=0, atol=1e-14)
    np.testing.assert_allclose(track[:, 2], ref["h"][1:n], rtol=0, atol=1e-9)
    np.testing.assert_allclose(track[:, 3:6], ref["v_enu"][1:n], rtol=0, atol=1e-12)
    np.testing.assert_allclose(track[:, 6:], ref["q_nb"][1:n], rtol=0, atol=1e-14)
    np.testing.assert_allclose(h, ref["h"][-1], rtol=0, atol=1e-9)
    np.testing.assert_allclose(v, ref["v_enu"][-1], rtol=0, atol=1e-12)
    np.testing.assert_allclose(q, ref["q_nb"][-1], rtol=0, atol=1e-14)
    np.testing.assert_allclose(sums, [c_th.sum(axis=0), c_dv.sum(axis=0)], rtol=0, atol=1e-15)


def test_the_compiled_sum_is_numpys_bit_for_bit():
    # Every length up to past two of numpy's 128-value blocks, steps as the IMU's jitter them.
    rng = np.random.default_rng(11)
    for n in range(1, 300):
        for _ in range(5):
            a = 0.005 + 1e-4 * rng.standard_normal(n)
            assert _kernels.numpy_sum(a) == a.sum()


def test_the_compiled_time_update_is_the_segment_loop_then_the_filter_prediction():
    # Bit for bit: the navigator's decisions (gates, modes) can hinge on the last bit.
    rng = np.random.default_rng(3)
    # Gauss-Markov, clock and extra blocks: the model's constant terms are in F too.
    noise = filter_noise(GRADES["mems_adis16405"])
    space = StateSpace(make_layout(("pos", "vel", "att", "bg", "ba", "gmg", "gma", "sg", "sa",
                                    "nz", "clock"), noise),
                       {"td": ExtraState(1, 0.01, 1e-6, 50.0)})
    q0 = np.array([0.9, 0.1, -0.2, 0.37]) / np.linalg.norm([0.9, 0.1, -0.2, 0.37])
    start = NavState(0.9, 0.5, 120.0, np.array([12.0, -3.0, 0.4]), q0, 0.0)
    P0 = np.diag(rng.uniform(1e-6, 1.0, space.size))
    n = 10
    t = 0.01 * np.arange(1, n + 1) + 1e-4 * rng.standard_normal(n)
    th = rng.normal(0.0, 2e-3, (n, 3))
    dv = rng.normal(0.0, 5e-2, (n, 3)) + np.array([0.0, 0.0, 0.098])
    cth, cdv = rng.normal(0.0, 1e-7, (n, 3)), rng.normal(0.0, 1e-6, (n, 3))
    estimates = {"bg": np.array([1e-3, -2e-3, 5e-4]), "ba": np.array([0.05, -0.02, 0.1]),
                 "sg": np.array([1e-3, -5e-4, 2e-3]), "sa": np.array([-1e-3, 2e-3, 5e-4]),
                 "nz": np.array([0.02, -0.015])}

    s = RunState(nav=start, ekf=ErrorStateEKF(space, noise, P0), estimates=dict(estimates))
    track = np.empty((n - 1, 10))
    phi = propagate(s, (t, th, dv, cth, cdv), noise, 0.1, BridgedGaps(1.0, 0.1), space, track)

    errors = SensorErrors.of_estimates(estimates)
    dts = np.diff(t, prepend=0.0)
    T = float(dts.sum())
    v, q, sums = start.v_enu.copy(), start.q_nb.copy(), np.empty((2, 3))
    track_ref = np.empty((n - 1, 10))
    lat, lon, h = _kernels.mech_segment(start.lat, start.lon, start.h, v, q, th, dv, cth, cdv,
                                        dts, errors.gyro_bias, errors.gyro_scale,
                                        errors.accel_bias, errors.accel_scale,
                                        estimates["nz"], T / n, WGS84.kernel_params, sums,
                                        track_ref)
    ekf = ErrorStateEKF(space, noise, P0)
    phi_ref = ekf.predict(start, sums[1] / T, sums[0] / T, T)
    # then the turn's attitude variance of the gyros' cross-axis errors (no "ng" block here)
    turn_noise(RunState(nav=s.nav, ekf=ekf, omega=sums[0] / T, omega_time=T), noise, space)
    assert (s.nav.lat, s.nav.lon, s.nav.h, s.nav.t) == (lat, lon, h, t[-1])
    assert np.array_equal(s.nav.v_enu, v) and np.array_equal(s.nav.q_nb, q)
    assert np.array_equal(s.a_enu, (v - start.v_enu) / T)
    assert np.array_equal(s.omega, sums[0] / T)
    assert np.array_equal(phi, phi_ref) and np.array_equal(s.ekf.P, ekf.P)
    assert np.array_equal(track, track_ref)


def test_a_bridged_gap_adds_its_variance_over_the_time_spent_in_it():
    space = StateSpace(make_layout(("pos", "vel", "att"), filter_noise(GRADES["tactical"])))
    gaps = BridgedGaps(accel_sigma=2.0, rate_sigma=0.1)
    gaps.add(10.0, 10.5, horizon=0.0)                                  # held by the caller
    gaps.add(20.0, 20.01, horizon=0.0, angle_var=4e-8, velocity_var=9e-6)  # interpolated
    vel, att = space["vel"], space["att"]

    def added(t0, t1, yaw_known=True):
        P = np.zeros((space.size, space.size))
        gaps.add_noise(P, space, t0, t1, yaw_known)
        return np.diag(P)[vel], np.diag(P)[att]

    v, a = added(9.0, 11.0)                       # the whole held gap: (sigma T)^2
    np.testing.assert_allclose(v, (2.0 * 0.5) ** 2)
    np.testing.assert_allclose(a, (0.1 * 0.5) ** 2)
    v, a = added(10.0, 10.25)                     # half of it: half
    np.testing.assert_allclose(v, 0.5 * (2.0 * 0.5) ** 2)
    v, a = added(19.9, 20.1, yaw_known=False)     # the interpolated sample, yaw out of P
    np.testing.assert_allclose(v, 9e-6)
    np.testing.assert_allclose(a, [4e-8, 4e-8, 0.0])
    gaps.add(30.0, 30.01, horizon=25.0, angle_var=1e-8, velocity_var=1e-6)
    assert [g[0] for g in gaps.gaps] == [30.0]    # those ended before the horizon forgotten


def test_a_turn_adds_the_attitude_error_its_gyros_scale_and_cross_axis_errors_make():
    """A 90 deg turn about body z, then a 20 deg roll to and fro, against the attitude errors
    the gyros' drawn scale-factor and cross-axis errors make over the same rotations (the
    error matrix times the rotation, body axes; level, yaw 0, so body = nav)."""

    noise = filter_noise(GRADES["consumer_mems"], "rw")
    space = StateSpace(make_layout("15", noise))
    att = space["att"]
    s = RunState.initial(space)
    s.nav = NavState(0.9, 0.5, 0.0, np.zeros(3), np.array([1.0, 0.0, 0.0, 0.0]), 0.0)
    s.ekf = ErrorStateEKF(space, noise, np.zeros((space.size, space.size)))
    s.heading_known = True

    def turn(rate, seconds, steps=200):
        s.omega, s.omega_time = np.asarray(rate, float), seconds / steps
        for _ in range(steps):
            turn_noise(s, noise, space)

    theta = np.pi / 2
    turn([0.0, 0.0, theta / 4.0], 4.0)                 # 90 deg in 4 s, against TURN_TIME 10 s
    var = np.diag(s.ekf.P[att, att]).copy()
    rng = np.random.default_rng(3)
    g = GRADES["consumer_mems"].gyro
    M = error_matrix(g.scale_sigma * rng.standard_normal((20000, 3)),
                     g.misalign_sigma * rng.standard_normal((20000, 6)))
    errors = M @ np.array([0.0, 0.0, theta])            # what each drawn unit turns by
    # the whole turn's error, less what the memory lets go of during its 4 s
    truth = errors.var(axis=0)
    assert np.all(var <= 1.05 * truth) and np.all(var >= 0.95 * np.exp(-4.0 / TURN_TIME) * truth)
    # (yaw from the z gyro's 1.5 % scale, the tilts from the x and y gyros' 2 % cross-axis)
    # a roll of 20 deg to and fro: each swing adds what it turns, not the time spent rolling
    before = np.diag(s.ekf.P[att, att]).copy()
    for _ in range(5):
        turn([np.radians(20.0), 0.0, 0.0], 1.0, 20)
        turn([-np.radians(20.0), 0.0, 0.0], 1.0, 20)
    swing = (g.misalign_sigma * np.radians(20.0)) ** 2
    assert np.diag(s.ekf.P[att, att])[1] - before[1] < 10 * swing
    # with the heading unknown the yaw stays out of P
    s.ekf.P[:] = 0.0
    s.heading_known = False
    turn([0.0, 0.0, theta / 4.0], 4.0)
    assert s.ekf.P[att, att][2, 2] == 0.0 and s.ekf.P[att, att][0, 0] > 0.0
