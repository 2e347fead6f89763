"""GNSS raw-measurement simulator, receiver clock and multipath models against independent truth:
an independent light-time range (pymap3d geometry), the Klobuchar value, the double differences
of a known baseline, the SPP of the project, Doppler against the phase rate, injected slips, the
shading schedule, the Allan variance of the oscillator (allantools) and Van Loan's Q."""
import dataclasses
import json
import math

import allantools
import numpy as np
import pymap3d
import pytest
from conftest import shared_path

from ins_gnss_ros.gnss import ephemeris_data
from ins_gnss_ros.gnss.atmosphere import klobuchar_delay, tropo_delay
from ins_gnss_ros.gnss.clock_model import (OCXO, TCXO, OscillatorSpec, allan_variance,
                                           process_noise, simulate_clock, transition)
from ins_gnss_ros.gnss.constants import FREQ_E1, FREQ_L1
from ins_gnss_ros.gnss.cycle_slip import detect_slips_doppler, doppler_phase_residual
from ins_gnss_ros.gnss.differences import (AntennaEpoch, NoiseModel, form_double_differences,
                                           select_references)
from ins_gnss_ros.gnss.ephemeris import group_delay, sat_position
from ins_gnss_ros.gnss.multipath import MultipathModel, MultipathProcess
from ins_gnss_ros.gnss.simulator import (GnssSimulator, SimulatorConfig, SlipEvent, solve_fix,
                                         time_reference)
from ins_gnss_ros.nav.discretize import van_loan
from ins_gnss_ros.nav.rotations import quat_from_euler, quat_rotate
from ins_gnss_ros.sim import scenarios

C = 299792458.0
WE = 7.2921151467e-5
LAT, LON, H = math.radians(59.9), math.radians(30.3), 22.0
Q_NB = quat_from_euler(0.0, 0.0, 0.4)
EXACT = SimulatorConfig(noise=NoiseModel(0.0, 0.0, 0.0, 0.0), doppler_sigma=(0.0, 0.0),
                        multipath=None, half_cycle_resolve_s=0.0)


@pytest.fixture(scope="module")
def broadcast():
    return ephemeris_data.load(LON)


def _static(sim, n, dt=1.0, t0=0.0):
    return [sim.epoch(t0 + k * dt, LAT, LON, H, np.zeros(3), Q_NB) for k in range(n)]


def _independent_range(eph, t_gps, rx):
    """Light-time range solved in the inertial frame aligned with ECEF at reception, written
    out here from the ICD definition (the satellite positions come from the tested
    ephemeris module)."""
    tau = 0.07
    for _ in range(6):
        pos = sat_position(eph, t_gps - tau)[0]
        c, s = math.cos(WE * tau), math.sin(WE * tau)
        sat = np.array([[c, s, 0], [-s, c, 0], [0, 0, 1]]) @ pos
        tau = np.linalg.norm(sat - rx) / C
    return C * tau, sat


# ------------------------------------------------------------------------------- data set
def test_stored_ephemerides_equal_a_fresh_decode():
    fresh = ephemeris_data.extract(shared_path("data", "walk_0827", "gnss_1730.ubx"))
    stored = json.loads(ephemeris_data.DATA_FILE.read_text())
    assert fresh == stored
    assert len(stored["ephemerides"]) == 11


def test_rotated_set_is_the_same_orbit_turned_about_the_earth_axis(broadcast):
    original = ephemeris_data.load()
    shift = LON - original.site[1]
    c, s = math.cos(shift), math.sin(shift)
    rz = np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]])   # active rotation eastwards
    t = original.t_first
    for sat_id, eph in original.ephemerides.items():
        turned = sat_position(broadcast.ephemerides[sat_id], t)
        base = sat_position(eph, t)
        assert np.allclose(turned[0], rz @ base[0], atol=1e-6)
        assert turned[1] == base[1]
    lo, hi = broadcast.validity()
    assert hi - lo > 2 * 3600


