"""Speed-log simulator (ins_gnss_ros.sim.log_sim) against hand-computed cases."""
import numpy as np
import pytest

from ins_gnss_ros.sim import log_sim
from ins_gnss_ros.sim import trajectory as tr

LAT0, LON0, H0 = np.deg2rad(60.8), np.deg2rad(31.5), 20.0


def _ship(route, duration):
    return tr.generate(tr.ShipMotion(route), LAT0, LON0, H0, duration, rate=20.0, oversample=2)


def test_heading_north_with_east_current():
    """Bow north at 5 m/s, water moving east at 1 m/s: through the water the ship moves
    (−1, 5) m/s ENU, i.e. 5 m/s ahead and 1 m/s to port (+y FLU)."""
    traj = _ship(tr.Route(yaw0=np.pi / 2, speed0=5.0).hold(10.0), 10.0)
    cur = log_sim.CurrentModel(mean_enu=np.array([1.0, 0.0, 0.0]))
    out = log_sim.simulate_log(traj, cur, log_sim.LogSpec(rate=2.0, dual_axis=True))
    np.testing.assert_allclose(out.speed, 5.0, atol=1e-9)
    np.testing.assert_allclose(out.transverse, 1.0, atol=1e-9)
    spec = log_sim.LogSpec(rate=2.0, scale_error=0.02, offset=0.1, dual_axis=True)
    out = log_sim.simulate_log(traj, cur, spec)
    np.testing.assert_allclose(out.speed, 5.0 * 1.02 + 0.1, atol=1e-9)
    np.testing.assert_allclose(out.transverse, 1.0 * 1.02 + 0.1, atol=1e-9)
    single = log_sim.simulate_log(traj, cur, log_sim.LogSpec(rate=2.0))
    assert np.all(np.isnan(single.transverse))
    assert single.t[1] - single.t[0] == pytest.approx(0.5)


def test_lever_arm_in_a_turn():
    """A transducer 10 m aft of the IMU swings to starboard in a steady left turn at rate r:
    transverse speed −10 r (ω × l with ω = (0, 0, r), l = (−10, 0, 0))."""
    rate = 6.0 / 300.0  # 6 m/s on a 300 m radius
    route = tr.Route(yaw0=0.3, speed0=6.0, ramp=5.0).turn(np.pi, radius=300.0)
    traj = _ship(route, 60.0)
    spec = log_sim.LogSpec(rate=1.0, lever_arm_b=np.array([-10.0, 0.0, 0.0]), dual_axis=True)
    out = log_sim.simulate_log(traj, spec=spec)
    steady = (out.t > 10.0) & (out.t < 50.0)
    # ω_eb also holds the transport rate v tan(lat)/R ≈ 2e-6 rad/s: 2e-5 m/s at 10 m.
    np.testing.assert_allclose(out.transverse[steady], -10.0 * rate, atol=5e-5)
    np.testing.assert_allclose(out.speed[steady], 6.0, atol=1e-6)


def test_current_gauss_markov_statistics():
    sigma, tau = 0.1, 50.0
    t = np.arange(0.0, 100000.0, 1.0)
    c = log_sim.simulate_current(t, log_sim.CurrentModel(np.array([0.2, -0.1, 0.0]), sigma, tau),
                                 np.random.default_rng(5))
    dev = c[:, :2] - [0.2, -0.1]
    np.testing.assert_allclose(dev.std(axis=0), sigma, rtol=0.1)
    np.testing.assert_allclose(dev.mean(axis=0), 0.0, atol=0.2 * sigma)
    lag = int(tau)
    rho = np.mean(dev[lag:] * dev[:-lag], axis=0) / dev.var(axis=0)
    np.testing.assert_allclose(rho, np.exp(-1.0), atol=0.1)
    assert np.all(c[:, 2] == 0.0)


def test_noise_and_determinism():
    traj = _ship(tr.Route(speed0=7.0).hold(200.0), 200.0)
    spec = log_sim.LogSpec(rate=10.0, noise_std=0.05)
    cur = log_sim.CurrentModel(gm_sigma=0.05, gm_tau=100.0)
    a = log_sim.simulate_log(traj, cur, spec, seed=4)
    b = log_sim.simulate_log(traj, cur, spec, seed=4)
    np.testing.assert_array_equal(a.speed, b.speed)
    err = a.speed - a.water_velocity_b[:, 0]
    assert err.std() == pytest.approx(0.05, rel=0.1)
    # The log sees the ground speed minus the current along the bow.
    np.testing.assert_allclose(a.water_velocity_b[:, 0], 7.0 - a.current_enu[:, 0], atol=1e-9)
