"""The ``map`` frame (REP-105): an ENU tangent plane on the WGS-84 ellipsoid around a datum.

A datum is ``(lat rad, lon rad, h m)``; positions in the frame are east, north, up in metres.
``nav/odom``, ``/tf`` and the ``ekf`` node's ``~/to_ll`` / ``~/from_ll`` services all convert
here, so the map position of a geodetic point is one computation everywhere.
"""
from __future__ import annotations

import math

import numpy as np

from .earth import ecef_to_enu_matrix, ecef_to_geodetic, enu_to_ecef, geodetic_to_ecef

#: Heights a datum may have, m (the ellipsoidal heights of the Earth's surface and of aircraft).
HEIGHT_RANGE = (-1000.0, 1e5)


def datum_from_degrees(lat_deg: float, lon_deg: float, h: float) -> tuple[float, float, float]:
    """A datum from geodetic degrees and ellipsoidal height (m); ValueError if it is none."""
    if not (math.isfinite(lat_deg) and math.isfinite(lon_deg) and math.isfinite(h)):
        raise ValueError("datum is not finite")
    if not -90.0 <= lat_deg <= 90.0:
        raise ValueError(f"datum latitude {lat_deg} deg outside [-90, 90]")
    if not -180.0 <= lon_deg <= 360.0:
        raise ValueError(f"datum longitude {lon_deg} deg outside [-180, 360]")
    if not HEIGHT_RANGE[0] <= h <= HEIGHT_RANGE[1]:
        raise ValueError(f"datum height {h} m outside {list(HEIGHT_RANGE)}")
    return math.radians(lat_deg), math.radians(lon_deg), float(h)


def to_map(datum, lat, lon, h) -> np.ndarray:
    """ENU position (m, shape (..., 3)) in the frame around ``datum`` of the point(s) at lat,
    lon (rad), h (m).

    Each point's rotation is its own vector-matrix product, so a point has the same map
    position alone and among many (the offline path converts a whole run at once, the nodes
    one epoch at a time): one matrix product of all points rounds differently in BLAS.
    """
    d = geodetic_to_ecef(lat, lon, h) - geodetic_to_ecef(*datum)
    return np.matmul(d[..., None, :], ecef_to_enu_matrix(datum[0], datum[1]).T)[..., 0, :]


def from_map(datum, enu) -> tuple[float, float, float]:
    """(lat rad, lon rad, h m) of the point at ``enu`` (m) in the frame around ``datum``."""
    lat, lon, h = ecef_to_geodetic(enu_to_ecef(enu, *datum))
    return float(lat), float(lon), float(h)