# ---------------------------------------------------------------------- closed loop
def test_pseudorange_minus_modelled_terms_is_the_true_range(broadcast):
    sim = GnssSimulator(broadcast, EXACT)
    epoch = _static(sim, 3)[-1][0]
    rx = np.array(pymap3d.geodetic2ecef(LAT, LON, H, deg=False))
    clock = epoch.clock[0]
    assert len(epoch.raw.obs) >= 7
    for ob in epoch.raw.obs:
        eph = sim.ephemerides[ob.sat_id]
        rho, sat = _independent_range(eph, epoch.t_gps, rx)
        az, el, _ = pymap3d.ecef2aer(*sat, LAT, LON, H, deg=False)
        t_tx = epoch.t_gps - rho / C
        dt_sat = sat_position(eph, t_tx)[1]
        iono = klobuchar_delay(epoch.t_gps, LAT, LON, el, az, *broadcast.klobuchar, FREQ_L1)
        tropo = tropo_delay(LAT, H, el)
        modelled = clock - C * (dt_sat - group_delay(eph, ob.frequency_hz)) + iono + tropo
        assert ob.pseudorange_m - modelled == pytest.approx(rho, abs=1e-3)
        lam = C / ob.frequency_hz
        phase_m = rho + clock - C * dt_sat - iono + tropo
        n = ob.carrier_cycles - phase_m / lam
        assert n == pytest.approx(round(n), abs=1e-3 / lam)
    # The receiver tags the epoch with its own clock.
    # (to the 0.24 us resolution of a float64 GPS time, see gnss/time.py)
    assert epoch.raw.t_gps - epoch.t_gps == pytest.approx(clock / C, abs=5e-7)


def test_ionosphere_is_the_klobuchar_value_on_l1_and_e1(broadcast):
    with_iono = _static(GnssSimulator(broadcast, EXACT), 2)[-1][0]
    without = _static(GnssSimulator(broadcast, dataclasses.replace(EXACT, ionosphere=False)),
                      2)[-1][0]
    rx = np.array(pymap3d.geodetic2ecef(LAT, LON, H, deg=False))
    systems = set()
    for a, b, el, az in zip(with_iono.raw.obs, without.raw.obs, with_iono.truth.elevation,
                            with_iono.truth.azimuth):
        _, sat = _independent_range(GnssSimulator(broadcast).ephemerides[a.sat_id],
                                    with_iono.t_gps, rx)
        az_i, el_i, _ = pymap3d.ecef2aer(*sat, LAT, LON, H, deg=False)
        expected = klobuchar_delay(with_iono.t_gps, LAT, LON, el_i, az_i, *broadcast.klobuchar)
        assert 0.5 < expected < 30.0
        assert a.pseudorange_m - b.pseudorange_m == pytest.approx(expected, abs=1e-4)
        lam = C / a.frequency_hz
        # The phase advances by the same amount (ionospheric divergence of code and phase).
        assert (a.carrier_cycles - b.carrier_cycles) * lam == pytest.approx(-expected, abs=1e-4)
        systems.add(a.system)
    assert systems == {"G", "E"}
    assert FREQ_E1 == FREQ_L1   # so the 1/f² scaling leaves the E1 delay equal to L1's


# ----------------------------------------------------------------- self-consistency
def test_double_differences_of_a_static_baseline_are_geometry_plus_integers(broadcast):
    arms = ((0.75, 0.0, 1.0), (-0.75, 0.0, 1.0))     # 1.5 m fore-aft (seed 004 ISON-1)
    noise = NoiseModel(0.002, 0.002, 0.3, 0.3)
    cfg = SimulatorConfig(lever_arms=arms, noise=noise, multipath=None, half_cycle_resolve_s=0.0,
                          seed=4)
    sim = GnssSimulator(broadcast, cfg)
    b_enu = quat_rotate(Q_NB, np.subtract(arms[1], arms[0]))
    assert np.linalg.norm(b_enu) == pytest.approx(1.5)
    worst = 0.0
    for pair in _static(sim, 20):
        ants = [AntennaEpoch([o.sat_id for o in e.raw.obs],
                             np.array([o.carrier_cycles for o in e.raw.obs]),
                             np.array([o.pseudorange_m for o in e.raw.obs]),
                             np.array([C / o.frequency_hz for o in e.raw.obs])) for e in pair]
        ids = ants[0].signal_ids
        los = dict(zip(ids, pair[0].truth.los_enu))
        refs = select_references(ids, pair[0].truth.elevation, ants[0].wavelength)
        dd = form_double_differences(ants, los, refs, noise)
        assert len(dd.pairs) >= 5
        amb = [{s: n for s, n in zip(ids, e.truth.ambiguity)} for e in pair]
        for j, (s, r) in enumerate(dd.pairs):
            n_dd = (amb[1][s] - amb[1][r]) - (amb[0][s] - amb[0][r])
            residual = dd.phase[j] - dd.geometry[j] @ b_enu / dd.wavelength[j] - n_dd
            worst = max(worst, abs(residual) / math.sqrt(dd.cov_phase[j, j]))
            assert round(dd.phase[j] - dd.geometry[j] @ b_enu / dd.wavelength[j]) == n_dd
    assert worst < 4.5


