"""Hard- and soft-iron magnetometer calibration by ellipsoid fitting.

A magnetometer fixed to a vehicle reads m = A b + c + noise, where b is the external field in the
sensor frame, c the hard-iron offset (permanent magnetisation, sensor zero offsets) and A the
soft-iron / scale / non-orthogonality matrix (Gebre-Egziabher et al., "Calibration of
strapdown magnetometers in magnetic field domain", J. Aerosp. Eng. 2006; Groves §6.1.1). While
the vehicle turns, |b| stays the local field magnitude B, so the readings lie on the ellipsoid
(m - c)^T Q (m - c) = 1 with Q = (A A^T)^-1 / B². Fitting that quadric by algebraic least
squares gives c and Q; the correction

    b = W (m - c),     W = B Q^(1/2)   (symmetric square root)

maps the ellipsoid back to the sphere of radius B. The algebraic fit is biased by noise (the bias
grows as σ² and is amplified when the readings cover only a cap of the ellipsoid, as on a
turntable with a steep field), so :func:`calibrate` refines c and W by non-linear least squares
on the field-magnitude residual |W (m - c)| - B (Vasconcelos et al., "Geometric approach to
strapdown magnetometer calibration in sensor frame", IEEE TAES 2011), which is close to the
maximum-likelihood estimate for isotropic noise. W recovers A^-1 only up to a rotation, so the
symmetric choice assumes a symmetric soft-iron matrix; a rotation of the triad (misalignment to
base_link) stays and must come from a heading reference (the ΔK_mk term of
:mod:`ins_gnss_ros.magnetic.turntable_kf`). The seed (004 §2.9) models only zero offsets and
anomalies; the soft-iron fit is the standard completion its extraction recommends.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.optimize import least_squares


@dataclass
class HardSoftIron:
    """Magnetometer correction b = W (m - c), sensor frame, tesla.

    Attributes
    ----------
    offset : ndarray, shape (3,)
        Hard-iron offset c, T.
    matrix : ndarray, shape (3, 3)
        Soft-iron correction W (dimensionless).
    """

    offset: np.ndarray
    matrix: np.ndarray

    def __post_init__(self):
        for name, shape in (("offset", (3,)), ("matrix", (3, 3))):
            try:
                a = np.array(getattr(self, name), dtype=float)
            except (TypeError, ValueError):
                raise ValueError(f"{name}: not numeric") from None
            if a.shape != shape or not np.all(np.isfinite(a)):
                raise ValueError(f"{name}: expected finite {shape}, got {a.shape}")
            setattr(self, name, a)
        if np.linalg.det(self.matrix) <= 0:
            raise ValueError("matrix: must have a positive determinant")

    def apply(self, raw) -> np.ndarray:
        """Calibrated field W (m - c), T; raw shape (3,) or (N, 3)."""
        return (np.asarray(raw, float) - self.offset) @ self.matrix.T

    def distort(self, field) -> np.ndarray:
        """Forward model m = W^-1 b + c, the inverse of :meth:`apply`."""
        return np.linalg.solve(self.matrix, np.asarray(field, float).T).T + self.offset

    def to_dict(self) -> dict:
        return {"hard_iron": self.offset.tolist(), "soft_iron": self.matrix.tolist()}

    @classmethod
    def from_dict(cls, d: dict) -> "HardSoftIron":
        return cls(offset=d.get("hard_iron", np.zeros(3)), matrix=d.get("soft_iron", np.eye(3)))


def fit_ellipsoid(points):
    """Algebraic least-squares ellipsoid through 3-D points.

    Fits the general quadric x^T Q x + 2 u^T x + k = 0 (10 coefficients, unit norm: the smallest
    right singular vector of the design matrix) to points centred and scaled to unit spread for
    conditioning, then rewrites it as (x - c)^T P (x - c) = 1.

    Parameters
    ----------
    points : array_like, shape (N, 3), N >= 9, spread over the ellipsoid (not one plane).

    Returns
    -------
    center : ndarray, shape (3,)
    shape : ndarray, shape (3, 3)
        P, symmetric positive definite, units 1/unit².

    Raises
    ------
    ValueError
        Too few points, or points that do not determine an ellipsoid (e.g. one plane).
    """
    x = np.asarray(points, float)
    if x.ndim != 2 or x.shape[1] != 3 or len(x) < 9:
        raise ValueError("need at least 9 points of shape (N, 3)")
    mean, scale = x.mean(axis=0), x.std()
    y = (x - mean) / scale
    d = np.column_stack([y[:, 0] ** 2, y[:, 1] ** 2, y[:, 2] ** 2,
                         2 * y[:, 0] * y[:, 1], 2 * y[:, 0] * y[:, 2], 2 * y[:, 1] * y[:, 2],
                         2 * y[:, 0], 2 * y[:, 1], 2 * y[:, 2], np.ones(len(y))])
    _, s, vt = np.linalg.svd(d, full_matrices=False)
    if s[-2] < 1e-6 * s[0]:
        raise ValueError("points do not determine an ellipsoid (degenerate coverage)")
    v = vt[-1]
    q = np.array([[v[0], v[3], v[4]], [v[3], v[1], v[5]], [v[4], v[5], v[2]]])
    u, k = v[6:9], v[9]
    center_y = -np.linalg.solve(q, u)
    p = q / (center_y @ q @ center_y - k)
    if np.any(np.linalg.eigvalsh(p) <= 0):
        raise ValueError("fitted quadric is not an ellipsoid")
    return mean + scale * center_y, p / scale ** 2


def calibrate(points, field_magnitude: float, roll=None, pitch=None) -> HardSoftIron:
    """Hard/soft-iron correction from a rotation recording.

    Parameters
    ----------
    points : array_like, shape (N, 3)
        Raw magnetometer readings over well-spread attitudes, body FLU axes, T.
    field_magnitude : float
        Local field magnitude B, T (e.g. :func:`ins_gnss_ros.magnetic.wmm.field_elements` total).
    roll, pitch : array_like, shape (N,), optional
        INS roll and pitch of each reading, rad. With them the fit also asks the vertical
        component of the calibrated field to stay constant (the angle between gravity and the
        field is invariant, Li and Li, "Dot product invariance method for accelerometer and
        magnetometer calibration", 2012), which removes the near-degeneracy between the offset
        and the scale along the field's mean direction when the readings cover only a cap.

    Returns
    -------
    HardSoftIron
        c and symmetric W with |W (m - c)| ≈ B for all readings (least squares).
    """
    x = np.asarray(points, float)
    center, p = fit_ellipsoid(x)
    w, v = np.linalg.eigh(p)
    w0 = field_magnitude * (v * np.sqrt(w)) @ v.T  # = B P^(1/2), the algebraic solution
    iu = np.triu_indices(3)
    up = None
    if roll is not None and pitch is not None:
        # Third row of C_Lb = Ry(pitch) Rx(roll): the body-frame components of the local vertical.
        roll, pitch = np.asarray(roll, float), np.asarray(pitch, float)
        up = np.column_stack([-np.sin(pitch), np.cos(pitch) * np.sin(roll),
                              np.cos(pitch) * np.cos(roll)])

    def unpack(q):
        m = np.zeros((3, 3))
        m[iu] = q[:6]
        return m + np.triu(m, 1).T, q[6:9] * field_magnitude

    def residual(q):
        m, c = unpack(q)
        b = (x - c) @ m / field_magnitude
        r = np.linalg.norm(b, axis=1) - 1.0
        if up is None:
            return r
        # q[9]: the (unknown, constant) vertical component of the field over B, i.e. -sin(dip).
        return np.r_[r, np.sum(b * up, axis=1) - q[9]]

    q0 = np.r_[w0[iu], center / field_magnitude]
    if up is not None:
        q0 = np.r_[q0, np.mean(np.sum((x - center) @ w0 * up, axis=1)) / field_magnitude]
    m, c = unpack(least_squares(residual, q0, method="lm").x)
    return HardSoftIron(offset=c, matrix=m)
