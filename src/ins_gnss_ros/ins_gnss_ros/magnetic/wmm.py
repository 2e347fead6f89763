"""Main geomagnetic field from the World Magnetic Model (WMM), via pygeomag.

The magnetic compass needs three things from a field model at the current position and date
(seed 004 §2.3, eq. 2.3.5): the declination d that turns a magnetic azimuth into a true one,
and the expected total intensity and inclination against which a measured field is checked for
disturbances (:mod:`ins_gnss_ros.magnetic.disturbance`).

pygeomag is a port of NOAA's legacy WMM C code; this module only adapts its units and frames to
the project's conventions: SI units (tesla, radians, metres) and ENU vectors. The WMM itself
(NOAA/NCEI and BGS, "The US/UK World Magnetic Model for 2025-2030", technical report) gives
X (north), Y (east), Z (down) in nT, declination D positive east of true north and inclination
I positive downward.
"""
from __future__ import annotations

import datetime
import math
from dataclasses import dataclass
from functools import lru_cache

import numpy as np
from pygeomag import GeoMag, calculate_decimal_year

NT = 1e-9  # tesla per nanotesla


@dataclass(frozen=True)
class FieldElements:
    """Geomagnetic field elements at one point (WMM naming, SI units).

    Attributes
    ----------
    declination : float
        D, rad, positive when magnetic north is east of true north.
    inclination : float
        I, rad, positive when the field points below the horizon (northern hemisphere).
    total : float
        F, total intensity, T.
    horizontal : float
        H, horizontal intensity, T.
    north, east, down : float
        X, Y, Z components, T.
    """

    declination: float
    inclination: float
    total: float
    horizontal: float
    north: float
    east: float
    down: float

    @property
    def enu(self) -> np.ndarray:
        """Field vector in the ENU navigation frame, T, shape (3,)."""
        return np.array([self.east, self.north, -self.down])


@lru_cache(maxsize=8)
def _geomag(coefficients_file: str) -> GeoMag:
    # Loading and normalising the coefficients is the slow part: do it once per model.
    return GeoMag(coefficients_file=coefficients_file)


def decimal_year(when: datetime.datetime | float) -> float:
    """Decimal year of a datetime (UTC) or of a POSIX time in seconds."""
    if not isinstance(when, datetime.datetime):
        when = datetime.datetime.fromtimestamp(float(when), tz=datetime.timezone.utc)
    return float(calculate_decimal_year(when))


def field_elements(lat: float, lon: float, h: float, year: float,
                   coefficients_file: str = "wmm/WMM_2025.COF") -> FieldElements:
    """Geomagnetic field elements from the World Magnetic Model.

    Parameters
    ----------
    lat, lon : float
        Geodetic latitude and longitude, rad.
    h : float
        Height above the WGS-84 ellipsoid, m (the WMM's vertical reference).
    year : float
        Decimal year (see :func:`decimal_year`), inside the model's 5-year life span.
    coefficients_file : str
        Coefficient file shipped with pygeomag, default WMM2025 (valid 2025.0-2030.0).

    Returns
    -------
    FieldElements
    """
    model = _geomag(coefficients_file)
    lo, hi = model.life_span
    if not lo <= year <= hi:
        raise ValueError(f"year {year:.3f} outside the {model.model} life span {lo}-{hi}")
    r = model.calculate(glat=float(np.degrees(lat)), glon=float(np.degrees(lon)),
                        alt=float(h) / 1000.0, time=float(year))
    return FieldElements(declination=np.radians(r.d), inclination=np.radians(r.i),
                         total=r.f * NT, horizontal=r.h * NT,
                         north=r.x * NT, east=r.y * NT, down=r.z * NT)


#: How far (m) and how long (years) the main field is taken as the one evaluated last by
#: :class:`FieldAlongTrack`. The main field's gradient is of the order of a dipole's, 3 F / R
#: (about 0.03 nT/m): at most ~1.5 nT over 50 m, 0.015 deg of declination where the horizontal
#: intensity is 6,000 nT (the edge of the WMM's caution zone) and ~0.001 deg at mid-latitudes,
#: against a magnetometer heading's tenths of a degree; the secular variation (declination
#: up to a few tenths of a degree a year) moves it by less over 0.001 year (8.8 h).
FIELD_STEP_M, FIELD_STEP_YEARS = 50.0, 1e-3
#: Metres per radian of latitude or longitude on the equator, for that distance.
_EARTH_RADIUS_M = 6_378_137.0


class FieldAlongTrack:
    """:func:`field_elements` of a moving vehicle, evaluated again only once it has moved
    ``FIELD_STEP_M`` or ``FIELD_STEP_YEARS`` from where it was last: a compass asks at every
    magnetometer sample (50-100 Hz), and one evaluation of the degree-12 model costs more than
    the rest of the sample's work (docs/results/live_cost.md)."""

    def __init__(self, coefficients_file: str = "wmm/WMM_2025.COF"):
        self.coefficients_file = coefficients_file
        self._at = None        # (lat, lon, h, year) of the last evaluation
        self._elements = None

    def __call__(self, lat: float, lon: float, h: float, year: float) -> FieldElements:
        """The field at (lat, lon rad, h m) in ``year``; ValueError as field_elements."""
        at = self._at
        if at is None or abs(year - at[3]) > FIELD_STEP_YEARS or _EARTH_RADIUS_M * math.hypot(
                lat - at[0], math.cos(lat) * (lon - at[1])) + abs(h - at[2]) > FIELD_STEP_M:
            self._elements = field_elements(lat, lon, h, year, self.coefficients_file)
            self._at = (lat, lon, h, year)
        return self._elements
