"""Earth model against published constants (NIMA TR8350.2, PZ-90.11) and pymap3d."""
import numpy as np
import pymap3d
import pytest

from ins_gnss_ros.nav import earth
from ins_gnss_ros.nav.earth import KRASOVSKY, PZ90_11, WGS84

RNG = np.random.default_rng(20260708)


def _random_points(n):
    lat = RNG.uniform(-np.pi / 2, np.pi / 2, n)
    lat[:4] = [np.pi / 2, -np.pi / 2, 0.0, np.deg2rad(89.9999)]  # poles, equator, near pole
    lon = RNG.uniform(-np.pi, np.pi, n)
    h = np.where(np.arange(n) % 2 == 0, RNG.uniform(-500.0, 20_000.0, n),
                 RNG.uniform(0.0, 40_000_000.0, n))
    h[4:8] = [0.0, -100.0, 1000.0, 36_000_000.0]
    return lat, lon, h


def test_wgs84_published_constants():
    # TR8350.2 tables 3.1, 3.3: derived constants of the level ellipsoid.
    assert WGS84.b == pytest.approx(6356752.3142, abs=1e-4)
    assert WGS84.e2 == pytest.approx(6.69437999014e-3, abs=1e-14)
    assert WGS84.m == pytest.approx(0.00344978650684, abs=1e-13)
    assert abs(WGS84.gamma_e - 9.7803253359) < 1e-9
    assert abs(WGS84.gamma_p - 9.8321849378) < 1e-9
    assert WGS84.somigliana_k == pytest.approx(0.00193185265241, abs=1e-13)


def test_normal_gravity_published_values():
    assert abs(earth.normal_gravity(0.0, 0.0) - 9.7803253359) < 1e-9
    assert abs(earth.normal_gravity(np.pi / 2, 0.0) - 9.8321849378) < 1e-9
    assert abs(earth.normal_gravity(-np.pi / 2, 0.0) - 9.8321849378) < 1e-9
    # TR8350.2 eq. 4-3 linear term at the equator: -0.3087691 mGal/m = -3.087691e-6 s^-2.
    slope = (earth.normal_gravity(0.0, 1.0) - earth.normal_gravity(0.0, -1.0)) / 2
    assert slope == pytest.approx(-3.087691e-6, abs=1e-12)


def test_other_ellipsoids():
    # PZ-90.11 normal gravity at the equator 978032.84 mGal (PZ-90.11 reference document).
    assert PZ90_11.gamma_e == pytest.approx(9.7803284, abs=1e-6)
    assert KRASOVSKY.e2 == pytest.approx(0.0066934, abs=1e-7)  # as printed in seed 003
    assert KRASOVSKY.b == pytest.approx(6356863.0188, abs=1e-3)  # published semi-minor axis


def test_radii_against_geometry():
    # Meridian radius equals the radius of curvature of the meridian ellipse computed from the
    # ECEF meridian section by finite differences: rm = (ds/dlat), ds the arc length.
    lat = np.deg2rad(np.array([0.0, 30.0, 60.0, 89.0]))
    d = 1e-6
    for la in lat:
        p1 = earth.geodetic_to_ecef(la - d, 0.0, 0.0)
        p2 = earth.geodetic_to_ecef(la + d, 0.0, 0.0)
        rm, rn = earth.radii(la)
        assert np.linalg.norm(p2 - p1) / (2 * d) == pytest.approx(rm, rel=1e-9)
        # Parallel circle radius = rn cos(lat).
        assert np.hypot(*earth.geodetic_to_ecef(la, 0.0, 0.0)[:2]) == pytest.approx(
            rn * np.cos(la), rel=1e-12)
    rm, rn = earth.radii(0.0)
    assert rn == pytest.approx(WGS84.a, rel=1e-15)
    assert rm == pytest.approx(WGS84.b ** 2 / WGS84.a, rel=1e-15)


def test_gravity_vector_and_gradient():
    lat, h = np.deg2rad(47.0), 300.0
    g = earth.gravity_enu(lat, h)
    assert g[:2].tolist() == [0.0, 0.0] and g[2] < -9.8
    G = earth.gravity_gradient_enu(lat, h)
    # Point-mass truth GM/r^3 diag(-1, -1, 2) (the J2 part changes it by ~0.3 %).
    r = np.linalg.norm(earth.geodetic_to_ecef(lat, 0.0, h))
    truth = WGS84.gm / r ** 3 * np.array([-1.0, -1.0, 2.0])
    np.testing.assert_allclose(np.diag(G), truth, rtol=5e-3)
    # The vertical term is the derivative of the height series.
    dgdh = (earth.normal_gravity(lat, h + 10) - earth.normal_gravity(lat, h - 10)) / 20
    assert G[2, 2] == pytest.approx(-dgdh, rel=1e-9)
    # Horizontal terms: the gravity vector along the ellipsoid normal 1 km east, resolved in the
    # starting ENU frame, tilts back towards the start.
    lon0 = 0.3
    p1 = earth.enu_to_ecef([1000.0, 0.0, 0.0], lat, lon0, h)
    la1, lo1, h1 = earth.ecef_to_geodetic(p1)
    g1_ecef = earth.ecef_to_enu_matrix(la1, lo1).T @ earth.gravity_enu(la1, h1)
    g1 = earth.ecef_to_enu_matrix(lat, lon0) @ g1_ecef
    assert g1[0] / 1000.0 == pytest.approx(G[0, 0], rel=5e-3)


