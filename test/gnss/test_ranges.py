"""Tight-coupling measurements (gnss/ranges.py) against the GNSS simulator's truth terms (its own
exact light-time geometry, clock and atmosphere, built independently of the navigator's model),
finite differences of the true range (Doppler sign), pymap3d (elevation), and the navigator
run on SatelliteRanges alone on the simulated car."""
import dataclasses
import math

import numpy as np
import pymap3d
import pytest

from ins_gnss_ros.gnss import ephemeris_data
from ins_gnss_ros.gnss.differences import NoiseModel
from ins_gnss_ros.gnss.ranges import RangeConfig, correct_observations, satellite_ranges
from ins_gnss_ros.gnss.simulator import GnssSimulator, SimulatorConfig, solve_fix
from ins_gnss_ros.nav.error_model import nav_error
from ins_gnss_ros.nav import GnssFix, GnssVelocity, Navigator, NavigatorConfig
from ins_gnss_ros.nav.sensor_errors import MEMS_ADIS16405, filter_noise
from ins_gnss_ros.nav.strapdown import NavState
from ins_gnss_ros.sim.imu_sim import ImuSpec, simulate_imu
from ins_gnss_ros.sim.scenarios import ShadingWindow, car

LEVER = (0.5, 0.3, 1.2)
RATE = 50.0
EXACT = dict(noise=NoiseModel(0.0, 0.0, 0.0, 0.0), doppler_sigma=(0.0, 0.0), multipath=None)


@pytest.fixture(scope="module")
def traj():
    return car(duration=130.0, seed=5, rate=RATE, static=15.0).trajectory


@pytest.fixture(scope="module")
def broadcast(traj):
    return ephemeris_data.load(traj.lon[0])


def _simulate(traj, broadcast, step=1.0, **config):
    sim = GnssSimulator(broadcast, SimulatorConfig(lever_arms=(LEVER,), **config))
    return sim, [e[0] for e in sim.run(traj, 1.0 / step)]


@pytest.fixture(scope="module")
def exact(traj, broadcast):
    return _simulate(traj, broadcast, **EXACT)


@pytest.fixture(scope="module")
def noisy(traj, broadcast):
    return _simulate(traj, broadcast, step=2.0)


def _truth_state(traj, t):
    k = int(round(t * RATE))
    return NavState(traj.lat[k], traj.lon[k], traj.h[k], traj.v_enu[k], traj.q_nb[k], t)


def _terms(sim, epoch, traj, config):
    """(corrected ranges, index of each in the epoch's observations)."""
    cr = correct_observations(epoch.raw, sim.ephemerides, _truth_state(traj, epoch.t), LEVER,
                              config)
    ids = [o.sat_id for o in epoch.raw.obs]
    return cr, [ids.index(c.sat_id) for c in cr]


def _model_residuals(c, epoch):
    """Corrected measurement minus the navigator's prediction from the TRUE antenna and clock."""
    ant = epoch.antenna_truth
    rho = np.linalg.norm(c.sat_pos - ant.xyz)
    u = (c.sat_pos - ant.xyz) / rho
    pr = c.pseudorange - (rho + epoch.clock[0] - c.sat_clock)
    rr = c.range_rate - (u @ (c.sat_vel - ant.vel) + epoch.clock[1] - c.sat_clock_drift)
    return pr, rr


# ------------------------------------------------------------------ measurement model
def test_noise_free_ranges_reproduce_the_simulated_geometry(traj, broadcast, exact):
    sim, epochs = exact
    config = RangeConfig(klobuchar=broadcast.klobuchar)
    n = 0
    for ep in epochs[::10]:
        cr, idx = _terms(sim, ep, traj, config)
        tr = ep.truth
        for c, i in zip(cr, idx):
            # Light-time range incl. Sagnac: the transmission time from the measured
            # pseudorange is off by the delays (~30 ns), moving the satellite by ~0.1 mm.
            assert np.linalg.norm(c.sat_pos - ep.antenna_truth.xyz) == pytest.approx(
                tr.range[i], abs=1e-3)
            assert c.sat_clock == pytest.approx(tr.sat_clock[i] - tr.group_delay[i], abs=1e-4)
            assert c.iono == pytest.approx(tr.iono[i], abs=1e-4)
            assert c.tropo == pytest.approx(tr.tropo[i], abs=1e-4)
            pr, rr = _model_residuals(c, ep)
            assert abs(pr) < 1e-3
            assert abs(rr) < 1e-5
            n += 1
    assert n > 100


def test_elevation_agrees_with_pymap3d(traj, exact):
    sim, epochs = exact
    ep = epochs[40]
    cr, _ = _terms(sim, ep, traj, RangeConfig())
    a = ep.antenna_truth
    for c in cr:
        az, el, _ = pymap3d.ecef2aer(*c.sat_pos, a.lat, a.lon, a.h, deg=False)
        assert c.elevation == pytest.approx(el, abs=1e-7)
        assert c.azimuth == pytest.approx(az, abs=1e-7)


