"""set_pose (robot_localization's SetPose) and the map frame around a datum, against truth."""
import numpy as np
import pymap3d

from ins_gnss_ros.nav import ALIGNING, NAVIGATING, GnssFix, Navigator
from ins_gnss_ros.nav.error_model import nav_error
from ins_gnss_ros.nav.local_frame import datum_from_degrees, from_map, to_map
from ins_gnss_ros.nav.set_pose import set_pose

from test_navigator import IMU_RATE, SIGMA_P, config, gnss, simulate, truth_state


def test_map_frame_matches_pymap3d():
    datum = datum_from_degrees(59.9, 30.3, 40.0)
    lat, lon, h = np.radians(59.91), np.radians(30.33), 75.0
    enu = to_map(datum, lat, lon, h)
    expected = pymap3d.geodetic2enu(59.91, 30.33, 75.0, 59.9, 30.3, 40.0)
    np.testing.assert_allclose(enu, expected, atol=1e-6)
    np.testing.assert_allclose(from_map(datum, enu), (lat, lon, h), atol=1e-12)


def test_datum_out_of_range_is_refused():
    for bad in ((91.0, 0.0, 0.0), (0.0, 0.0, np.nan), (0.0, 0.0, 2e5)):
        try:
            datum_from_degrees(*bad)
        except ValueError:
            continue
        raise AssertionError(f"{bad} accepted")


def test_navigates_on_from_the_set_pose():
    """Before any fix (ALIGNING), the pose of the static car at 10 s is set from truth: the
    navigator starts there, refuses older fixes and, aided from then on, stays on the truth."""
    traj, imu = simulate(duration=40.0)
    meas = gnss(traj, np.random.default_rng(5))
    nav = Navigator(config())
    k0 = int(10.0 * IMU_RATE)
    nav.add_imu(imu.t[:k0], imu.dtheta[:k0], imu.dv[:k0])
    assert nav.mode == ALIGNING
    t0 = float(imu.t[k0 - 1])
    truth = truth_state(traj, t0)
    cov = np.diag([0.01, 0.01, 0.01, 1e-4, 1e-4, 0.0])  # no yaw variance given: sigma0 taken
    set_pose(nav, t0, truth.lat, truth.lon, truth.h, truth.q_nb, cov)
    assert nav.mode == NAVIGATING and nav.started
    dp, dv, phi = nav_error(nav.solution, truth)
    assert np.linalg.norm(dp) < 1e-6 and np.linalg.norm(phi) < 1e-9
    S = nav.space
    np.testing.assert_allclose(np.diag(nav.covariance())[S["pos"]], 0.01)
    before = len(nav.updates)
    old = next(m for m in meas if m.t < t0 - 1.0 and isinstance(m, GnssFix))
    nav.add_measurement(old)
    assert nav.updates[before:] and nav.updates[-1].reason == "too old"
    for m in meas:
        if m.t > t0:
            nav.add_measurement(m)
    nav.add_imu(imu.t[k0:], imu.dtheta[k0:], imu.dv[k0:])
    nav.flush()
    dp, dv, phi = nav_error(nav.solution, truth_state(traj, nav.solution.t))
    assert nav.mode == NAVIGATING
    assert np.linalg.norm(dp) < 3 * SIGMA_P and np.linalg.norm(dv) < 0.1
    assert np.degrees(np.linalg.norm(phi)) < 1.5