def test_spp_of_simulated_pseudoranges_recovers_truth_within_its_budget(broadcast):
    cfg = SimulatorConfig(multipath=None, seed=11)
    sim = GnssSimulator(broadcast, cfg)
    nees, h_err = [], []
    for (epoch,) in _static(sim, 40, dt=2.0):
        fix = solve_fix(epoch, sim)
        truth = epoch.antenna_truth
        err = pymap3d.geodetic2enu(fix.lat, fix.lon, fix.h, truth.lat, truth.lon, truth.h,
                                   deg=False)
        nees.append(np.asarray(err) @ np.linalg.solve(fix.covariance_enu, err))
        h_err.append(math.hypot(err[0], err[1]))
        assert np.all(np.abs(fix.vel_enu) < 4 * np.sqrt(np.diag(fix.vel_covariance_enu)) + 1e-3)
        # Both system clocks estimate the one receiver clock (GST = GPST here).
        for clock in fix.clock_m.values():
            assert clock == pytest.approx(epoch.clock[0], abs=5.0)
    # The SPP weights (sigma0/sin E) over-bound the simulated noise sqrt(a² + b²/sin² E),
    # so the normalised squared error must average below its 3 degrees of freedom.
    assert np.mean(nees) < 3.0
    assert np.sqrt(np.mean(np.square(h_err))) < 2.0


@pytest.fixture(scope="module")
def car_run(broadcast):
    """A 25 s stretch of the seed 004 car trial at 10 Hz, two antennas, slips injected."""
    scenario = scenarios.car(duration=25.0, seed=2, rate=10.0, static=2.0, oversample=2)
    slips = (SlipEvent(8.05, "G10", 7, antenna=1), SlipEvent(14.0, "E07", -3),
             SlipEvent(21.3, "G23", 2, antenna=0))
    cfg = SimulatorConfig(lever_arms=((0.75, 0.0, 1.0), (-0.75, 0.0, 1.0)), multipath=None,
                          slips=slips, half_cycle_resolve_s=0.0, seed=5)
    sim = GnssSimulator(broadcast, cfg)
    return scenario, slips, sim.run(scenario.trajectory, 10.0)


def test_doppler_agrees_with_the_phase_rate_on_a_moving_car(car_run):
    """Phase change + integrated Doppler leaves, per antenna, the receiver clock's phase noise
    (white frequency noise moves the offset, not the drift state: common to all satellites)
    plus measurement noise per satellite."""
    scenario, _, epochs = car_run
    assert np.max(np.linalg.norm(scenario.trajectory.v_enu, axis=1)) > 6.0
    worst, worst_clock = 0.0, 0.0
    for prev, curr in zip(epochs[:-1], epochs[1:]):
        for a in range(2):
            p, c = prev[a], curr[a]
            ip = {o.sat_id: i for i, o in enumerate(p.raw.obs)}
            res, sig = [], []
            for i, o in enumerate(c.raw.obs):
                if c.loss_of_lock[i]:
                    continue
                q = p.raw.obs[ip[o.sat_id]]
                res.append(doppler_phase_residual(q.carrier_cycles, o.carrier_cycles,
                                                  q.doppler_hz, o.doppler_hz, c.t - p.t))
                sig.append(math.hypot(o.cp_std_cycles * math.sqrt(2), o.doppler_std_hz * 0.1))
            lam = C / c.raw.obs[0].frequency_hz
            clock = (c.clock[0] - p.clock[0] - 0.5 * (c.clock[1] + p.clock[1]) * (c.t - p.t)) / lam
            res = np.array(res) - clock
            worst_clock = max(worst_clock, abs(np.median(res)) / np.median(sig))
            worst = max(worst, np.max(np.abs(res - np.median(res)) / np.array(sig)))
    assert worst < 5.0
    assert worst_clock < 3.0


