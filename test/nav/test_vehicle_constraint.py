"""nav/vehicle_constraint.py: the non-holonomic constraint learned from the aided solution.

Analytic bodies (a car's velocity along its x axis, a ship's sway) and a simulated car drive
whose truth the navigator does not see: the learned constraint switches on and bounds the drift
of a GNSS outage as the configured one does.
"""
import numpy as np

from ins_gnss_ros.nav import vehicle_constraint as vc
from ins_gnss_ros.nav.ekf import ExtraState, at_prior
from ins_gnss_ros.nav.error_model import nav_error
from ins_gnss_ros.nav.rotations import quat_from_euler, quat_to_dcm

from test_navigator import config, gnss, run, simulate, truth_state


def feed(learner, seconds, velocity_b, yaw=0.7, t0=0.0, dt=0.1):
    """A body at heading `yaw` moving with `velocity_b` (FLU, callable of t) for `seconds`."""
    q = quat_from_euler(0.01, -0.02, yaw)
    for t in np.arange(t0 + dt, t0 + seconds + dt / 2, dt):
        learner.add(t, quat_to_dcm(q) @ velocity_b(t), q)
    return t0 + seconds


def test_a_body_moving_along_its_x_axis_is_constrained_after_the_learning_time():
    rng = np.random.default_rng(1)
    learner = vc.LearnedConstraint()
    t = feed(learner, 29.0, lambda t: np.array([8.0, *0.05 * rng.standard_normal(2)]))
    assert learner.sigma is None and "29 of 30 s" in learner.summary()
    feed(learner, 2.0, lambda t: np.array([8.0, *0.05 * rng.standard_normal(2)]), t0=t)
    assert learner.sigma == (vc.SIGMA_FLOOR, vc.SIGMA_FLOOR)  # 2 x 0.05 m/s: the floor
    np.testing.assert_allclose(np.abs(learner.axes), np.eye(3), atol=0.03)  # ~level body
    np.testing.assert_allclose(learner.rms(learner.axes), [0.05, 0.05], atol=0.01)
    assert learner.summary().startswith("on: travel along body (+1.000")


def test_any_mounting_reversing_included():
    """An IMU in its own axes, yawed 175 deg and pitched 7 deg from the vehicle (the real car
    drive's), the vehicle backing up a third of the time: the axis of travel is learned, and
    the velocity across it is what is constrained."""
    rng = np.random.default_rng(2)
    q_mount = quat_from_euler(0.0, np.radians(7.0), np.radians(175.0))
    axis = quat_to_dcm(q_mount).T @ np.array([1.0, 0.0, 0.0])  # vehicle x in the IMU's axes

    def velocity(t):
        speed = -3.0 if int(t) % 3 == 0 else 8.0
        return speed * axis + 0.05 * rng.standard_normal(3)
    learner = vc.LearnedConstraint()
    feed(learner, 60.0, velocity)
    axes = learner.axes
    assert axes[0] @ axis > 0.9999
    np.testing.assert_allclose(axes[1:] @ axis, 0.0, atol=2e-3)  # the noise moves it a little
    assert learner.sigma is not None and np.all(learner.rms(axes) < 0.07)
    assert "mounting_rpy_deg [0, 7.0, 175.0]" in learner.summary()


def test_the_mounting_that_puts_the_travel_on_base_link_x():
    """The imu_preprocessor's mounting (v_base_link = Rz(yaw) Ry(pitch) Rx(roll) v_imu) of the
    real car drive's IMU, and others, back from their base_link x axis in the IMU's axes."""
    from ins_gnss_ros.nav.rotations import dcm_from_euler
    for pitch_deg, yaw_deg in ((-6.79, 174.65), (0.0, 90.0), (30.0, -45.0), (-80.0, 10.0)):
        c_bs = dcm_from_euler(0.0, np.radians(pitch_deg), np.radians(yaw_deg))
        pitch, yaw = vc.mounting_from_travel(c_bs.T @ np.array([1.0, 0.0, 0.0]))
        np.testing.assert_allclose(np.degrees([pitch, yaw]), [pitch_deg, yaw_deg], atol=1e-9)


