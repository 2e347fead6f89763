"""What the filter finds out about a sensor it is not told about, against simulated truth: the
GNSS velocity's latency ("vd" state), the IMU's white noise at rest (rest_noise.py), and a
rejection that an outage interrupts (integrity.py)."""
from dataclasses import replace

import numpy as np

from ins_gnss_ros.nav import GnssVelocity, Navigator
from ins_gnss_ros.nav.ekf import ExtraState
from ins_gnss_ros.nav.integrity import Integrity, rejection_start
from ins_gnss_ros.nav.lever_arm import lever_arm_velocity
from ins_gnss_ros.nav.rest_noise import RestNoise
from ins_gnss_ros.nav.sensor_errors import MEMS_ADIS16405, filter_noise
from ins_gnss_ros.sim.imu_sim import ImuSpec, simulate_imu

from test_navigator import IMU_RATE, LEVER, SIGMA_V, config, gnss, nees, run, simulate

GRADE = filter_noise(MEMS_ADIS16405, "rw")


def test_rest_noise_measures_white_noise_of_known_density_beside_gravity_and_bias():
    rng = np.random.default_rng(1)
    dt, n = 0.01, 6000
    t = dt * np.arange(1, n + 1)
    gyro_n, accel_n = 5e-3, 3e-2   # rad/s/sqrt(Hz), m/s^2/sqrt(Hz)
    bias = np.array([0.01, -0.02, 0.005])
    dtheta = (bias + gyro_n / np.sqrt(dt) * rng.standard_normal((n, 3))) * dt
    dv = (np.array([0.0, 0.3, 9.8]) + accel_n / np.sqrt(dt) * rng.standard_normal((n, 3))) * dt
    rest = RestNoise(GRADE)
    rest.confirm(-1.0, True)   # at rest since before the samples
    for k in range(0, n, 7):   # segments of 7 samples: blocks of unequal lengths
        rest.add(t[k:k + 7], dtheta[k:k + 7], dv[k:k + 7])
        rest.add(t[k:k + 7], dtheta[k:k + 7], dv[k:k + 7])   # a rewound re-run: passed over
    assert rest.noise is GRADE   # nothing confirmed yet
    rest.confirm(t[-1], True)
    gyro, accel, dof = rest.densities()
    assert dof > 300
    assert abs(np.sqrt(gyro) / gyro_n - 1.0) < 0.1 and abs(np.sqrt(accel) / accel_n - 1.0) < 0.1
    assert rest.noise.gyro_psd == gyro and rest.noise.accel_psd == accel
    assert rest.noise.blocks == GRADE.blocks


def test_rest_noise_never_below_the_grade_and_motion_drops_unconfirmed_blocks():
    rng = np.random.default_rng(2)
    dt, n = 0.01, 3000
    t = dt * np.arange(1, n + 1)
    white = 0.5 * rng.standard_normal((2, n, 3)) * dt / np.sqrt(dt)
    quiet = np.sqrt(GRADE.gyro_psd) * white[0], np.sqrt(GRADE.accel_psd) * white[1]
    rest = RestNoise(GRADE)
    rest.confirm(-1.0, True)
    _feed(rest, t, *quiet)
    rest.confirm(t[-1], True)
    assert rest.noise is GRADE and max(rest.ratios()) < 1.0
    # Blocks not yet confirmed when the GNSS speed says motion are not counted.
    before = rest.densities()
    _feed(rest, t + t[-1], 100.0 * quiet[0], 100.0 * quiet[1])
    rest.confirm(2 * t[-1], False)
    assert rest.densities() == before
    # A new rest: its first second after the first velocity is passed over.
    rest.confirm(3 * t[-1], True)
    _feed(rest, t[:99] + 3 * t[-1], 100.0 * quiet[0][:99], 100.0 * quiet[1][:99])
    rest.confirm(4 * t[-1], True)
    assert rest.densities() == before


def _feed(rest, t, dtheta, dv, step=10):
    """The samples in segments of `step`, as the navigator propagates them."""
    for k in range(0, len(t), step):
        rest.add(t[k:k + step], dtheta[k:k + step], dv[k:k + step])


def test_velocity_latency_state_converges_to_an_untold_100_ms():
    traj, imu = simulate()
    lag = int(round(0.1 * IMU_RATE))
    rng = np.random.default_rng(7)
    meas = []
    for m in gnss(traj, np.random.default_rng(6)):
        if isinstance(m, GnssVelocity):   # the antenna velocity of 0.1 s earlier, stamped now
            k = int(round(m.t * IMU_RATE)) - lag
            v = lever_arm_velocity(traj.v_enu[k], traj.q_nb[k], traj.omega_ib_b[k], LEVER,
                                   traj.lat[k])
            m = replace(m, v_enu=v + SIGMA_V * rng.standard_normal(3))
        meas.append(m)
    out = run(imu, meas, config(extras={"vd": ExtraState(1, 0.1)}))
    vd = out.estimates["vd"][:, 0]
    sigma = out.sigma("vd")[:, 0]
    assert abs(vd[-1] - 0.1) < max(0.01, 3 * sigma[-1]), (vd[-1], sigma[-1])
    assert np.all((vd >= 0.0) & (vd <= 0.5))


def test_imu_noisier_than_its_grade_is_measured_at_rest_and_the_nees_stays_honest():
    grade = replace(MEMS_ADIS16405,
                    gyro=replace(MEMS_ADIS16405.gyro,
                                 white_density=5 * MEMS_ADIS16405.gyro.white_density),
                    accel=replace(MEMS_ADIS16405.accel,
                                  white_density=5 * MEMS_ADIS16405.accel.white_density))
    traj, _ = simulate()
    imu = simulate_imu(traj, ImuSpec(grade, rate=IMU_RATE), seed=3)
    meas = gnss(traj, np.random.default_rng(5))
    nav = Navigator(config())
    for m in meas:
        nav.add_measurement(m)
    nav.add_imu(imu.t, imu.dtheta, imu.dv)
    nav.flush()
    ratios = nav._rest_noise.ratios()
    assert 4.0 < ratios[0] < 6.0 and 4.0 < ratios[1] < 6.0, ratios
    values = nees(nav.output(), traj, t_min=40.0)
    assert np.all(values > 0.2 * 3) and np.all(values < 4 * 3), values


def test_a_rejection_does_not_span_a_gap_in_which_the_kind_did_not_arrive():
    assert rejection_start(None, 10.0, 2.0) is None
    assert rejection_start((5.0, 9.0), 10.0, 2.0) == 5.0      # 1 s apart: continues
    assert rejection_start((5.0, 6.0), 20.0, 2.0) is None     # after a 14 s outage: anew
    guard = Integrity(config())
    guard.rejected("gnss_pos", 5.0)
    guard.rejected("gnss_pos", 6.0)
    guard.rejected("gnss_pos", 20.0)
    assert guard.rejecting["gnss_pos"] == (20.0, 20.0)
    assert not guard.degraded(20.0)   # not suspect at once after the outage
