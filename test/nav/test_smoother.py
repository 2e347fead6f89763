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


def test_imu_rate_track_follows_the_truth_between_epochs():
    """Epochs of an aircraft's truth at 10 Hz and its ideal 200 Hz increments: the IMU-rate
    solution meets every epoch and stays on the true path between them."""
    from ins_gnss_ros.nav.smoother import imu_rate_track
    from ins_gnss_ros.nav.track import Track
    from ins_gnss_ros.sim.scenarios import aircraft

    traj = aircraft(duration=40.0, seed=1, rate=200.0).trajectory
    k = np.arange(0, len(traj.t), 20)
    epochs = Track(traj.t[k], traj.lat[k], traj.lon[k], traj.h[k], traj.v_enu[k], traj.q_nb[k])
    dense = imu_rate_track(epochs, {"bg": np.zeros((len(k), 3))}, traj.t[1:], traj.dtheta, traj.dv)
    assert np.array_equal(dense.t, traj.t[1:k[-1] + 1])
    i = np.arange(1, k[-1] + 1)
    rm, rn = radii(traj.lat[i])
    north = (dense.lat - traj.lat[i]) * (rm + traj.h[i])
    east = (dense.lon - traj.lon[i]) * (rn + traj.h[i]) * np.cos(traj.lat[i])
    assert np.max(np.abs([north, east, dense.h - traj.h[i]])) < 1e-4  # m
    assert np.max(np.abs(dense.v_enu - traj.v_enu[i])) < 1e-4         # m/s
    at_epochs = np.isin(dense.t, epochs.t)
    assert np.allclose(dense.lat[at_epochs], traj.lat[k[1:]], rtol=0, atol=1e-13)
    assert np.allclose(dense.omega_b, traj.dtheta[i - 1] / 0.005, rtol=0, atol=1e-12)


def test_late_measurements_smooth_as_timely_ones():
    """GNSS arriving 0.2 s late (the navigator rewinds to a checkpoint and applies it at its
    epoch) gives the record, and so the smoothed solution, of the same GNSS known in advance:
    the re-applied corrections of the checkpoint's epoch are not counted twice."""
    traj = car(duration=60.0, seed=5, rate=RATE, static=15.0).trajectory
    imu = simulate_imu(traj, ImuSpec(MEMS_ADIS16405, rate=RATE), seed=5)
    rng = np.random.default_rng(3)
    config = NavigatorConfig(noise=filter_noise(MEMS_ADIS16405, "rw"), layout="15",
                             sigma_tilt0=np.deg2rad(1.0), align_speed=1.0)
    measurements = []
    for k in range(20, len(traj.t), 20):
        rm, rn = radii(traj.lat[k])
        e = 0.3 * rng.standard_normal(3)
        measurements += [
            GnssFix(traj.t[k], traj.lat[k] + e[1] / (rm + traj.h[k]),
                    traj.lon[k] + e[0] / ((rn + traj.h[k]) * np.cos(traj.lat[k])),
                    traj.h[k] + e[2], 0.09 * np.eye(3)),
            GnssVelocity(traj.t[k], traj.v_enu[k] + 0.03 * rng.standard_normal(3),
                         9e-4 * np.eye(3))]
    timely = Navigator(config)
    for m in measurements:
        timely.add_measurement(m)
    timely.add_imu(imu.t, imu.dtheta, imu.dv)
    timely.flush()
    late = Navigator(config)
    queue = list(measurements)
    for i in range(0, len(imu.t), 10):
        late.add_imu(imu.t[i:i + 10], imu.dtheta[i:i + 10], imu.dv[i:i + 10])
        while queue and queue[0].t <= imu.t[min(i + 9, len(imu.t) - 1)] - 0.2:
            late.add_measurement(queue.pop(0))
    for m in queue:
        late.add_measurement(m)
    late.flush()
    a, b = timely.output(), late.output()
    assert np.array_equal(a.t, b.t)
    sa, sb = rts_smooth(a), rts_smooth(b)
    rm, rn = radii(sa.lat)
    north = (sa.lat - sb.lat) * (rm + sa.h)
    east = (sa.lon - sb.lon) * (rn + sa.h) * np.cos(sa.lat)
    # 3 mm (the late run's segments end at other samples); with the corrections of the
    # checkpoint epochs counted twice it was 0.16 m.
    assert np.max(np.hypot(north, east)) < 0.01
