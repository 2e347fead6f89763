"""Earth model: reference ellipsoids, normal gravity, Earth and transport rates, ECEF/ENU.

Frames
------
* ECEF: Earth-centred Earth-fixed, z along the rotation axis, x through the Greenwich meridian.
* ENU: local East-North-Up frame at a geodetic point (the project's navigation frame, REP-103).

Positions are geodetic: latitude and longitude in radians, ellipsoidal height in metres.

References
----------
* NIMA TR8350.2, "Department of Defense World Geodetic System 1984", 3rd ed. (WGS-84 constants,
  Somigliana normal gravity eq. 4-1, height series eq. 4-3).
* H. Moritz, "Geodetic Reference System 1980", Bulletin Geodesique 54 (closed-form normal gravity
  at the equator and pole from the four defining constants).
* "Parametry Zemli 1990" (PZ-90.11) reference document, 2014 (PZ-90.11 constants).
* Groves, "Principles of GNSS, Inertial and Multisensor Integrated Navigation", 2nd ed., ch. 2
  (radii of curvature, Earth and transport rates, ECEF/ENU transforms).
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from functools import cached_property

import numpy as np


@dataclass(frozen=True)
class Ellipsoid:
    """Reference ellipsoid with its normal gravity field (level ellipsoid).

    Attributes
    ----------
    a : float
        Semi-major axis, m.
    f : float
        Flattening, dimensionless.
    gm : float
        Geocentric gravitational constant (incl. atmosphere), m^3/s^2.
    omega : float
        Earth rotation rate, rad/s.
    gamma_e, gamma_p : float
        Normal gravity on the ellipsoid at the equator and at the poles, m/s^2.
    """

    a: float
    f: float
    gm: float
    omega: float
    gamma_e: float
    gamma_p: float

    @cached_property  # read at every filter update: computed once (the ellipsoid is immutable)
    def e2(self) -> float:
        """First eccentricity squared, dimensionless."""
        return self.f * (2.0 - self.f)

    @property
    def b(self) -> float:
        """Semi-minor axis, m."""
        return self.a * (1.0 - self.f)

    @property
    def m(self) -> float:
        """Geodetic parameter m = omega^2 a^2 b / GM, dimensionless (TR8350.2 table 3.3)."""
        return self.omega ** 2 * self.a ** 2 * self.b / self.gm

    @property
    def somigliana_k(self) -> float:
        """Somigliana's constant k = b gamma_p / (a gamma_e) - 1 (TR8350.2 eq. 4-1)."""
        return self.b * self.gamma_p / (self.a * self.gamma_e) - 1.0

    @cached_property
    def kernel_params(self) -> tuple:
        """(a, f, e2, m, omega, gamma_e, somigliana_k): the ellipsoid as the numba kernels
        (nav/_kernels.py) take it."""
        return (self.a, self.f, self.e2, self.m, self.omega, self.gamma_e, self.somigliana_k)

    @classmethod
    def from_defining(cls, a: float, f: float, gm: float, omega: float) -> "Ellipsoid":
        """Build a level ellipsoid from its four defining constants.

        Equatorial and polar normal gravity follow from the closed-form formulas of the level
        ellipsoid (Moritz, "Geodetic Reference System 1980"; Heiskanen & Moritz, "Physical
        Geodesy", ch. 2).
        For WGS-84 this reproduces the published 9.7803253359 and 9.8321849378 m/s^2.
        """
        b = a * (1.0 - f)
        e_prime = np.sqrt(a * a - b * b) / b  # second eccentricity
        q0 = 0.5 * ((1.0 + 3.0 / e_prime ** 2) * np.arctan(e_prime) - 3.0 / e_prime)
        q0p = 3.0 * (1.0 + 1.0 / e_prime ** 2) * (1.0 - np.arctan(e_prime) / e_prime) - 1.0
        m = omega ** 2 * a ** 2 * b / gm
        gamma_e = gm / (a * b) * (1.0 - m - m * e_prime * q0p / (6.0 * q0))
        gamma_p = gm / (a * a) * (1.0 + m * e_prime * q0p / (3.0 * q0))
        return cls(a, f, gm, omega, float(gamma_e), float(gamma_p))


