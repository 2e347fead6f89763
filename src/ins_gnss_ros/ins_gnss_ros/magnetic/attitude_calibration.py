"""Hard/soft-iron magnetometer calibration with known attitude (turntable with a reference).

On a turntable the attitude of every sample is known: the reference heading (table angle or the
ISON-2 attitude output, seed 004 Lab 3), the INS roll and pitch, and the Earth field B_n from
the WMM. Each sample then gives the field in body axes, b_k = C_bn,k B_n, and the sensor model of
:mod:`ins_gnss_ros.magnetic.ellipsoid_fit`,

    m_k = A b_k + c + noise,       A = W^-1 (soft iron, scale),  c = hard iron,

is LINEAR in A and c (the error model of Groves §6.1.1 with b_k known instead of only |b_k|).
Unlike the ellipsoid fit, which only knows |b_k| = B, this pins every axis, including the one
along the steep field that a turntable with a single 10° tilt leaves weakly determined in the
ellipsoid fit.

Besides A and c, a constant heading offset δ (the seed's ΔK_mk, rad) is estimated: the triad
behaves as if the table were at K_ref + δ, with K_ref the reference azimuth. It takes up a zero
offset of the table or of the reference, or a yaw mounting error of the unit. Without it a 1°
offset would appear in A as a rotation about the body z axis, which is wrong at every tilted
attitude (the tests measure 2.4° of heading RMS at tilts up to 30° from a 1° offset).

A is symmetric by default (``symmetric=True``). On the seed's recording (level turns plus one
tilt at one heading) a general A and δ are not separable: for level samples a nav-frame rotation
about the vertical and a body-frame rotation about z are the same, and one tilted pose gives only
the three equations that fix the third column of A. A symmetric A (no misalignment of the triad,
the ellipsoid fit's assumption too) leaves 10 unknowns and an over-determined problem: the x, y
entries of the third column follow from the level samples by symmetry, so the tilt has to fix
only A_zz and c. ``symmetric=False`` (a general A: misalignment, non-orthogonality) needs tilted
revolutions at several headings, which separate its body-z rotation from δ.

Attitude noise. The regressors b_k carry the roll/pitch (and reference heading) noise, an
errors-in-variables problem. Each residual is weighted by its own covariance,

    Σ_k = σ_m² I + A J_k Σ_att J_k^T A^T,     J_k = ∂b_k/∂(roll, pitch, heading),

re-evaluated with the current A (iterated "effective variance" weighting, as in York's
straight-line fit). With 0.05° of roll/pitch noise the perturbation of b_k is 46 nT, about the
50 nT sensor noise; at 0.2° the attitude term (mostly the vertical field tipped into the
horizontal body axes, Z σ = 180 nT) dominates, and an unweighted fit lets those samples pull the
third column of A, which the seed's recording (one 10° tilt) determines only weakly. The tests
measure it: at 0.2° tilt noise the hard-iron error is about 70 nT with these weights and 1300 nT
with weights that ignore the attitude noise (ordinary least squares). Constant roll/pitch
errors are not modelled (a 0.05° bias costs about 100 nT).

A recording whose attitudes do not determine the unknowns (e.g. ``symmetric=False`` on the
seed's recording) shows up in ``offset_std`` and ``heading_offset_std``: check them.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.optimize import least_squares

from ins_gnss_ros.magnetic.ellipsoid_fit import HardSoftIron
from ins_gnss_ros.nav.conventions import yaw_from_azimuth
from ins_gnss_ros.nav.rotations import dcm_from_euler

_SYM = (np.array([0, 0, 0, 1, 1, 2]), np.array([0, 1, 2, 1, 2, 2]))  # upper triangle of A


@dataclass
class AttitudeCalibration:
    """Result of :func:`calibrate_with_attitude`.

    Attributes
    ----------
    calibration : HardSoftIron
        Correction b = W (m - c), W = A^-1.
    heading_offset : float
        δ, rad: the triad sees the table at K_ref + δ (subtract it from the compass azimuth to
        read the reference, as ``MagneticCompass(heading_bias=δ)``).
    offset_std : ndarray, shape (3,)
        1σ of the hard iron c from the weighted fit, T.
    heading_offset_std : float
        1σ of δ, rad.
    residual_rms : float
        RMS of the unweighted residuals m_k - A b_k - c, T.
    """

    calibration: HardSoftIron
    heading_offset: float
    offset_std: np.ndarray
    heading_offset_std: float
    residual_rms: float


def body_field(field_enu, roll, pitch, azimuth) -> np.ndarray:
    """Earth field in body FLU axes for known attitudes, b = C_nb^T B_n.

    Parameters
    ----------
    field_enu : array_like, shape (3,)
        Field in ENU, any unit.
    roll, pitch : array_like, shape (N,)
        ROS roll and pitch, rad.
    azimuth : array_like, shape (N,)
        Heading, clockwise from north, rad.

    Returns
    -------
    ndarray, shape (N, 3)
    """
    c_nb = dcm_from_euler(roll, pitch, yaw_from_azimuth(np.asarray(azimuth, float)))
    return np.einsum("nji,j->ni", c_nb, np.asarray(field_enu, float))


def _field_jacobian(b, roll, pitch):
    """∂b/∂(roll, pitch, azimuth), shape (N, 3, 3), columns in that order.

    b = Rx(-roll) Ry(-pitch) Rz(-yaw) B_n, so a small rotation of the body about an axis u
    (body components) changes b by -u × b: u = e_x for roll, Rx(-roll) e_y for pitch and the
    body components of the up axis for yaw (azimuth = π/2 - yaw, hence the sign flip).
    """
    cr, sr = np.cos(roll), np.sin(roll)
    cp, sp = np.cos(pitch), np.sin(pitch)
    zeros = np.zeros_like(roll)
    axes = np.stack([np.stack([zeros + 1.0, zeros, zeros], -1),
                     np.stack([zeros, cr, -sr], -1),
                     -np.stack([-sp, cp * sr, cp * cr], -1)], 1)  # (N, 3 axes, 3)
    return -np.cross(axes, b[:, None, :]).transpose(0, 2, 1)


def calibrate_with_attitude(raw, roll, pitch, azimuth, field_enu, field_std: float = 50e-9,
                            roll_std: float = np.radians(0.05), pitch_std: float = np.radians(0.05),
                            azimuth_std: float = 0.0, symmetric: bool = True,
                            iterations: int = 3) -> AttitudeCalibration:
    """Hard/soft iron and heading offset from a recording with known attitude.

    Parameters
    ----------
    raw : array_like, shape (N, 3)
        Raw magnetometer readings, body FLU axes, T.
    roll, pitch : array_like, shape (N,)
        INS roll and pitch, rad.
    azimuth : array_like, shape (N,)
        Reference heading (table angle or reference system), clockwise from north, rad. A
        constant offset of it is estimated (``heading_offset``).
    field_enu : array_like, shape (3,)
        Earth field in ENU, T (``field_elements(...).enu``).
    field_std : float
        White noise of each magnetometer axis, T.
    roll_std, pitch_std, azimuth_std : float
        White noise of the attitude, rad.
    symmetric : bool
        Symmetric A (10 unknowns with c and δ); False for a general A, which needs tilted
        revolutions (see the module docstring).
    iterations : int
        Re-weighting passes (the weights depend on A).

    Returns
    -------
    AttitudeCalibration

    Raises
    ------
    ValueError
        Inconsistent shapes, or a recording that does not determine the unknowns.
    """
    m = np.asarray(raw, float)
    roll, pitch, azimuth = (np.asarray(a, float) for a in (roll, pitch, azimuth))
    if m.ndim != 2 or m.shape[1] != 3 or not len(m) == len(roll) == len(pitch) == len(azimuth):
        raise ValueError("raw must be (N, 3) and roll, pitch, azimuth (N,)")
    if iterations < 1:
        raise ValueError("iterations must be at least 1")
    field_enu = np.asarray(field_enu, float)
    scale = np.linalg.norm(field_enu)  # work in units of the field for conditioning
    m = m / scale
    n_a = 6 if symmetric else 9
    att_cov = np.diag([roll_std, pitch_std, azimuth_std]) ** 2
    sigma_m = field_std / scale

    def unpack(q):
        if symmetric:
            a = np.zeros((3, 3))
            a[_SYM] = q[:6]
            a = a + np.triu(a, 1).T
        else:
            a = q[:9].reshape(3, 3)
        return a, q[n_a:n_a + 3], q[n_a + 3]

    # A heading offset δ turns the unit about the vertical: C_nb(K + δ) = Rz(-δ) C_nb(K), so
    # b_k(δ) = C_nb,k^T Rz(δ) B_n and the attitudes need to be converted only once.
    c_nb = dcm_from_euler(roll, pitch, yaw_from_azimuth(azimuth))
    field_unit = field_enu / scale

    def model_field(delta):
        return np.einsum("nji,j->ni", c_nb, dcm_from_euler(0.0, 0.0, delta) @ field_unit)

    # Start: ordinary linear least squares with δ = 0, m_k = A b_k + c.
    b = model_field(0.0)
    design = np.column_stack([b, np.ones(len(b))])
    sol, _, rank, _ = np.linalg.lstsq(design, m, rcond=None)
    if rank < 4:
        raise ValueError("the attitudes do not determine the calibration (too few distinct ones)")
    a0 = sol[:3].T
    # On level samples the offset appears as A Rz(δ) (Rz commutes with the level attitude):
    # start δ at the rotation angle of the polar decomposition of the horizontal 2x2 block.
    delta0 = np.arctan2(a0[1, 0] - a0[0, 1], a0[0, 0] + a0[1, 1])
    a0 = a0 @ dcm_from_euler(0.0, 0.0, -delta0)
    a0 = 0.5 * (a0 + a0.T) if symmetric else a0
    q = np.r_[a0[_SYM] if symmetric else a0.ravel(), sol[3], delta0]

    for _ in range(iterations):
        a, _, delta = unpack(q)
        b = model_field(delta)
        j = np.einsum("ij,njk->nik", a, _field_jacobian(b, roll, pitch))
        cov = sigma_m ** 2 * np.eye(3) + j @ att_cov @ j.transpose(0, 2, 1)
        whiten = np.linalg.inv(np.linalg.cholesky(cov))  # r^T Σ^-1 r = |L^-1 r|²

        def residual(qq):
            aa, cc, dd = unpack(qq)
            r = m - model_field(dd) @ aa.T - cc
            return np.einsum("nij,nj->ni", whiten, r).ravel()

        fit = least_squares(residual, q, method="lm", x_scale="jac")
        q = fit.x

    jac = fit.jac
    s = np.linalg.svd(jac, compute_uv=False)
    if s[-1] < 1e-9 * s[0]:
        raise ValueError("the attitudes do not determine the calibration (singular fit)")
    dof = max(jac.shape[0] - jac.shape[1], 1)
    chi2 = 2.0 * fit.cost / dof  # > 1 when the stated noise is too small: inflate σ honestly
    p_cov = np.linalg.inv(jac.T @ jac) * max(chi2, 1.0)
    std = np.sqrt(np.diag(p_cov))
    a, c, delta = unpack(q)
    resid = m - model_field(delta) @ a.T - c
    return AttitudeCalibration(
        calibration=HardSoftIron(offset=c * scale, matrix=np.linalg.inv(a)),
        heading_offset=float(delta),
        offset_std=std[n_a:n_a + 3] * scale,
        heading_offset_std=float(std[n_a + 3]),
        residual_rms=float(np.sqrt(np.mean(resid ** 2)) * scale))
