"""Satellite orbit and clock from broadcast ephemerides, against an independent formulation.

No PyPI GNSS library installs cleanly into this venv without pulling pinned plotting
stacks (gnss_lib_py needs kaleido/plotly/xarray<=2024.7), so the reference orbit is
written here differently from the library: eccentric anomaly by scipy's brentq bracketing
root finder, true anomaly by the half-angle formula, and the orbit-to-ECEF transformation
as a product of elementary rotation matrices R3(-Omega) R1(-i), applied to the real
ephemerides decoded from the recorded stream.
"""
import math

import numpy as np
import pymap3d
import pytest
from conftest import shared_path
from scipy.optimize import brentq

from ins_gnss_ros.gnss.constants import FREQ_E1, FREQ_E5A, FREQ_E5B, FREQ_L1, FREQ_L2
from ins_gnss_ros.gnss.ephemeris import (KeplerEphemeris, accuracy_m,
                                         earth_rotation_correction, elevation_azimuth,
                                         group_delay, satellite_at_reception, sat_position)
from ins_gnss_ros.gnss.nav_decode import NavDataAssembler
from ins_gnss_ros.gnss.stream import Decoder

C = 299792458.0
WE = 7.2921151467e-5  # IS-GPS-200 Table 20-IV / Galileo OS SIS ICD 5.1.1


def _r1(a):
    c, s = math.cos(a), math.sin(a)
    return np.array([[1, 0, 0], [0, c, s], [0, -s, c]])


def _r3(a):
    c, s = math.cos(a), math.sin(a)
    return np.array([[c, s, 0], [-s, c, 0], [0, 0, 1]])


def reference_orbit(eph, t):
    """Independent textbook evaluation of the broadcast orbit and clock at GPS time t.

    BeiDou (BDS-SIS-ICD-B1I 3.0 Table 5-11): CGCS2000 mu and Earth rate, toe counted in
    BDT seconds of week (BDT = GPST - 14 s)."""
    mu = 3.986005e14 if eph.system == "G" else 3.986004418e14
    we = 7.2921150e-5 if eph.system == "C" else WE
    toe_sow = (eph.toe - 14.0) % 604800 if eph.system == "C" else eph.toe % 604800
    a = eph.sqrt_a ** 2
    tk = t - eph.toe
    mean = eph.m0 + (math.sqrt(mu / a ** 3) + eph.delta_n) * tk
    ecc = brentq(lambda x: x - eph.e * math.sin(x) - mean, mean - 1.0, mean + 1.0, xtol=1e-15)
    nu = 2.0 * math.atan(math.sqrt((1 + eph.e) / (1 - eph.e)) * math.tan(ecc / 2.0))
    arg = nu + eph.omega
    u = arg + eph.cuc * math.cos(2 * arg) + eph.cus * math.sin(2 * arg)
    r = a * (1 - eph.e * math.cos(ecc)) + eph.crc * math.cos(2 * arg) + eph.crs * math.sin(2 * arg)
    inc = eph.i0 + eph.idot * tk + eph.cic * math.cos(2 * arg) + eph.cis * math.sin(2 * arg)
    node = eph.omega0 + (eph.omega_dot - we) * tk - we * toe_sow
    pos = _r3(-node) @ _r1(-inc) @ np.array([r * math.cos(u), r * math.sin(u), 0.0])
    f_rel = -2.0 * math.sqrt(mu) / C ** 2
    dt = t - eph.toc
    clock = eph.af0 + eph.af1 * dt + eph.af2 * dt ** 2 + f_rel * eph.e * eph.sqrt_a * math.sin(ecc)
    return pos, clock


