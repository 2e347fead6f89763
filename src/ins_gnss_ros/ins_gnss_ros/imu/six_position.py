"""Multi-position static calibration of an IMU (six-face "cube" test and its generalisation).

At rest the accelerometers measure only the reaction to gravity, f_b = C_nb^T [0, 0, g] (ENU,
body FLU), and the gyros only the Earth rate, ω_b = C_nb^T ω_ie^n (Groves §4.4.5 and §14.2.1;
Titterton & Weston §8.3). Averaging each static position and fitting the triad model of
:mod:`ins_gnss_ros.imu.calibration`, x_raw = M^-1 x + b, gives:

* with known face orientations, the 12 accelerometer parameters (full M and b) by linear least
  squares, raw_k = A f_k + b with A = M^-1 (at least four independent positions; six faces give
  18 equations);
* without orientations, only from the known magnitude of gravity, 9 parameters (b and an
  upper-triangular M: the calibrated z axis along the z accelerometer, y in the y-z accelerometer
  plane) by non-linear least squares on |M (raw_k - b)| = g (at least nine positions);
* the gyro bias, as the mean of raw_k - ω_b,k. Earth rate (7.3e-5 rad/s) is subtracted when
  the face orientations are known; it matters only for sensors whose bias is below ~1e-4 rad/s
  (tactical grade and better); the gyro scale factor is not observable from Earth rate alone.
"""
from __future__ import annotations

import numpy as np
from scipy.optimize import least_squares

from ins_gnss_ros.imu.calibration import TriadCalibration
from ins_gnss_ros.nav.earth import earth_rate_enu
from ins_gnss_ros.nav.rotations import dcm_from_euler

#: Roll and pitch (rad) that point each body axis up; e.g. "-x" is nose down.
FACES = {"+z": (0.0, 0.0), "-z": (np.pi, 0.0), "+x": (0.0, -np.pi / 2), "-x": (0.0, np.pi / 2),
         "+y": (np.pi / 2, 0.0), "-y": (-np.pi / 2, 0.0)}


def face_attitude(face: str, yaw: float = 0.0) -> np.ndarray:
    """C_nb (body FLU to ENU) of a cube face: the named body axis up, turned by ``yaw`` (rad)."""
    if face not in FACES:
        raise ValueError(f"face {face!r}: expected one of {sorted(FACES)}")
    roll, pitch = FACES[face]
    return dcm_from_euler(roll, pitch, yaw)


def static_specific_force(c_nb, gravity: float) -> np.ndarray:
    """Specific force at rest in body axes, C_nb^T [0, 0, g], m/s²; c_nb shape (3, 3) or (K, 3, 3)."""
    return np.einsum("...ji,j->...i", c_nb, np.array([0.0, 0.0, gravity]))


def static_earth_rate(c_nb, lat: float) -> np.ndarray:
    """Earth rotation rate at rest in body axes, C_nb^T ω_ie^n, rad/s."""
    return np.einsum("...ji,j->...i", c_nb, earth_rate_enu(lat))


def _triad(m: np.ndarray, b: np.ndarray) -> TriadCalibration:
    """Split M into I + diag(s) + N for :class:`TriadCalibration`."""
    s = np.diag(m) - 1.0
    return TriadCalibration(bias=b, scale=s, nonorthogonality=m - np.diag(np.diag(m)),
                            label="accel")


def fit_accel_known_faces(raw_means, f_true) -> TriadCalibration:
    """Accelerometer bias, scale and non-orthogonality from positions of known orientation.

    Parameters
    ----------
    raw_means : array_like, shape (K, 3)
        Mean raw accelerometer reading of each static position, m/s².
    f_true : array_like, shape (K, 3)
        True specific force of each position in the (ideal) sensor frame, m/s², e.g. from
        :func:`static_specific_force`. K >= 4 non-coplanar positions.

    Returns
    -------
    TriadCalibration
        M = A^-1 and b of raw = A f + b (the misalignment of the fixture to the sensor axes is
        absorbed into the non-orthogonality).
    """
    raw, f = np.asarray(raw_means, float), np.asarray(f_true, float)
    design = np.column_stack([f, np.ones(len(f))])
    if np.linalg.matrix_rank(design) < 4:
        raise ValueError("positions do not determine the accelerometer model (need 4 "
                         "non-coplanar specific-force directions)")
    coef = np.linalg.lstsq(design, raw, rcond=None)[0]  # rows: A^T (3), b (1)
    return _triad(np.linalg.inv(coef[:3].T), coef[3])


def fit_accel_gravity_norm(raw_means, gravity: float) -> TriadCalibration:
    """Accelerometer bias, scale and non-orthogonality from the gravity magnitude alone.

    Parameters
    ----------
    raw_means : array_like, shape (K, 3)
        Mean raw readings of K >= 9 static positions in well-spread, unknown orientations.
    gravity : float
        Local gravity magnitude, m/s² (e.g. :func:`ins_gnss_ros.nav.earth.normal_gravity`).

    Returns
    -------
    TriadCalibration
        Upper-triangular M (see the module docstring) and b.
    """
    raw = np.asarray(raw_means, float)
    if len(raw) < 9:
        raise ValueError(f"{len(raw)} positions: the gravity-norm fit needs at least 9")
    iu = np.triu_indices(3)

    def unpack(p):
        m = np.zeros((3, 3))
        m[iu] = p[:6]
        return m, p[6:]

    def residual(p):
        m, b = unpack(p)
        return np.linalg.norm((raw - b) @ m.T, axis=1) / gravity - 1.0

    p0 = np.concatenate([np.eye(3)[iu], np.zeros(3)])
    sol = least_squares(residual, p0, method="lm", xtol=1e-14, ftol=1e-14)
    return _triad(*unpack(sol.x))


def fit_gyro_bias(raw_means, c_nb=None, lat: float | None = None) -> np.ndarray:
    """Gyro bias from static positions, rad/s.

    Parameters
    ----------
    raw_means : array_like, shape (K, 3)
        Mean raw gyro reading of each position, rad/s.
    c_nb : array_like, shape (K, 3, 3), optional
        Attitude of each position; with ``lat`` the Earth rate is removed first.
    lat : float, optional
        Geodetic latitude, rad.
    """
    raw = np.asarray(raw_means, float)
    if c_nb is not None and lat is not None:
        raw = raw - static_earth_rate(np.asarray(c_nb, float), lat)
    return raw.mean(axis=0)