#: WGS-84 (NIMA TR8350.2, table 3.1).
WGS84 = Ellipsoid.from_defining(6378137.0, 1.0 / 298.257223563, 3.986004418e14, 7.292115e-5)
#: PZ-90.11 (GLONASS ICD 2016 / PZ-90.11 reference document).
PZ90_11 = Ellipsoid.from_defining(6378136.0, 1.0 / 298.25784, 3.986004418e14, 7.292115e-5)
#: Krasovsky 1940 (SK-42), used by seed 003: a = 6378245 m, f = 1/298.3. Only a and f are defined
#: by the datum; GM and omega are taken equal to WGS-84's to complete the level ellipsoid.
KRASOVSKY = Ellipsoid.from_defining(6378245.0, 1.0 / 298.3, 3.986004418e14, 7.292115e-5)


def _radii(lat, a, e2):
    """Radii of curvature from raw ellipsoid parameters (shared with the numba kernels)."""
    s = np.sin(lat)
    w = 1.0 - e2 * s * s
    rn = a / np.sqrt(w)
    rm = a * (1.0 - e2) / (w * np.sqrt(w))
    return rm, rn


def radii(lat, ell: Ellipsoid = WGS84):
    """Meridian and prime-vertical radii of curvature (Groves ch. 2).

    Parameters
    ----------
    lat : float or array_like
        Geodetic latitude, rad.
    ell : Ellipsoid

    Returns
    -------
    rm, rn : float or ndarray
        Meridian (north-south) and prime-vertical (east-west) radii, m.
    """
    return _radii(lat, ell.a, ell.e2)


def _normal_gravity(lat, h, a, f, e2, m, gamma_e, k):
    """Normal gravity from raw ellipsoid parameters (shared with the numba kernels);
    k = b gamma_p / (a gamma_e) - 1 is Somigliana's constant."""
    s2 = np.sin(lat) ** 2
    gamma0 = gamma_e * (1.0 + k * s2) / np.sqrt(1.0 - e2 * s2)
    return gamma0 * (1.0 - 2.0 / a * (1.0 + f + m - 2.0 * f * s2) * h + 3.0 * h * h / (a * a))


def _normal_gravity_dh(lat, h, gamma0, a, f, m):
    """d|g|/dh of :func:`_normal_gravity`, the exact derivative of the TR8350.2 eq. 4-3 height
    series; gamma0 is the normal gravity on the ellipsoid (h = 0) at lat (raw ellipsoid
    parameters, shared with the numba kernels)."""
    s2 = np.sin(lat) ** 2
    return gamma0 * (-2.0 / a * (1.0 + f + m - 2.0 * f * s2) + 6.0 * h / a ** 2)


def normal_gravity(lat, h, ell: Ellipsoid = WGS84):
    """Magnitude of normal gravity at geodetic latitude and ellipsoidal height.

    Somigliana's closed form on the ellipsoid (TR8350.2 eq. 4-1) with the second-order height
    series above it (TR8350.2 eq. 4-3), valid for heights of a few tens of km.

    Parameters
    ----------
    lat : float or array_like
        Geodetic latitude, rad.
    h : float or array_like
        Ellipsoidal height, m.

    Returns
    -------
    float or ndarray
        Normal gravity, m/s^2 (positive).
    """
    return _normal_gravity(lat, h, ell.a, ell.f, ell.e2, ell.m, ell.gamma_e, ell.somigliana_k)


def gravity_enu(lat, h, ell: Ellipsoid = WGS84) -> np.ndarray:
    """Normal gravity vector in ENU, [0, 0, -g], m/s^2.

    The deflection of the vertical (a few arc-seconds, i.e. ~1e-4 m/s^2 horizontally) and the
    tiny north component of normal gravity above the ellipsoid are neglected: gravity acts along
    the ellipsoid normal ("plumb-bob" gravity, Groves 2.4.7).
    """
    return np.array([0.0, 0.0, -normal_gravity(lat, h, ell)])


