"""RTS smoother over a simulated car run with a GNSS outage."""
import numpy as np
import pytest

from ins_gnss_ros.nav.earth import radii
from ins_gnss_ros.nav.error_model import nav_error
from ins_gnss_ros.nav.lever_arm import lever_arm_position, lever_arm_velocity
from ins_gnss_ros.nav import GnssFix, GnssVelocity, Navigator, NavigatorConfig
from ins_gnss_ros.nav.sensor_errors import MEMS_ADIS16405, filter_noise
from ins_gnss_ros.nav.smoother import rts_smooth
from ins_gnss_ros.nav.strapdown import NavState
from ins_gnss_ros.sim.imu_sim import ImuSpec, simulate_imu
from ins_gnss_ros.sim.scenarios import car

RATE = 100.0
LEVER = np.array([0.5, 0.3, 1.2])
OUTAGE = (60.0, 80.0)


@pytest.fixture(scope="module")
def runs():
    traj = car(duration=100.0, seed=4, rate=RATE, static=15.0).trajectory
    imu = simulate_imu(traj, ImuSpec(MEMS_ADIS16405, rate=RATE), seed=4)
    rng = np.random.default_rng(2)
    nav = Navigator(NavigatorConfig(noise=filter_noise(MEMS_ADIS16405, "rw"), layout="15",
                                    lever_arm_b=LEVER, sigma_tilt0=np.deg2rad(1.0),
                                    align_speed=1.0))
    for k in range(25, len(traj.t), 25):
        t = traj.t[k]
        if OUTAGE[0] < t < OUTAGE[1]:
            continue
        lat, lon, h = lever_arm_position(traj.lat[k], traj.lon[k], traj.h[k], traj.q_nb[k], LEVER)
        rm, rn = radii(lat)
        e = 0.3 * rng.standard_normal(3)
        nav.add_measurement(GnssFix(t, lat + e[1] / (rm + h), lon + e[0] / ((rn + h) * np.cos(lat)),
                                    h + e[2], 0.09 * np.eye(3)))
        v = lever_arm_velocity(traj.v_enu[k], traj.q_nb[k], traj.omega_ib_b[k], LEVER, lat)
        nav.add_measurement(GnssVelocity(t, v + 0.03 * rng.standard_normal(3), 9e-4 * np.eye(3)))
    nav.add_imu(imu.t, imu.dtheta, imu.dv)
    nav.flush()
    out = nav.output()
    return traj, out, rts_smooth(out)


def errors(traj, t, lat, lon, h, v, q):
    res = []
    for k in range(len(t)):
        i = int(round(t[k] * RATE))
        true = NavState(traj.lat[i], traj.lon[i], traj.h[i], traj.v_enu[i], traj.q_nb[i])
        res.append(np.concatenate(nav_error(NavState(lat[k], lon[k], h[k], v[k], q[k]), true)))
    return np.array(res)


def test_smoother_reduces_outage_error(runs):
    traj, out, sm = runs
    inside = (out.t > OUTAGE[0]) & (out.t < OUTAGE[1])
    fwd = errors(traj, out.t[inside], out.lat[inside], out.lon[inside], out.h[inside],
                 out.v_enu[inside], out.q_nb[inside])
    smo = errors(traj, sm.t[inside], sm.lat[inside], sm.lon[inside], sm.h[inside],
                 sm.v_enu[inside], sm.q_nb[inside])
    h_fwd = np.hypot(fwd[:, 0], fwd[:, 1])
    h_smo = np.hypot(smo[:, 0], smo[:, 1])
    assert h_fwd.max() > 1.0  # the outage is long enough to matter
    assert h_smo.max() < 0.3 * h_fwd.max()
    assert np.sqrt(np.mean(h_smo ** 2)) < 0.3 * np.sqrt(np.mean(h_fwd ** 2))


def test_smoothed_covariance_is_smaller_and_consistent(runs):
    traj, out, sm = runs
    S = out.space
    inside = np.flatnonzero((out.t > OUTAGE[0]) & (out.t < OUTAGE[1]))
    var_f = np.array([np.diag(out.P[k][S["pos"], S["pos"]]) for k in inside])
    var_s = np.array([np.diag(sm.P[k][S["pos"], S["pos"]]) for k in inside])
    assert np.all(var_s <= var_f * (1 + 1e-9))
    smo = errors(traj, sm.t[inside], sm.lat[inside], sm.lon[inside], sm.h[inside],
                 sm.v_enu[inside], sm.q_nb[inside])
    nees = np.mean([e @ np.linalg.solve(sm.P[k][S["pos"], S["pos"]], e)
                    for e, k in zip(smo[:, :3], inside)])
    assert 0.2 * 3 < nees < 4 * 3


def test_smoother_leaves_alignment_epochs_and_end_unchanged(runs):
    _, out, sm = runs
    aligning = out.mode == "ALIGNING"
    np.testing.assert_array_equal(sm.lat[aligning], out.lat[aligning])
    assert sm.lat[-1] == pytest.approx(out.lat[-1], abs=1e-12)