@pytest.fixture(scope="module")
def ephemerides():
    data = shared_path("data", "walk_0827", "gnss_1730.ubx").read_bytes()
    # Only RXM-SFRBX frames are parsed (fast); the reception time is that of the first epoch,
    # 2025-08-28 17:30:39.75 GPST (GPS week 2381), which resolves the week of toe and toc.
    frames, pos = [], 0
    while pos < len(data):
        if data[pos] == 0xB5:
            end = pos + 8 + int.from_bytes(data[pos + 4:pos + 6], "little")
            if data[pos + 2:pos + 4] == b"\x02\x13":
                frames.append(data[pos:end])
        else:
            end = data.index(b"\n", pos) + 1
        pos = end
    assembler = NavDataAssembler()
    for record in Decoder().feed(b"".join(frames)):
        assembler.add(record, 2381 * 604800.0 + 408639.75)
    assert {e.system for e in assembler.ephemerides.values()} == {"G", "E", "C"}
    return list(assembler.ephemerides.values())


def test_positions_match_independent_formulation(ephemerides):
    worst_pos = worst_clock = 0.0
    for eph in ephemerides:
        for dt in (-7200.0, -1800.0, 0.0, 900.0, 3600.0, 7200.0):
            xyz, clock, _, _ = sat_position(eph, eph.toe + dt)
            ref_xyz, ref_clock = reference_orbit(eph, eph.toe + dt)
            worst_pos = max(worst_pos, np.linalg.norm(xyz - ref_xyz))
            worst_clock = max(worst_clock, abs(clock - ref_clock))
    assert worst_pos < 0.01          # the done-when criterion: 1 cm
    assert worst_clock * C < 0.001   # clock to 1 mm of range


def test_velocity_is_derivative_of_position(ephemerides):
    for eph in ephemerides:
        t = eph.toe + 1234.5
        _, _, vel, drift = sat_position(eph, t)
        plus, clk_plus = reference_orbit(eph, t + 0.5)
        minus, clk_minus = reference_orbit(eph, t - 0.5)
        assert np.allclose(vel, plus - minus, atol=1e-3)
        assert drift == pytest.approx(clk_plus - clk_minus, abs=1e-14)


def test_radius_and_speed_are_physical(ephemerides):
    for eph in ephemerides:
        xyz, _, vel, _ = sat_position(eph, eph.toe)
        a = eph.sqrt_a ** 2
        assert a * (1 - eph.e) - 2000 < np.linalg.norm(xyz) < a * (1 + eph.e) + 2000
        # Inertial speed from vis-viva; ECEF velocity adds omega x r.
        inertial = vel + np.cross([0, 0, eph.omega_e], xyz)
        mu = 3.986e14
        expected = math.sqrt(mu * (2 / np.linalg.norm(xyz) - 1 / a))
        assert np.linalg.norm(inertial) == pytest.approx(expected, rel=1e-3)


def test_week_crossover():
    """A time just after the week rollover evaluated against a toe from the previous week
    equals the continuous-time result (IS-GPS-200 20.3.3.4.3)."""
    eph = KeplerEphemeris("G", 1, toe=2381 * 604800.0 + 604000.0, toc=2381 * 604800.0 + 604000.0,
                          sqrt_a=5153.6, e=0.01, m0=0.3, delta_n=4e-9, omega0=1.0, i0=0.96,
                          omega=0.5, idot=1e-10, omega_dot=-8e-9, cuc=1e-6, cus=5e-6, crc=200.0,
                          crs=20.0, cic=1e-7, cis=-1e-7, af0=1e-4, af1=1e-12, af2=0.0, tgd=0.0,
                          bgd_e5a=0.0, iode=1, health=0, accuracy_index=0)
    t = 2382 * 604800.0 + 300.0
    xyz, clock, _, _ = sat_position(eph, t)
    ref, ref_clock = reference_orbit(eph, t)
    assert np.linalg.norm(xyz - ref) < 0.01 and clock == pytest.approx(ref_clock, abs=1e-15)