def gravity_gradient_enu(lat, h, ell: Ellipsoid = WGS84) -> np.ndarray:
    """Gradient of the gravity vector in ENU with respect to ENU position, 1/s^2.

    G[i, j] = d g_enu[i] / d r_enu[j]. Gravity points down, so moving horizontally by dx tilts
    it towards the starting point: d g_E / d x_E = -g / R. Moving up weakens it, so
    d g_U / d h = -d|g|/dh = +2 g / R approximately (the vertical-channel instability that
    makes the free-inertial height diverge). The vertical term is the exact derivative of the
    TR8350.2 eq. 4-3 height series; R for the horizontal terms is the Gaussian mean radius
    sqrt(rm rn) + h (spherical approximation, adequate for an error model).

    Returns
    -------
    ndarray, shape (3, 3)
        diag(-g/R, -g/R, -d|g|/dh).
    """
    rm, rn = radii(lat, ell)
    g = normal_gravity(lat, h, ell)
    r = np.sqrt(rm * rn) + h
    dg_dh = _normal_gravity_dh(lat, h, normal_gravity(lat, 0.0, ell), ell.a, ell.f, ell.m)
    return np.diag([-g / r, -g / r, -dg_dh])


def earth_rate_enu(lat, ell: Ellipsoid = WGS84) -> np.ndarray:
    """Earth rotation rate omega_ie resolved in ENU, rad/s, shape (..., 3) (Groves ch. 2
    and 5, ENU order)."""
    lat = np.asarray(lat, float)
    # Filled in place: called for single latitudes at every filter epoch (rotations.skew).
    out = np.zeros(lat.shape + (3,))
    out[..., 1] = ell.omega * np.cos(lat)
    out[..., 2] = ell.omega * np.sin(lat)
    return out


def transport_rate_enu(lat, h, v_enu, ell: Ellipsoid = WGS84) -> np.ndarray:
    """Transport rate omega_en (rotation of ENU w.r.t. ECEF) resolved in ENU, rad/s.

    [-vn/(rm+h), ve/(rn+h), ve tan(lat)/(rn+h)] (Groves ch. 5, ENU ordering).

    Parameters
    ----------
    lat, h : float or ndarray, shape (...)
        Geodetic latitude (rad) and ellipsoidal height (m).
    v_enu : array_like, shape (..., 3)
        Velocity relative to the Earth in ENU, m/s.

    Returns
    -------
    ndarray, shape (..., 3)
    """
    rm, rn = radii(lat, ell)
    v_enu = np.asarray(v_enu, float)
    ve, vn = v_enu[..., 0], v_enu[..., 1]
    return np.stack([-vn / (rm + h), ve / (rn + h), ve * np.tan(lat) / (rn + h)], -1)


def _scalars(*values) -> bool:
    """All of `values` are scalars (floats checked first: np.ndim costs a microsecond)."""
    for v in values:
        if not isinstance(v, float):
            return all(np.ndim(v) == 0 for v in values)
    return True


def geodetic_to_ecef(lat, lon, h, ell: Ellipsoid = WGS84) -> np.ndarray:
    """Geodetic to ECEF coordinates (Groves ch. 2), vectorised.

    Returns
    -------
    ndarray, shape (..., 3)
        ECEF position, m.
    """
    if _scalars(lat, lon, h):
        # One point (every GNSS fix of the front end): the same arithmetic compiled, without
        # the numpy calls on scalars, broadcasting and stacking that cost ten times more.
        return np.array(_kernels.geodetic_to_ecef(float(lat), float(lon), float(h), ell.a,
                                                  ell.e2))
    lat, lon, h = np.broadcast_arrays(np.asarray(lat, float), np.asarray(lon, float),
                                      np.asarray(h, float))
    return np.stack(_geodetic_to_ecef(lat, lon, h, ell.a, ell.e2), axis=-1)


def _geodetic_to_ecef(lat, lon, h, a, e2):
    """(x, y, z) of geodetic_to_ecef from raw ellipsoid parameters, scalars or arrays of one
    shape."""
    return _ecef(lat, lon, h, _radii(lat, a, e2)[1], e2)


def _ecef(lat, lon, h, rn, e2):
    """ECEF (x, y, z) of a geodetic point with prime-vertical radius rn (shared with the numba
    kernels)."""
    cl = np.cos(lat)
    x = (rn + h) * cl * np.cos(lon)
    y = (rn + h) * cl * np.sin(lon)
    z = (rn * (1.0 - e2) + h) * np.sin(lat)
    return x, y, z