def test_uncorrected_ionosphere_is_a_positive_code_delay(traj, exact):
    sim, epochs = exact
    ep = epochs[60]
    cr, idx = _terms(sim, ep, traj, RangeConfig(klobuchar=None))
    for c, i in zip(cr, idx):
        assert c.iono == 0.0
        assert _model_residuals(c, ep)[0] == pytest.approx(ep.truth.iono[i], abs=1e-3)
        assert ep.truth.iono[i] > 1.0


def test_doppler_sign_from_the_true_range_rate(traj, exact):
    """-lambda D: negative while the true range shrinks (positive Doppler, approaching). Checked
    while the car stands (t < 15 s), where the central difference is exact to ~1 mm/s (driving,
    the car's jerk leaves centimetres)."""
    sim, epochs = exact
    ids = lambda ep: [o.sat_id for o in ep.raw.obs]  # noqa: E731
    checked = {1: 0, -1: 0}
    for k in range(1, 14):
        before, ep, after = epochs[k - 1], epochs[k], epochs[k + 1]
        cr, idx = _terms(sim, ep, traj, RangeConfig())
        for c, i in zip(cr, idx):
            if c.sat_id not in ids(before) or c.sat_id not in ids(after):
                continue
            slope = (after.truth.range[ids(after).index(c.sat_id)]
                     - before.truth.range[ids(before).index(c.sat_id)]) / 2.0
            geometric = c.range_rate - ep.clock[1] + c.sat_clock_drift
            assert geometric == pytest.approx(slope, abs=2e-3)
            doppler = ep.raw.obs[i].doppler_hz
            assert np.sign(doppler) == -np.sign(slope)
            checked[int(np.sign(slope))] += 1
    assert checked[1] > 0 and checked[-1] > 0


def test_residuals_of_noisy_observations_match_the_variances(traj, broadcast, noisy):
    sim, epochs = noisy
    # The simulator's code noise 0.3 + 0.3/sin E plus its multipath 1 m exp(-E / 20 deg).
    config = RangeConfig(klobuchar=broadcast.klobuchar, code_sigma=(0.3, 0.32),
                         doppler_sigma=(0.02, 0.02))
    z_pr, z_rr, left = [], [], []
    for ep in epochs:
        cr, idx = _terms(sim, ep, traj, config)
        for c, i in zip(cr, idx):
            pr, rr = _model_residuals(c, ep)
            z_pr.append(pr / math.sqrt(c.pr_var))
            z_rr.append(rr / math.sqrt(c.rr_var))
            left.append(pr - ep.truth.noise_code[i] - ep.truth.multipath_code[i])
    assert len(z_pr) > 300
    assert np.max(np.abs(left)) < 1e-3          # nothing but the simulated noise remains
    assert 0.7 < np.std(z_pr) < 1.3
    assert 0.8 < np.std(z_rr) < 1.2
    assert abs(np.mean(z_rr)) < 0.15


# ------------------------------------------------------------------ selection
def test_selection_mask_limit_health_fit_interval_and_signals(traj, exact):
    sim, epochs = exact
    ep = epochs[50]
    state = _truth_state(traj, ep.t)
    every = correct_observations(ep.raw, sim.ephemerides, state, LEVER, RangeConfig())
    el = [c.elevation for c in every]
    assert el == sorted(el, reverse=True) and len(every) >= 6
    high = correct_observations(ep.raw, sim.ephemerides, state, LEVER,
                                RangeConfig(elevation_mask=math.radians(40.0)))
    assert [c.sat_id for c in high] == [c.sat_id for c in every
                                        if c.elevation >= math.radians(40.0)]
    three = satellite_ranges(ep.raw, sim.ephemerides, ep.t, state, LEVER,
                             RangeConfig(max_satellites=3))
    assert np.allclose(three.sat_pos, [c.sat_pos for c in every[:3]])
    assert three.t == ep.t and three.range_rate.shape == (3,) and three.pr_var.shape == (3,)
    first = every[0].sat_id
    ephs = dict(sim.ephemerides)
    ephs[first] = dataclasses.replace(ephs[first], health=1)
    ephs[every[1].sat_id] = dataclasses.replace(ephs[every[1].sat_id],
                                                toe=ephs[every[1].sat_id].toe - 3 * 3600.0)
    del ephs[every[2].sat_id]
    kept = correct_observations(ep.raw, ephs, state, LEVER, RangeConfig())
    assert [c.sat_id for c in kept] == [c.sat_id for c in every[3:]]
    gps_only = correct_observations(ep.raw, sim.ephemerides, state, LEVER,
                                    RangeConfig(signals={"G": "1C"}))
    assert gps_only and all(c.sat_id[0] == "G" for c in gps_only)
    assert not correct_observations(ep.raw, sim.ephemerides, state, LEVER,
                                    RangeConfig(signals={"G": "2L", "E": "5Q"}))