def test_earth_and_transport_rate():
    lat = np.deg2rad(55.75)
    w = earth.earth_rate_enu(lat)
    assert np.linalg.norm(w) == pytest.approx(7.292115e-5, rel=1e-15)
    # Earth rate in ECEF is [0, 0, omega]: rotate it into ENU independently via pymap3d.
    e, n, u = pymap3d.ecef2enuv(0.0, 0.0, WGS84.omega, lat, 1.0, deg=False)
    np.testing.assert_allclose(w, [e, n, u], atol=1e-20)
    # Transport rate: moving north at v rotates ENU about -East at v / (rm + h); moving east
    # rotates ENU about the Earth axis at ve / ((rn + h) cos lat) (longitude rate).
    h = 1234.0
    rm, rn = earth.radii(lat)
    np.testing.assert_allclose(earth.transport_rate_enu(lat, h, [0.0, 50.0, 0.0]),
                               [-50.0 / (rm + h), 0.0, 0.0], rtol=1e-15)
    lon_rate = 30.0 / ((rn + h) * np.cos(lat))
    np.testing.assert_allclose(earth.transport_rate_enu(lat, h, [30.0, 0.0, 1.0]),
                               lon_rate * np.array([0.0, np.cos(lat), np.sin(lat)]), rtol=1e-12)


def test_geodetic_ecef_against_pymap3d():
    lat, lon, h = _random_points(500)
    xyz = earth.geodetic_to_ecef(lat, lon, h)
    x, y, z = pymap3d.geodetic2ecef(lat, lon, h, deg=False)
    np.testing.assert_allclose(xyz, np.c_[x, y, z], atol=1e-6, rtol=0)
    la, lo, hh = earth.ecef_to_geodetic(xyz)
    r = np.linalg.norm(xyz, axis=-1)
    # pymap3d's inverse (You 2000, non-iterative) is itself approximate above ~50 km (1e-6 m at
    # 100 km, metres at GEO), so compare to it below 20 km ...
    low = h < 20_000.0
    lat_p, lon_p, h_p = pymap3d.ecef2geodetic(x[low], y[low], z[low], deg=False)
    assert np.max(np.abs(la[low] - lat_p) * r[low]) < 1e-6
    assert np.max(np.abs(hh[low] - h_p)) < 1e-6
    off_axis = np.abs(np.cos(lat)) > 1e-9  # longitude is undefined on the axis
    assert np.max(np.abs(np.angle(np.exp(1j * (lo - lon))) * r)[off_axis]) < 1e-6
    # ... and everywhere (poles, up to GEO) to the points pymap3d's forward transform produced.
    assert np.max(np.abs(la - lat) * r) < 1e-6
    assert np.max(np.abs(hh - h)) < 1e-6
    assert np.max(np.abs(la - lat)) < 1e-12


def test_enu_against_pymap3d():
    lat, lon, h = _random_points(200)
    lat0, lon0, h0 = np.deg2rad(59.9), np.deg2rad(30.3), 15.0
    xyz = earth.geodetic_to_ecef(lat, lon, h)
    enu = earth.ecef_to_enu(xyz, lat0, lon0, h0)
    e, n, u = pymap3d.ecef2enu(xyz[:, 0], xyz[:, 1], xyz[:, 2], lat0, lon0, h0, deg=False)
    np.testing.assert_allclose(enu, np.c_[e, n, u], atol=1e-6, rtol=0)
    x, y, z = pymap3d.enu2ecef(e, n, u, lat0, lon0, h0, deg=False)
    np.testing.assert_allclose(earth.enu_to_ecef(enu, lat0, lon0, h0), np.c_[x, y, z],
                               atol=1e-6, rtol=0)
    C = earth.ecef_to_enu_matrix(lat0, lon0)
    np.testing.assert_allclose(C @ C.T, np.eye(3), atol=1e-15)
    assert np.linalg.det(C) == pytest.approx(1.0)
