"""Broadcast ionosphere and standard troposphere delay models for single-point positioning.

* Ionosphere: the GPS broadcast (Klobuchar) model, IS-GPS-200 §20.3.3.5.2.5 and Figure
  20-4, with the alpha/beta of LNAV subframe 4 page 18 or defaults supplied by the caller.
* Troposphere: Saastamoinen (1972) zenith delays in the form of Davis et al. (1985) for the
  hydrostatic part, with pressure, temperature and humidity from the standard atmosphere
  (ISO 2533, the usual practice when no meteorological data are available),
  mapped to the slant direction with the Black & Eisner (1984) mapping function
  m(E) = 1.001 / sqrt(0.002001 + sin^2 E) quoted in RTCA DO-229 §A.4.2.4.
"""
import math

from .constants import C_LIGHT, FREQ_L1


def klobuchar_delay(t_gps, lat, lon, elevation, azimuth, alpha, beta, frequency_hz=FREQ_L1):
    """Ionospheric group delay of the GPS broadcast model.

    Parameters
    ----------
    t_gps : float
        GPS time [s] (only the time of day matters).
    lat, lon : float
        Receiver geodetic latitude and longitude [rad].
    elevation, azimuth : float
        Satellite elevation and azimuth (clockwise from north) [rad].
    alpha : sequence of 4 float
        Amplitude coefficients [s, s/semicircle, s/semicircle^2, s/semicircle^3].
    beta : sequence of 4 float
        Period coefficients [s, s/semicircle, ...].
    frequency_hz : float
        Carrier frequency; the L1 delay is scaled by (f_L1 / f)^2.

    Returns
    -------
    float
        Slant group delay [m] (positive: the pseudorange is too long).
    """
    # The ICD works in semicircles: convert the angles once.
    el_sc = elevation / math.pi
    psi = 0.0137 / (el_sc + 0.11) - 0.022                       # Earth angle to the IPP
    phi_i = min(max(lat / math.pi + psi * math.cos(azimuth), -0.416), 0.416)
    lam_i = lon / math.pi + psi * math.sin(azimuth) / math.cos(phi_i * math.pi)
    phi_m = phi_i + 0.064 * math.cos((lam_i - 1.617) * math.pi)  # geomagnetic latitude
    local_time = (4.32e4 * lam_i + t_gps) % 86400.0
    slant = 1.0 + 16.0 * (0.53 - el_sc) ** 3
    amplitude = max(0.0, sum(a * phi_m ** n for n, a in enumerate(alpha)))
    period = max(72000.0, sum(b * phi_m ** n for n, b in enumerate(beta)))
    x = 2.0 * math.pi * (local_time - 50400.0) / period
    delay = 5.0e-9
    if abs(x) < 1.57:
        delay += amplitude * (1.0 - x ** 2 / 2.0 + x ** 4 / 24.0)
    return slant * delay * C_LIGHT * (FREQ_L1 / frequency_hz) ** 2


def standard_atmosphere(h):
    """Pressure [hPa], temperature [K] and water-vapour pressure [hPa] at height `h` [m]
    from the ISO 2533 standard atmosphere troposphere (sea level 1013.25 hPa, 288.15 K,
    lapse rate 6.5 K/km, exponent g0 M / (R L) = 5.25588) with 50 % relative humidity
    (Magnus formula for the saturation pressure)."""
    h = max(h, -500.0)
    geopotential = 6356766.0 * h / (6356766.0 + h)  # ISO 2533 works in geopotential height
    temperature = 288.15 - 6.5e-3 * geopotential
    pressure = 1013.25 * (temperature / 288.15) ** 5.25588
    celsius = temperature - 273.15
    vapour = 0.5 * 6.1078 * math.exp(17.27 * celsius / (celsius + 237.3))
    return pressure, temperature, vapour


def saastamoinen_zenith(lat, h, pressure=None, temperature=None, vapour=None):
    """Zenith hydrostatic and wet delays of Saastamoinen's model [m].

    Hydrostatic: 0.0022768 P / (1 - 0.00266 cos 2 lat - 0.00028 h_km) (Davis et al. 1985);
    wet: 0.002277 (1255 / T + 0.05) e (Saastamoinen 1972).  Meteorological values default
    to `standard_atmosphere(h)`.
    """
    std = standard_atmosphere(h)
    pressure = std[0] if pressure is None else pressure
    temperature = std[1] if temperature is None else temperature
    vapour = std[2] if vapour is None else vapour
    hydrostatic = 0.0022768 * pressure / (1.0 - 0.00266 * math.cos(2.0 * lat) - 0.00028e-3 * h)
    wet = 0.002277 * (1255.0 / temperature + 0.05) * vapour
    return hydrostatic, wet


def black_eisner_mapping(elevation):
    """Slant/zenith delay ratio m(E) = 1.001 / sqrt(0.002001 + sin^2 E) (RTCA DO-229)."""
    return 1.001 / math.sqrt(0.002001 + math.sin(elevation) ** 2)


def tropo_delay(lat, h, elevation):
    """Slant tropospheric delay [m] for a receiver at latitude `lat` [rad], ellipsoidal
    height `h` [m] (used as orthometric: the geoid difference moves the result by under
    1 cm per 10 m), satellite elevation `elevation` [rad]."""
    if h > 20000.0 or elevation <= 0.0:
        return 0.0
    hydrostatic, wet = saastamoinen_zenith(lat, h)
    return (hydrostatic + wet) * black_eisner_mapping(elevation)