def test_group_delays():
    gps = KeplerEphemeris("G", 1, 0, 0, 5153.6, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0,
                          tgd=-8e-9, bgd_e5a=0.0, iode=0, health=0, accuracy_index=0)
    gamma = (77 / 60) ** 2  # IS-GPS-200: gamma = (1575.42/1227.6)^2 = (77/60)^2
    assert group_delay(gps, FREQ_L1) == -8e-9
    assert group_delay(gps, FREQ_L2) == pytest.approx(gamma * -8e-9)
    # The L1/L2 ionosphere-free combination needs no group delay.
    assert (gamma * group_delay(gps, FREQ_L1) - group_delay(gps, FREQ_L2)) == pytest.approx(0, abs=1e-20)
    gal = KeplerEphemeris("E", 1, 0, 0, 5440.6, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0,
                          tgd=3e-9, bgd_e5a=2e-9, iode=0, health=0, accuracy_index=0)
    assert group_delay(gal, FREQ_E1) == 3e-9
    assert group_delay(gal, FREQ_E5B) == pytest.approx((154 / 118) ** 2 * 3e-9)
    # E1/E5a ionosphere-free with the I/NAV clock: BGD(E1,E5b) - BGD(E1,E5a).
    ga = (154 / 115) ** 2
    combo = (ga * group_delay(gal, FREQ_E1) - group_delay(gal, FREQ_E5A)) / (ga - 1)
    assert combo == pytest.approx(3e-9 - 2e-9)


def test_sagnac_rotation_matches_first_order_formula():
    """Range change of the Earth-rotation correction = (omega/c)(x_s y_r - y_s x_r) to first
    order (Groves 2nd ed. eq. 8.41; RTCA DO-229)."""
    rx = np.array(pymap3d.geodetic2ecef(40.0, -105.0, 1600.0))
    sat = np.array([-1.2e7, -2.0e7, 1.3e7])
    tau = np.linalg.norm(sat - rx) / C
    rotated, _ = earth_rotation_correction(sat, np.zeros(3), tau)
    change = np.linalg.norm(rotated - rx) - np.linalg.norm(sat - rx)
    assert change == pytest.approx(WE / C * (sat[0] * rx[1] - sat[1] * rx[0]), abs=2e-3)


def test_elevation_azimuth_against_pymap3d():
    rx_geo = (40.0966916, -105.1471665, 1580.0)
    rx = np.array(pymap3d.geodetic2ecef(*rx_geo))
    for sat in ([-1.2e7, -2.0e7, 1.3e7], [1.0e7, -2.2e7, 0.5e7], [-2.5e7, 0.3e7, 0.9e7]):
        az, el, _ = pymap3d.ecef2aer(*sat, *rx_geo)
        elevation, azimuth = elevation_azimuth(rx, np.array(sat))
        assert math.degrees(elevation) == pytest.approx(el, abs=1e-7)
        assert math.degrees(azimuth) == pytest.approx(az, abs=1e-7)


def test_transmission_time_from_pseudorange(ephemerides):
    """With an exact pseudorange built from the light-time equation solved in an inertial
    frame, the satellite state at reception reproduces the geometric range."""
    rx = np.array(pymap3d.geodetic2ecef(40.0966916, -105.1471665, 1580.0))
    eph = ephemerides[0]
    t_rx = eph.toe + 600.0
    # Inertial frame = ECEF axes at t_rx: a point fixed in inertial space has ECEF
    # coordinates that turn by R3(omega * tau) (passive rotation) while the signal flies.
    tau = 0.07
    for _ in range(10):
        sat_tx, clock = reference_orbit(eph, t_rx - tau)
        sat_inertial = _r3(WE * tau) @ sat_tx
        tau = np.linalg.norm(sat_inertial - rx) / C
    pseudorange = C * tau + C * 0.0 - C * clock  # receiver clock 0, satellite clock included
    xyz, sv_clock, _, _ = satellite_at_reception(eph, t_rx, pseudorange, rx)
    assert np.linalg.norm(xyz - sat_inertial) < 0.01
    assert np.linalg.norm(xyz - rx) - C * sv_clock == pytest.approx(pseudorange, abs=0.01)


def test_broadcast_accuracy_from_ura_and_sisa_indices():
    assert accuracy_m("G", 0) == 2.4 and accuracy_m("C", 14) == 6144.0
    assert math.isnan(accuracy_m("G", 15))
    assert [accuracy_m("E", i) for i in (49, 50, 75, 100)] == pytest.approx([0.49, 0.5, 1.0, 2.0])
    assert math.isnan(accuracy_m("E", 126))   # no accuracy prediction available