def test_cycle_slips_appear_exactly_where_injected(car_run):
    _, slips, epochs = car_run
    found, flagged = set(), set()
    for prev, curr in zip(epochs[:-1], epochs[1:]):
        for a in range(2):
            p, c = prev[a], curr[a]
            amb_p = dict(zip([o.sat_id for o in p.raw.obs], p.truth.ambiguity))
            for o, n, lol in zip(c.raw.obs, c.truth.ambiguity, c.loss_of_lock):
                if o.sat_id in amb_p and n != amb_p[o.sat_id]:
                    found.add((round(c.t, 1), o.sat_id, a, int(n - amb_p[o.sat_id])))
                if lol and o.sat_id in amb_p:
                    flagged.add((round(c.t, 1), o.sat_id, a))
            ep = [AntennaEpoch([o.sat_id for o in e.raw.obs],
                               np.array([o.carrier_cycles for o in e.raw.obs]),
                               np.array([o.pseudorange_m for o in e.raw.obs]),
                               np.array([C / o.frequency_hz for o in e.raw.obs]),
                               doppler=np.array([o.doppler_hz for o in e.raw.obs]))
                  for e in (p, c)]
            detected = detect_slips_doppler(ep[0], ep[1], c.t - p.t)
            injected = {s for (t, s, aa, _) in found if t == round(c.t, 1) and aa == a}
            assert detected == injected, (c.t, a)
    expected = set()
    for ev in slips:
        t_epoch = math.ceil(ev.t * 10 - 1e-9) / 10
        for a in ((0, 1) if ev.antenna is None else (ev.antenna,)):
            expected.add((t_epoch, ev.sat_id, a, ev.cycles))
    assert found == expected
    assert flagged == {f[:3] for f in found}


def test_satellite_counts_obey_the_shading_schedule_and_outages(broadcast):
    shading = tuple(scenarios.shading_schedule(200.0, first=20.0, length=30.0, gap=10.0))
    cfg = dataclasses.replace(EXACT, shading=shading, outages=((170.0, 180.0),))
    open_sky = _static(GnssSimulator(broadcast, EXACT), 100, dt=2.0)
    shaded = _static(GnssSimulator(broadcast, cfg), 100, dt=2.0)
    seen_limits = set()
    for (free,), (epoch,) in zip(open_sky, shaded):
        n_free, n = len(free.raw.obs), len(epoch.raw.obs)
        limit = next((w.max_satellites for w in shading if w.t_start <= epoch.t < w.t_end), None)
        if 170.0 <= epoch.t < 180.0:
            assert n == 0
        elif limit is None:
            assert n == n_free
        else:
            seen_limits.add(limit)
            assert n == min(limit, n_free)
            # The kept satellites are the highest at the window's start.
            assert {o.sat_id for o in epoch.raw.obs} <= {o.sat_id for o in free.raw.obs}
    assert seen_limits == {6, 4, 3, 2}
    assert min(len(e.raw.obs) for (e,) in open_sky) >= 8


def test_same_seed_same_output_and_reacquisition_after_outage(broadcast):
    cfg = SimulatorConfig(lever_arms=((0, 0, 0), (1, 0, 0)), slip_rate=0.02, seed=9,
                          outages=((10.0, 14.0),))
    runs = [_static(GnssSimulator(broadcast, cfg), 30) for _ in range(2)]
    other = _static(GnssSimulator(broadcast, dataclasses.replace(cfg, seed=10)), 30)
    for a, b, c in zip(*runs, other):
        for x, y, z in zip(a, b, c):
            assert [dataclasses.astuple(o) for o in x.raw.obs] == \
                   [dataclasses.astuple(o) for o in y.raw.obs]
            if x.raw.obs:
                assert x.raw.obs[0].pseudorange_m != z.raw.obs[0].pseudorange_m
    after = runs[0][14][0]
    assert after.t == 14.0 and after.loss_of_lock.all()
    assert all(o.lock_ms == 0.0 for o in after.raw.obs)
    assert sum(e[0].loss_of_lock.sum() for e in runs[0][1:10]) > 0   # random slips happen


