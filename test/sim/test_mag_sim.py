"""Magnetometer simulator (ins_gnss_ros.sim.mag_sim) against hand-computed cases."""
import numpy as np
import pymap3d
import pytest

from ins_gnss_ros.sim import mag_sim
from ins_gnss_ros.sim import trajectory as tr

LAT0, LON0, H0 = np.deg2rad(59.9), np.deg2rad(30.3), 20.0
NT = 1e-9
B_ENU = np.array([2000.0, 15000.0, -50000.0]) * NT  # St Petersburg-like: east, north, up


def _at_rest(yaw, duration=2.0):
    route = tr.Route(yaw0=yaw).hold(duration)
    return tr.generate(tr.CarMotion(route), LAT0, LON0, H0, duration, rate=50.0, oversample=2)


def test_level_headings():
    north = mag_sim.simulate_magnetometer(_at_rest(np.pi / 2), B_ENU, rate=10.0)
    # Facing north: forward = N, left = W, up = U.
    np.testing.assert_allclose(north.field_b, np.tile([15000.0, -2000.0, -50000.0], (21, 1)) * NT,
                               atol=1e-15)
    east = mag_sim.simulate_magnetometer(_at_rest(0.0), B_ENU, rate=10.0)
    np.testing.assert_allclose(east.field_b[0], np.array([2000.0, 15000.0, -50000.0]) * NT,
                               atol=1e-15)
    ned = mag_sim.simulate_magnetometer(_at_rest(0.0), [15000e-9, 2000e-9, 50000e-9],
                                        rate=10.0, frame="NED")
    np.testing.assert_allclose(ned.field_b, east.field_b, atol=1e-15)


def test_iron_and_sensor_errors():
    err = mag_sim.MagErrors(hard_iron_b=np.array([100.0, -200.0, 300.0]) * NT,
                            soft_iron=np.diag([0.1, 0.0, 0.0]),
                            scale_misalignment=np.array([[0.0, 0.0, 0.0],
                                                         [0.0, 0.02, 0.0],
                                                         [0.0, 0.0, 0.0]]),
                            offset_b=np.array([0.0, 0.0, 1000.0]) * NT)
    m = mag_sim.simulate_magnetometer(_at_rest(np.pi / 2), B_ENU, err, rate=10.0)
    # x: 1.1·15000 + 100; y: 1.02·(−2000 − 200); z: −50000 + 300 + 1000.
    np.testing.assert_allclose(m.field_b[0], np.array([16600.0, -2244.0, -48700.0]) * NT,
                               atol=1e-15)
    np.testing.assert_allclose(m.external_b[0], np.array([15000.0, -2000.0, -50000.0]) * NT,
                               atol=1e-15)


def test_dipole_disturbance_as_vehicle_passes():
    """Drive east at 10 m/s past a vertical dipole 10 m north of the road at x = 100 m:
    at closest approach r ⟂ m, so B = −μ0 m / (4π d³) = −100 nT (up); at 2d it is 8× weaker."""
    duration = 30.0
    traj = tr.generate(tr.CarMotion(tr.Route(yaw0=0.0, speed0=10.0).hold(duration)),
                       LAT0, LON0, H0, duration, rate=50.0, oversample=2)
    lat, lon, h = pymap3d.enu2geodetic(100.0, 10.0, 0.0, LAT0, LON0, H0, deg=False)
    dip = mag_sim.Dipole(lat, lon, h, (0.0, 0.0, 1000.0))
    m = mag_sim.simulate_magnetometer(traj, B_ENU, rate=50.0, dipoles=[dip])
    k = np.argmin(np.abs(m.t - 10.0))
    np.testing.assert_allclose(m.disturbance_n[k], [0.0, 0.0, -100.0 * NT], atol=0.5 * NT)
    np.testing.assert_allclose(m.field_b[k] - m.field_b[0], [0.0, 0.0, -100.0 * NT],
                               atol=1.5 * NT)
    # Abeam at x = 100 ± 10√3 the distance is 20 m: a vertical moment seen horizontally.
    k2 = np.argmin(np.abs(m.t - (10.0 + np.sqrt(3.0))))
    assert m.disturbance_n[k2, 2] == pytest.approx(-1e-7 * 1000 / 20.0 ** 3, rel=0.02)
    assert np.abs(m.disturbance_n[-1]).max() < 0.2 * NT  # 200 m away


def test_noise_and_determinism():
    err = mag_sim.MagErrors(noise_std=50.0 * NT)
    a = mag_sim.simulate_magnetometer(_at_rest(1.0, 100.0), B_ENU, err, rate=50.0, seed=2)
    b = mag_sim.simulate_magnetometer(_at_rest(1.0, 100.0), B_ENU, err, rate=50.0, seed=2)
    np.testing.assert_array_equal(a.field_b, b.field_b)
    np.testing.assert_allclose((a.field_b - a.external_b).std(axis=0), 50.0 * NT, rtol=0.1)
