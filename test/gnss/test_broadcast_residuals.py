"""The independent GNSS simulator: its truth differs from the broadcast models by the residuals
asked for, and its Doppler stays the rate of its carrier phase.

Truth: the same seed without residuals (everything else identical, noise and multipath off),
the code-minus-phase split of ionosphere (opposite signs) and range terms (same sign), and the
carrier phase itself for the Doppler (phase change over 1 s = -Doppler)."""
import math

import numpy as np
import pytest

from ins_gnss_ros.gnss import ephemeris_data
from ins_gnss_ros.gnss.atmosphere import tropo_delay
from ins_gnss_ros.gnss.broadcast_residuals import BroadcastResiduals
from ins_gnss_ros.gnss.differences import NoiseModel
from ins_gnss_ros.gnss.simulator import GnssSimulator, SimulatorConfig
from ins_gnss_ros.nav.rotations import quat_from_euler

LAT, LON, H = math.radians(40.1), math.radians(-105.1), 1580.0
EXACT = SimulatorConfig(noise=NoiseModel(0.0, 0.0, 0.0, 0.0), doppler_sigma=(0.0, 0.0),
                        multipath=None, half_cycle_resolve_s=0.0, seed=3)


def _epochs(residuals, times=(0.0, 1.0)):
    sim = GnssSimulator(ephemeris_data.load(LON),
                        SimulatorConfig(**{**vars(EXACT), "residuals": residuals}))
    return [sim.epoch(t, LAT, LON, H, np.zeros(3), quat_from_euler(0.0, 0.0, 0.3))[0]
            for t in times]


def test_zero_residuals_are_the_broadcast_models():
    plain = _epochs(None)
    zero = _epochs(BroadcastResiduals(1.0, 0.0, 0.0, 0.0))
    for a, b in zip(plain, zero):
        assert [(o.pseudorange_m, o.doppler_hz, o.carrier_cycles) for o in a.raw.obs] == \
            [(o.pseudorange_m, o.doppler_hz, o.carrier_cycles) for o in b.raw.obs]


def test_residuals_have_their_sizes():
    sizes = BroadcastResiduals(iono_scale=2.0, iono_satellite_sigma=0.25,
                               tropo_zenith_sigma=0.05, sisre_sigma=1.0)
    plain, first = _epochs(None, (0.0,))[0], _epochs(sizes, (0.0,))[0]
    lam = np.array([299792458.0 / o.frequency_hz for o in first.raw.obs])
    code = np.array([o.pseudorange_m for o in first.raw.obs]) - \
        [o.pseudorange_m for o in plain.raw.obs]
    phase = lam * (np.array([o.carrier_cycles for o in first.raw.obs]) -
                   [o.carrier_cycles for o in plain.raw.obs])
    iono_extra = (code - phase) / 2.0             # true minus Klobuchar, m
    range_extra = (code + phase) / 2.0            # orbit + clock + troposphere residual, m
    ratio = 1.0 + iono_extra / plain.truth.iono   # true / Klobuchar
    assert len(ratio) >= 8
    assert np.mean(ratio) == pytest.approx(2.0, abs=0.25)
    assert 0.1 < np.std(ratio) / 2.0 < 0.45
    zenith = tropo_delay(LAT, H, math.pi / 2)
    tropo_extra = (first.truth.tropo - plain.truth.tropo) / (plain.truth.tropo / zenith)
    assert np.ptp(tropo_extra) < 1e-9 and abs(tropo_extra[0]) < 0.25  # one zenith residual
    sisre = range_extra - (first.truth.tropo - plain.truth.tropo)
    assert 0.4 < np.sqrt(np.mean(sisre ** 2)) < 1.8


def test_the_doppler_carries_the_residuals_rates():
    """The carrier phase moves by minus the mean Doppler (a static antenna, 1 s apart), up to a
    term common to all satellites (the receiver clock's drift rate over the second). The
    residuals are exaggerated so that a missing rate would show: 100 m of orbit error moves
    the range by up to 0.015 m/s (0.08 cycles in 1 s)."""
    a, b = _epochs(BroadcastResiduals(iono_scale=20.0, sisre_sigma=100.0))
    d_phase = np.array([o.carrier_cycles for o in b.raw.obs]) - \
        [o.carrier_cycles for o in a.raw.obs]
    mean_doppler = (np.array([o.doppler_hz for o in a.raw.obs]) +
                    [o.doppler_hz for o in b.raw.obs]) / 2.0
    misfit = d_phase + mean_doppler
    assert np.abs(misfit - misfit.mean()).max() < 1e-3  # cycles


def test_the_receivers_covariance_carries_the_residuals_budget():
    """A static receiver's single-point fix (code noise, multipath and the residuals), one
    epoch per seed: the covariance it reports covers the error it has (a consistent 3-D
    covariance gives a mean squared Mahalanobis distance of 3), where the noise's alone, 0.5 m
    for metres of model error, did not."""
    from ins_gnss_ros.gnss.simulator import solve_fix
    from ins_gnss_ros.nav.earth import ecef_to_enu, geodetic_to_ecef

    d2 = []
    for seed in range(1, 21):
        sim = GnssSimulator(ephemeris_data.load(LON),
                            SimulatorConfig(seed=seed, residuals=BroadcastResiduals()))
        fix = solve_fix(sim.epoch(0.0, LAT, LON, H, np.zeros(3),
                                  quat_from_euler(0.0, 0.0, 0.3))[0], sim)
        e = ecef_to_enu(geodetic_to_ecef(fix.lat, fix.lon, fix.h), LAT, LON, H)
        d2.append(float(e @ np.linalg.solve(fix.covariance_enu, e)))
    assert 1.0 < np.mean(d2) < 6.0, d2
    assert max(d2) < 25.0