def test_sway_beyond_the_limit_is_not_constrained_and_releases_a_constrained_body():
    learner = vc.LearnedConstraint()
    t = feed(learner, 60.0, lambda t: np.array([5.0, 0.2 * np.sin(t), 0.0]))
    np.testing.assert_allclose(learner.rms(learner.axes), [0.2 / np.sqrt(2), 0.0], atol=0.01)
    np.testing.assert_allclose(learner.sigma, [2 * 0.2 / np.sqrt(2), vc.SIGMA_FLOOR], atol=0.02)
    feed(learner, 600.0, lambda t: np.array([5.0, 0.8 * np.sin(t), 0.0]), t0=t)  # a ship
    assert learner.sigma is None and learner.axes is None
    assert learner.summary().startswith("off:") and "lateral 0.5" in learner.summary()


def test_slow_motion_and_re_run_epochs_are_not_learned():
    learner = vc.LearnedConstraint()
    feed(learner, 100.0, lambda t: np.array([0.5, 0.3, 0.3]))     # below MIN_SPEED
    assert learner.moving == 0.0
    learner = vc.LearnedConstraint()
    t = feed(learner, 20.0, lambda t: np.array([5.0, 0.0, 0.0]))
    feed(learner, 10.0, lambda t: np.array([5.0, 0.0, 0.0]), t0=t - 10.0)  # a rewind re-runs
    assert np.isclose(learner.moving, 19.9)  # 200 epochs: the first stands for no time


def test_the_learned_constraint_bounds_a_simulated_outage_like_the_configured_one():
    """A simulated car (15 s static, then driving; MEMS IMU, lever arm) with 4 Hz fixes and
    velocities and a 60 s outage from 50 s: unconstrained, learned (from 30 s of driving before
    the outage) and a configured constraint; horizontal error at the outage's end."""
    traj, imu = simulate(duration=110.0)
    outage = (50.0, 110.0)
    meas = [m for m in gnss(traj, np.random.default_rng(5))
            if not outage[0] <= m.t < outage[1]]
    errors = {}
    boresight = ExtraState(2, np.radians(vc.BORESIGHT_SIGMA_DEG))  # as filter_config adds it
    for name, kw in (("off", {}), ("learned", {"nhc_learn": True,
                                               "extras": {"nhc": boresight}}),
                     ("configured", {"nhc_sigma": (0.1, 0.1)})):
        out = run(imu, meas, config(**kw))
        dp = nav_error(out.state(len(out.t) - 1), truth_state(traj, out.t[-1]))[0]
        errors[name] = np.hypot(dp[0], dp[1])
    # This simulated IMU drifts little (0.36 m in 60 s); the real car drive's: 6.7 -> 3.4 m RMS
    # of the per-outage maxima (docs/results/product_path.md).
    assert errors["learned"] < 0.85 * errors["off"], errors
    assert abs(errors["learned"] - errors["configured"]) < 0.25 * errors["configured"], errors


def test_the_held_side_slip_tells_nothing_of_the_yaw_at_first_and_keeps_p_positive():
    """hold_side_slip: the boresight yaw takes the slip a course alignment put into the yaw
    error (minus it): a lateral constraint, which sees v (phi_U + slip) at speed v along the
    body x axis (measurements.nonholonomic), sees only the yaw error's other part at first."""
    rng = np.random.default_rng(4)
    A = rng.standard_normal((8, 8))
    yaw, slip, slip_var = 5, 7, np.radians(3.0) ** 2
    for var_yaw in (np.radians(5.0) ** 2, np.radians(2.0) ** 2):  # above and below slip_var
        P = A @ A.T * 1e-4
        P[yaw, :] *= np.sqrt(var_yaw / P[yaw, yaw])
        P[:, yaw] = P[yaw, :]
        P[yaw, yaw] = var_yaw
        held = vc.hold_side_slip(P, yaw, slip, slip_var)
        assert np.linalg.eigvalsh(held)[0] > 0.0
        assert np.array_equal(np.delete(np.delete(held, slip, 0), slip, 1),
                              np.delete(np.delete(P, slip, 0), slip, 1))
        h = np.zeros(8)
        h[[yaw, slip]] = 10.0  # m/s: the lateral row's yaw and boresight-yaw columns
        c = min(slip_var, vc.SLIP_SHARE * var_yaw)
        expected = 100.0 * (var_yaw + slip_var - 2.0 * c + vc.SLIP_OWN_SIGMA ** 2)
        assert np.isclose(h @ held @ h, expected, rtol=1e-12)
    block = slice(6, 8)
    forgotten = at_prior(held, block, np.radians(vc.BORESIGHT_SIGMA_DEG))
    assert np.array_equal(forgotten[block, :6], np.zeros((2, 6)))
    assert np.allclose(forgotten[block, block],
                       np.radians(vc.BORESIGHT_SIGMA_DEG) ** 2 * np.eye(2))