def ecef_to_geodetic(xyz, ell: Ellipsoid = WGS84):
    """ECEF to geodetic coordinates by Bowring's iteration on the parametric latitude.

    Each iteration is third-order convergent; the loop stops when the latitude changes by less
    than 1e-14 rad (normally 2-3 iterations for points from the centre of the Earth to GEO).
    The height uses the expression p cos(lat) + z sin(lat) - a sqrt(1 - e2 sin^2 lat), which is
    well conditioned at the poles as well as the equator.

    Parameters
    ----------
    xyz : array_like, shape (..., 3)
        ECEF position, m.

    Returns
    -------
    lat, lon, h : float or ndarray
        Geodetic latitude (rad), longitude (rad), ellipsoidal height (m).
    """
    xyz = np.asarray(xyz, float)
    x, y, z = xyz[..., 0], xyz[..., 1], xyz[..., 2]
    a, b, e2 = ell.a, ell.b, ell.e2
    ep2 = e2 / (1.0 - e2)
    p = np.hypot(x, y)
    lon = np.arctan2(y, x)
    beta = np.arctan2(z * a, p * b)  # parametric latitude, first guess
    lat = np.arctan2(z + ep2 * b * np.sin(beta) ** 3, p - e2 * a * np.cos(beta) ** 3)
    for _ in range(10):
        beta = np.arctan2(b * np.sin(lat), a * np.cos(lat))
        lat_new = np.arctan2(z + ep2 * b * np.sin(beta) ** 3, p - e2 * a * np.cos(beta) ** 3)
        done = np.all(np.abs(lat_new - lat) < 1e-14)
        lat = lat_new
        if done:
            break
    s = np.sin(lat)
    h = p * np.cos(lat) + z * s - a * np.sqrt(1.0 - e2 * s * s)
    return lat, lon, h


def ecef_to_enu_matrix(lat, lon) -> np.ndarray:
    """Rotation matrix C such that v_enu = C @ v_ecef (Groves ch. 2, ENU row order).

    Returns
    -------
    ndarray, shape (..., 3, 3)
        One matrix per (lat, lon) pair, rad.
    """
    if _scalars(lat, lon):
        # One matrix (per GNSS fix): the same values without broadcasting and stacking, the
        # functions of the math module (numpy's on a scalar cost ten times more).
        sl, cl = math.sin(lat), math.cos(lat)
        so, co = math.sin(lon), math.cos(lon)
        return np.array((-so, co, 0.0, -sl * co, -sl * so, cl, cl * co, cl * so, sl)).reshape(3, 3)
    lat, lon = np.broadcast_arrays(np.asarray(lat, float), np.asarray(lon, float))
    sl, cl = np.sin(lat), np.cos(lat)
    so, co = np.sin(lon), np.cos(lon)
    z = np.zeros_like(sl)
    return np.stack([np.stack([-so, co, z], -1),
                     np.stack([-sl * co, -sl * so, cl], -1),
                     np.stack([cl * co, cl * so, sl], -1)], -2)


def ecef_to_enu(xyz, lat0, lon0, h0, ell: Ellipsoid = WGS84) -> np.ndarray:
    """ECEF position(s) to ENU coordinates relative to a geodetic origin.

    Parameters
    ----------
    xyz : array_like, shape (..., 3)
        ECEF position, m.
    lat0, lon0, h0 : float
        Origin of the tangent plane (rad, rad, m).

    Returns
    -------
    ndarray, shape (..., 3)
        East, north, up, m.
    """
    d = np.asarray(xyz, float) - geodetic_to_ecef(lat0, lon0, h0, ell)
    return d @ ecef_to_enu_matrix(lat0, lon0).T


def enu_to_ecef(enu, lat0, lon0, h0, ell: Ellipsoid = WGS84) -> np.ndarray:
    """ENU coordinates relative to a geodetic origin to ECEF position(s), m; inverse of
    :func:`ecef_to_enu`."""
    return np.asarray(enu, float) @ ecef_to_enu_matrix(lat0, lon0) + geodetic_to_ecef(
        lat0, lon0, h0, ell)


# The kernels compile this module's formulas (geodetic_to_ecef's one point): imported after them.
from . import _kernels  # noqa: E402
