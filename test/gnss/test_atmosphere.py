"""Klobuchar ionosphere and Saastamoinen troposphere against ICD and published values."""
import math

import pytest

from ins_gnss_ros.gnss.atmosphere import (black_eisner_mapping, klobuchar_delay,
                                          saastamoinen_zenith, standard_atmosphere, tropo_delay)

C = 299792458.0


def test_klobuchar_daytime_peak_is_dc_plus_amplitude():
    """IS-GPS-200 Figure 20-4: at the IPP local time 14:00 (x = 0) the vertical delay is
    DC + AMP = 5 ns + AMP; at zenith the obliquity factor is F = 1 + 16 (0.53 - 0.5)^3.
    With alpha = (a0, 0, 0, 0) AMP = a0 whatever the geomagnetic latitude.  A receiver at
    longitude 0 seeing a satellite at zenith (azimuth 0) has its IPP at longitude 0, so the
    local time is GPS time of day."""
    alpha, beta = (30e-9, 0.0, 0.0, 0.0), (100000.0, 0.0, 0.0, 0.0)
    f = 1.0 + 16.0 * 0.03 ** 3
    delay = klobuchar_delay(50400.0, 0.3, 0.0, math.pi / 2, 0.0, alpha, beta)
    assert delay == pytest.approx(f * (5e-9 + 30e-9) * C, rel=1e-12)


def test_klobuchar_night_value():
    """Outside |x| < 1.57 the model is the constant night-time 5 ns times F."""
    alpha, beta = (30e-9, 0.0, 0.0, 0.0), (100000.0, 0.0, 0.0, 0.0)
    elevation = math.radians(30.0)
    f = 1.0 + 16.0 * (0.53 - 30.0 / 180.0) ** 3
    # IPP longitude from psi = 0.0137 / (E + 0.11) - 0.022 semicircles (azimuth 90 deg).
    psi = 0.0137 / (30 / 180 + 0.11) - 0.022
    lam_i = psi / math.cos(0.3 / math.pi * math.pi)  # phi_i = phi_u for azimuth 90 deg
    t_local_2am = (2 * 3600 - 4.32e4 * lam_i) % 86400
    delay = klobuchar_delay(t_local_2am, 0.3, 0.0, elevation, math.pi / 2, alpha, beta)
    assert delay == pytest.approx(f * 5e-9 * C, rel=1e-12)


def test_klobuchar_frequency_scaling_and_magnitude():
    """L2 delay = (f1/f2)^2 x L1 (IS-GPS-200 20.3.3.5.2.5); with typical broadcast
    coefficients mid-latitude daytime zenith delays are a few metres."""
    alpha = (1.1176e-8, 7.4506e-9, -5.9605e-8, -5.9605e-8)
    beta = (90112.0, 0.0, -196608.0, -65536.0)
    lat, lon = math.radians(40.0), math.radians(-105.0)
    t = 20 * 3600.0  # 13:00 local mean time at -105 deg
    l1 = klobuchar_delay(t, lat, lon, math.radians(80), 1.0, alpha, beta)
    l2 = klobuchar_delay(t, lat, lon, math.radians(80), 1.0, alpha, beta, 1227.60e6)
    assert l2 == pytest.approx(l1 * (77 / 60) ** 2)
    assert 1.5 < l1 < 10.0
    low = klobuchar_delay(t, lat, lon, math.radians(10), 1.0, alpha, beta)
    assert 2.0 < low / l1 < 3.5  # obliquity factor F(10 deg) / F(80 deg)


@pytest.mark.parametrize("h, pressure, temperature", [
    # ISO 2533 / ICAO standard atmosphere table values at geometric heights.
    (0.0, 1013.25, 288.15), (1000.0, 898.76, 281.651), (2000.0, 795.01, 275.154),
    (5000.0, 540.48, 255.676)])
def test_standard_atmosphere_against_icao_table(h, pressure, temperature):
    p, t, e = standard_atmosphere(h)
    assert p == pytest.approx(pressure, abs=0.05)
    assert t == pytest.approx(temperature, abs=1e-3)
    assert 0.0 < e < p


def test_saastamoinen_zenith_hydrostatic_published_value():
    """Davis et al. (1985): ZHD = 2.2768 mm/hPa x P / (1 - 0.00266 cos 2 phi - 0.28e-6 H):
    2.3069 m for 1013.25 hPa at 45 deg latitude and sea level; the wet delay of a standard
    atmosphere is about 0.1 m."""
    hydro, wet = saastamoinen_zenith(math.radians(45.0), 0.0, pressure=1013.25)
    assert hydro == pytest.approx(2.3069, abs=1e-4)
    assert 0.05 < wet < 0.2


def test_mapping_function():
    assert black_eisner_mapping(math.pi / 2) == pytest.approx(1.0, abs=1e-6)
    # At 5 deg the slant factor of modern mapping functions (Niell 1996) is about 10.2,
    # far below the flat-Earth 1/sin(5 deg) = 11.5.
    assert black_eisner_mapping(math.radians(5.0)) == pytest.approx(10.2, rel=0.02)
    assert tropo_delay(0.7, 1580.0, math.radians(90.0)) == pytest.approx(
        sum(saastamoinen_zenith(0.7, 1580.0)), rel=1e-6)
    assert tropo_delay(0.7, 1580.0, -0.1) == 0.0
