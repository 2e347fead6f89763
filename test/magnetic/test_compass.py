"""Tilt-compensated magnetic heading: geometry against independent truth, the seed's eq. 2.3.1,
the variance against Monte Carlo, and the compass pipeline."""
import numpy as np
import pytest

from ins_gnss_ros.magnetic.compass import (MagneticCompass, azimuth_variance, level_field,
                                           magnetic_azimuth)
from ins_gnss_ros.magnetic.ellipsoid_fit import HardSoftIron
from ins_gnss_ros.nav.conventions import azimuth_from_yaw, flu_to_rfu, wrap_pi
from ins_gnss_ros.nav.rotations import dcm_from_euler

DEG = np.pi / 180
# St Petersburg (seed 004's ITMO/Elektropribor), WMM2025 about 2026: ~12 deg E, dip ~74 deg.
DECL, DIP, TOTAL = 12.0 * DEG, 74.0 * DEG, 53e-6


def _field_enu(decl=DECL, dip=DIP, total=TOTAL):
    h = total * np.cos(dip)
    return np.array([h * np.sin(decl), h * np.cos(decl), -total * np.sin(dip)])


def _body_field(roll, pitch, yaw, f_enu=None):
    c_nb = dcm_from_euler(roll, pitch, yaw)
    return np.einsum("...ji,j->...i", c_nb, _field_enu() if f_enu is None else f_enu)


def test_level_by_hand():
    # Facing east (yaw 0) in a field pointing north and down: forward = east, left = north.
    assert magnetic_azimuth([0.0, 20e-6, -45e-6], 0.0, 0.0) == pytest.approx(np.pi / 2)
    # Facing magnetic north: azimuth 0 (not 2π).
    assert magnetic_azimuth([20e-6, 0.0, -45e-6], 0.0, 0.0) == pytest.approx(0.0)


def test_heading_under_large_tilts():
    rng = np.random.default_rng(1)
    n = 500
    roll, pitch = rng.uniform(-60, 60, n) * DEG, rng.uniform(-60, 60, n) * DEG
    yaw = rng.uniform(-np.pi, np.pi, n)
    az = magnetic_azimuth(_body_field(roll, pitch, yaw), roll, pitch)
    expected = azimuth_from_yaw(yaw) - DECL  # magnetic azimuth = true azimuth - declination
    assert np.max(abs(wrap_pi(az - expected))) < 1e-9
    assert np.all((az >= 0) & (az < 2 * np.pi))


def test_seed_eq_2_3_1_matches_level_frame():
    """The extraction's reconstructed C_{h_k,o} (seed 004 eq. 2.3.1), with the seed's roll θ
    (right wing down = ROS roll) and pitch ψ (nose up = -ROS pitch) on body x-starboard,
    y-forward axes, gives F_Ek = -F_Ly, F_Nk = F_Lx, F_Hk = F_Lz."""
    rng = np.random.default_rng(2)
    for _ in range(20):
        roll, pitch = rng.uniform(-1, 1, 2)
        f_b = rng.normal(size=3)
        th, psi = roll, -pitch
        c = np.array([[np.cos(th), 0, np.sin(th)],
                      [np.sin(psi) * np.sin(th), np.cos(psi), -np.sin(psi) * np.cos(th)],
                      [-np.cos(psi) * np.sin(th), np.sin(psi), np.cos(psi) * np.cos(th)]])
        f_ek, f_nk, f_hk = c @ flu_to_rfu(f_b)
        f_l = level_field(f_b, roll, pitch)
        np.testing.assert_allclose([-f_ek, f_nk, f_hk], [f_l[1], f_l[0], f_l[2]], atol=1e-12)
        assert np.arctan2(-f_ek, f_nk) % (2 * np.pi) == pytest.approx(magnetic_azimuth(f_b, roll, pitch))


def test_variance_matches_monte_carlo():
    rng = np.random.default_rng(3)
    roll, pitch, yaw = 25 * DEG, -15 * DEG, 40 * DEG
    f_b = _body_field(roll, pitch, yaw)
    sf, sr, sp = 150e-9, 0.3 * DEG, 0.2 * DEG
    n = 40000
    az = magnetic_azimuth(f_b + rng.normal(0, sf, (n, 3)), roll + rng.normal(0, sr, n),
                          pitch + rng.normal(0, sp, n))
    mc = np.var(wrap_pi(az - magnetic_azimuth(f_b, roll, pitch)))
    assert azimuth_variance(f_b, roll, pitch, sf, sr, sp) == pytest.approx(mc, rel=0.05)
    # Noise only: σ_A = σ_F / H.
    h = TOTAL * np.cos(DIP)
    assert azimuth_variance(f_b, roll, pitch, sf, 0.0, 0.0) == pytest.approx((sf / h) ** 2, rel=1e-9)


def test_pipeline_calibration_declination_and_bias():
    hsi = HardSoftIron(offset=[5e-6, -3e-6, 8e-6], matrix=[[1.05, 0.02, 0], [0.02, 0.95, 0.01], [0, 0.01, 1.0]])
    compass = MagneticCompass(calibration=hsi, heading_bias=1.5 * DEG)
    roll, pitch, yaw = 10 * DEG, -5 * DEG, 100 * DEG
    # The installation reads 1.5 deg too far clockwise: a magnetometer turned by -1.5 deg of yaw.
    raw = hsi.distort(_body_field(roll, pitch, yaw - 1.5 * DEG))
    reading, status = compass.update(0.0, raw, roll, pitch, DECL)
    assert status is None
    assert reading.true_azimuth == pytest.approx(azimuth_from_yaw(yaw), abs=1e-9)
    assert reading.magnetic_azimuth == pytest.approx(azimuth_from_yaw(yaw) - DECL, abs=1e-9)
    assert reading.variance > 0