def test_missing_doppler_state_or_satellites_give_no_rates_or_nothing(traj, exact):
    sim, epochs = exact
    ep = epochs[50]
    state = _truth_state(traj, ep.t)
    raw = dataclasses.replace(ep.raw, obs=list(ep.raw.obs))
    raw.obs[0] = dataclasses.replace(raw.obs[0], doppler_hz=math.nan)
    m = satellite_ranges(raw, sim.ephemerides, ep.t, state, LEVER)
    assert m.range_rate is None and len(m.pseudorange) == len(raw.obs)
    assert satellite_ranges(ep.raw, sim.ephemerides, ep.t, None, LEVER) is None
    assert satellite_ranges(ep.raw, sim.ephemerides, ep.t, state, LEVER,
                            RangeConfig(min_satellites=len(ep.raw.obs) + 1)) is None


# ------------------------------------------------------------------ navigator
def _navigate(traj, imu, sim, epochs, t_switch, t_cut=np.inf):
    """Stream IMU and GNSS as the ekf node does: SPP fixes until t_switch (start and heading
    alignment), SatelliteRanges only afterwards; no GNSS at all from t_cut on."""
    nav = Navigator(NavigatorConfig(noise=filter_noise(MEMS_ADIS16405, "rw"), layout="24",
                                    lever_arm_b=np.array(LEVER), sigma_pos0=3.0, sigma_vel0=0.2,
                                    sigma_tilt0=np.deg2rad(1.0), align_speed=1.0))
    config = RangeConfig(klobuchar=sim.broadcast.klobuchar, code_sigma=(0.3, 0.32),
                         doppler_sigma=(0.02, 0.02))
    i, x0 = 0, None
    for ep in epochs:
        j = int(np.searchsorted(imu.t, ep.t, side="right"))
        if j > i:
            nav.add_imu(imu.t[i:j], imu.dtheta[i:j], imu.dv[i:j])
            i = j
        if ep.t >= t_cut:
            continue
        if ep.t >= t_switch:
            m = satellite_ranges(ep.raw, sim.ephemerides, ep.t, nav.state_at(ep.t), LEVER,
                                 config)
            nav.add_measurement(m)
            continue
        fix = solve_fix(ep, sim, x0)
        x0 = fix.xyz
        nav.add_measurement(GnssFix(ep.t, fix.lat, fix.lon, fix.h, fix.covariance_enu))
        nav.add_measurement(GnssVelocity(ep.t, fix.vel_enu, fix.vel_covariance_enu))
    if i < len(imu.t):
        nav.add_imu(imu.t[i:], imu.dtheta[i:], imu.dv[i:])
    nav.flush()
    return nav.output()


def _horizontal_errors(out, traj, t0):
    err = []
    for k in np.flatnonzero(out.t >= t0):
        dp = nav_error(out.state(k), _truth_state(traj, out.t[k]))[0]
        err.append(math.hypot(dp[0], dp[1]))
    return np.array(err)


def test_navigator_on_ranges_converges_with_6_and_stays_bounded_with_3(traj, broadcast):
    imu = simulate_imu(traj, ImuSpec(MEMS_ADIS16405, rate=RATE), seed=5)
    t_switch = 60.0
    results = {}
    for n in (6, 3):
        sim, epochs = _simulate(traj, broadcast, shading=(ShadingWindow(t_switch, 200.0, n),))
        out = _navigate(traj, imu, sim, epochs, t_switch)
        ranges = [u for u in out.updates if u.name == "pseudorange"]
        assert len(ranges) == len(traj.t[::int(RATE)][traj.t[::int(RATE)] >= t_switch])
        assert all(len(u.innovation) == n for u in ranges)
        assert sum(u.accepted for u in ranges) >= 0.95 * len(ranges)
        results[n] = (out, epochs, _horizontal_errors(out, traj, t_switch))
    out, epochs, err = results[6]
    # The receiver clock (30 km off, 15 m/s drift, never seen by the loose start) is found.
    clock = out.estimates["clock"][-1]
    assert clock[0] == pytest.approx(epochs[-1].clock[0], abs=3.0)
    assert clock[1] == pytest.approx(epochs[-1].clock[1], abs=0.3)
    nis = np.mean([u.nis / len(u.innovation) for u in out.updates if u.name == "pseudorange"])
    assert 0.3 < nis < 2.0
    assert err[-20:].max() < 1.0
    # Three satellites: bounded, far below the inertial drift from the same start.
    _, epochs, err3 = results[3]
    ins = _horizontal_errors(_navigate(traj, imu, sim, epochs, np.inf, t_cut=t_switch), traj,
                             t_switch)
    assert err3.max() < 5.0
    assert ins.max() > 5.0 * err3.max()