def test_half_cycle_flags_and_lock_time(broadcast):
    # GPS L1 C/A (data channel): half-cycle ambiguity until 6 s of lock; Galileo E1-C (pilot):
    # none, the phase is valid and integer from the first epoch.
    cfg = dataclasses.replace(EXACT, half_cycle_resolve_s=6.0, seed=3)
    epochs = [e for (e,) in _static(GnssSimulator(broadcast, cfg), 10)]
    offsets = set()
    for e in epochs:
        assert {o.system for o in e.raw.obs} == {"G", "E"}
        for o, n in zip(e.raw.obs, e.truth.ambiguity):
            data = o.system == "G"
            assert o.half_cycle_valid == (e.t >= 6.0 or not data)
            assert o.lock_ms == pytest.approx(e.t * 1000.0)
            frac = n - math.floor(n)
            if data and e.t < 6.0:
                offsets.add(frac)
            else:
                assert frac == 0.0
    assert offsets == {0.0, 0.5}     # some GPS channels started on the inverted phase
    last = epochs[-1]
    first = dict(zip([o.sat_id for o in epochs[0].raw.obs], epochs[0].truth.ambiguity))
    for o in last.raw.obs:
        assert o.half_cycle_subtracted == (first[o.sat_id] % 1.0 == 0.5)
    cn0 = [o.cn0_dbhz for o in last.raw.obs]
    assert np.all(np.diff(np.array(cn0)[np.argsort(last.truth.elevation)]) > 0)


def test_time_reference_is_gnss_time(broadcast):
    sim = GnssSimulator(broadcast, EXACT, start_gps=1440433800.0, t0=100.0)
    (epoch,) = sim.epoch(101.0, LAT, LON, H, np.zeros(3), Q_NB)
    t, t_gps = time_reference(epoch, 20e-9, np.random.default_rng(0))
    assert t == 101.0 and t_gps == pytest.approx(1440433801.0, abs=1e-7)


# ------------------------------------------------------------------------------- clock
def test_clock_process_noise_is_van_loans_exact_discretisation():
    spec = OscillatorSpec(h0=2e-19, h_2=2e-20, aging_psd=1e-9)
    F = np.array([[0, 1, 0], [0, 0, 1], [0, 0, 0]], float)
    Qc = np.diag([0.5 * C ** 2 * spec.h0, 2 * math.pi ** 2 * C ** 2 * spec.h_2, spec.aging_psd])
    for dt in (0.1, 1.0, 7.0):
        phi, qk = van_loan(F, Qc, dt)
        assert np.allclose(transition(dt), phi)
        assert np.allclose(process_noise(spec, dt), qk, rtol=1e-7, atol=0)


@pytest.mark.parametrize("spec", [TCXO, OCXO])
def test_simulated_clock_has_the_oscillators_allan_deviation(spec):
    spec = dataclasses.replace(spec, drift0=0.0, offset0=0.0)
    t = np.arange(0.0, 20000.0, 1.0)
    x = simulate_clock(spec, t, np.random.default_rng(1))[:, 0] / C
    taus = np.array([1.0, 10.0, 100.0, 1000.0])
    taus_out, adev, _, _ = allantools.oadev(x, rate=1.0, data_type="phase", taus=taus)
    expected = np.sqrt(allan_variance(spec, taus_out))
    assert np.allclose(adev, expected, rtol=0.25)


# --------------------------------------------------------------------------- multipath
def test_multipath_is_a_gauss_markov_process_scaled_by_elevation():
    model = MultipathModel(code_sigma0=2.0, phase_sigma0=0.02, code_tau=5.0, phase_tau=20.0)
    proc = MultipathProcess(model, np.random.default_rng(0))
    el = math.radians(30.0)
    series = np.array([proc.step("k", k * 0.5, el) for k in range(40000)])
    code_sigma, phase_sigma = model.sigma(el)
    assert code_sigma == pytest.approx(2.0 * math.exp(-1.5))
    assert np.std(series[:, 0]) == pytest.approx(code_sigma, rel=0.05)
    assert np.std(series[:, 1]) == pytest.approx(phase_sigma, rel=0.15)
    for col, tau in ((0, 5.0), (1, 20.0)):
        s = series[:, col]
        lag = int(tau / 0.5)
        corr = np.corrcoef(s[:-lag], s[lag:])[0, 1]
        assert corr == pytest.approx(math.exp(-1.0), abs=0.06)
    assert model.sigma(0.0) == (2.0, 0.02)
