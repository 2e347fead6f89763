"""Numba kernels of the per-sample hot loops: strapdown mechanisation and coning/sculling.

This module only holds compiled inner loops; the equations, frames and references are
documented in :mod:`ins_gnss_ros.nav.strapdown` and :mod:`ins_gnss_ros.nav.coning`. Numba
caches the machine code next to the source (``cache=True``): the first call after a change
compiles for a few seconds, a later process loads it in about a second (docs/results/replay.md).
Quaternion arithmetic is written out on scalars here (rather than calling
:mod:`ins_gnss_ros.nav.rotations`, which works on stacked numpy arrays) so that a step allocates
almost nothing. Earth-model formulas are the ones of :mod:`ins_gnss_ros.nav.earth`, compiled
from the same source.
"""
from __future__ import annotations

import math

import numpy as np
from numba import njit

from . import earth

_radii = njit(cache=True)(earth._radii)
_normal_gravity = njit(cache=True)(earth._normal_gravity)


@njit(cache=True)
def _quat_rotvec(x, y, z):
    """Quaternion (w, x, y, z) of a rotation vector, with the small-angle series."""
    a2 = x * x + y * y + z * z
    if a2 < 1e-8:
        k = 0.5 - a2 / 48.0 + a2 * a2 / 3840.0
        w = 1.0 - a2 / 8.0 + a2 * a2 / 384.0
    else:
        a = math.sqrt(a2)
        k = math.sin(0.5 * a) / a
        w = math.cos(0.5 * a)
    return w, k * x, k * y, k * z


@njit(cache=True)
def _qmul(pw, px, py, pz, qw, qx, qy, qz):
    """Hamilton product p ⊗ q."""
    return (pw * qw - px * qx - py * qy - pz * qz,
            pw * qx + px * qw + py * qz - pz * qy,
            pw * qy - px * qz + py * qw + pz * qx,
            pw * qz + px * qy - py * qx + pz * qw)


@njit(cache=True)
def mech_step(lat, lon, h, v, q, dth, dv, dt, ell_par, h_ref, k1, k2, out_v, out_q):
    """One mechanisation step; see :func:`ins_gnss_ros.nav.strapdown.strapdown_step`.

    ell_par = (a, f, e2, m, omega, gamma_e, k). h_ref is NaN to leave the vertical channel
    free. Writes the new velocity and quaternion into out_v, out_q and returns (lat, lon, h).
    """
    a, f, e2, m, omega, gamma_e, ksom = ell_par
    qw, qx, qy, qz = q[0], q[1], q[2], q[3]
    # Delta v rotated into n(k-1) with the attitude at the start of the interval: the body
    # rotation within the interval is already in dv (rotation + sculling terms, coning.py).
    c00 = qw * qw + qx * qx - qy * qy - qz * qz
    c01 = 2.0 * (qx * qy - qw * qz)
    c02 = 2.0 * (qx * qz + qw * qy)
    c10 = 2.0 * (qx * qy + qw * qz)
    c11 = qw * qw - qx * qx + qy * qy - qz * qz
    c12 = 2.0 * (qy * qz - qw * qx)
    c20 = 2.0 * (qx * qz - qw * qy)
    c21 = 2.0 * (qy * qz + qw * qx)
    c22 = qw * qw - qx * qx - qy * qy + qz * qz
    un0 = c00 * dv[0] + c01 * dv[1] + c02 * dv[2]
    un1 = c10 * dv[0] + c11 * dv[1] + c12 * dv[2]
    un2 = c20 * dv[0] + c21 * dv[1] + c22 * dv[2]

    dh_err = 0.0 if math.isnan(h_ref) else h - h_ref
    ve, vn, vu = v[0], v[1], v[2]
    # Predictor (midpoint = start of interval), then corrector with midpoint lat, h, v.
    lat_m, h_m, ve_m, vn_m, vu_m = lat, h, ve, vn, vu
    for _ in range(2):
        rm, rn = _radii(lat_m, a, e2)
        cl, sl = math.cos(lat_m), math.sin(lat_m)
        wie1, wie2 = omega * cl, omega * sl
        wen0 = -vn_m / (rm + h_m)
        wen1 = ve_m / (rn + h_m)
        wen2 = ve_m * sl / cl / (rn + h_m)
        z0, z1, z2 = wen0 * dt, (wie1 + wen1) * dt, (wie2 + wen2) * dt
        # Rotation of the navigation frame over the interval: -1/2 zeta x dv_n.
        dvn0 = un0 - 0.5 * (z1 * un2 - z2 * un1)
        dvn1 = un1 - 0.5 * (z2 * un0 - z0 * un2)
        dvn2 = un2 - 0.5 * (z0 * un1 - z1 * un0)
        g = _normal_gravity(lat_m, h_m, a, f, e2, m, gamma_e, ksom)
        # Coriolis + centripetal of transport: (2 w_ie + w_en) x v.
        o0, o1, o2 = wen0, 2.0 * wie1 + wen1, 2.0 * wie2 + wen2
        cor0 = o1 * vu_m - o2 * vn_m
        cor1 = o2 * ve_m - o0 * vu_m
        cor2 = o0 * vn_m - o1 * ve_m
        ve1 = ve + dvn0 - cor0 * dt
        vn1 = vn + dvn1 - cor1 * dt
        vu1 = vu + dvn2 - (g + cor2 + k2 * dh_err) * dt
        h1 = h + (0.5 * (vu + vu1) - k1 * dh_err) * dt
        h_m = 0.5 * (h + h1)
        lat1 = lat + 0.5 * (vn + vn1) * dt / (rm + h_m)
        lat_mid = 0.5 * (lat + lat1)
        _, rn_mid = _radii(lat_mid, a, e2)
        lon1 = lon + 0.5 * (ve + ve1) * dt / ((rn_mid + h_m) * math.cos(lat_mid))
        lat_m = lat_mid
        ve_m, vn_m, vu_m = 0.5 * (ve + ve1), 0.5 * (vn + vn1), 0.5 * (vu + vu1)

    # q_nb(k) = q_{n(k) n(k-1)} ⊗ q_nb(k-1) ⊗ q_{b(k-1) b(k)}
    rw, rx, ry, rz = _quat_rotvec(dth[0], dth[1], dth[2])
    nw, nx, ny, nz = _quat_rotvec(-z0, -z1, -z2)
    tw, tx, ty, tz = _qmul(qw, qx, qy, qz, rw, rx, ry, rz)
    tw, tx, ty, tz = _qmul(nw, nx, ny, nz, tw, tx, ty, tz)
    s = 1.0 / math.sqrt(tw * tw + tx * tx + ty * ty + tz * tz)
    if tw < 0.0:
        s = -s
    out_q[0], out_q[1], out_q[2], out_q[3] = tw * s, tx * s, ty * s, tz * s
    out_v[0], out_v[1], out_v[2] = ve1, vn1, vu1
    return lat1, lon1, h1


@njit(cache=True)
def correct(lat, lon, h, v, q, dpos, dv, phi, a, e2, out_v, out_q):
    """Remove position, velocity and attitude errors; see
    :func:`ins_gnss_ros.nav.strapdown.apply_correction`. Writes the velocity and quaternion
    into out_v, out_q and returns (lat, lon, h)."""
    rm, rn = _radii(lat, a, e2)
    lat1 = lat - dpos[1] / (rm + h)
    lon1 = lon - dpos[0] / ((rn + h) * math.cos(lat))
    for j in range(3):
        out_v[j] = v[j] - dv[j]
    # q_true = q(phi) ⊗ q_computed, normalised with w >= 0. The same operations in the same
    # order as rotations.quat_normalize (a division by the norm), so that the result is
    # bit-identical to the numpy formulation: a filter decision (gate, mode) can hinge on the
    # last bit.
    rw, rx, ry, rz = _quat_rotvec(phi[0], phi[1], phi[2])
    tw, tx, ty, tz = _qmul(rw, rx, ry, rz, q[0], q[1], q[2], q[3])
    s = math.sqrt(tw * tw + tx * tx + ty * ty + tz * tz)
    if tw < 0.0:
        s = -s
    out_q[0], out_q[1], out_q[2], out_q[3] = tw / s, tx / s, ty / s, tz / s
    return lat1, lon1, h - dpos[2]


@njit(cache=True)
def mech_run(lat, lon, h, v0, q0, dths, dvs, dt, ell_par, h_ref, k1, k2):
    """Run :func:`mech_step` over N increments; returns arrays with N + 1 rows."""
    n = dths.shape[0]
    lla = np.empty((n + 1, 3))
    vel = np.empty((n + 1, 3))
    quat = np.empty((n + 1, 4))
    lla[0, 0], lla[0, 1], lla[0, 2] = lat, lon, h
    vel[0] = v0
    quat[0] = q0
    for i in range(n):
        lat, lon, h = mech_step(lat, lon, h, vel[i], quat[i], dths[i], dvs[i], dt, ell_par,
                                h_ref[i], k1, k2, vel[i + 1], quat[i + 1])
        lla[i + 1, 0], lla[i + 1, 1], lla[i + 1, 2] = lat, lon, h
    return lla, vel, quat


@njit(cache=True)
def _cross_acc(out, s, a0, a1, a2, b0, b1, b2):
    """out += s * (a x b) on scalars (no temporary arrays)."""
    out[0] += s * (a1 * b2 - a2 * b1)
    out[1] += s * (a2 * b0 - a0 * b2)
    out[2] += s * (a0 * b1 - a1 * b0)


@njit(cache=True)
def coning_sculling_run(dtheta, dv, prev_th, prev_v, two_sample, phi, dv_nav):
    """Coning/sculling of M intervals of N sub-samples; see :func:`..coning.coning_sculling`.

    dtheta, dv : (M, N, 3); prev_th, prev_v : (M, 3) sub-sample before each interval
    ("one_sample" only); two_sample : bool. Writes phi and dv_nav, (M, 3).
    """
    m, n = dtheta.shape[0], dtheta.shape[1]
    step = 2 if two_sample else 1
    alpha = np.empty(3)   # running sums at the start of the current block
    ups = np.empty(3)
    con = np.empty(3)     # coning sum
    scu = np.empty(3)     # sculling sum
    th = np.empty(3)      # block increments
    v = np.empty(3)
    for k in range(m):
        alpha[:] = 0.0
        ups[:] = 0.0
        con[:] = 0.0
        scu[:] = 0.0
        for i in range(0, n, step):
            if two_sample:
                a, b, c, d = dtheta[k, i], dtheta[k, i + 1], dv[k, i], dv[k, i + 1]
                for j in range(3):
                    th[j] = a[j] + b[j]
                    v[j] = c[j] + d[j]
                # Within-block terms of the two-sample algorithm (Ignagni; Savage ch. 7).
                _cross_acc(con, 2.0 / 3.0, a[0], a[1], a[2], b[0], b[1], b[2])
                _cross_acc(scu, 2.0 / 3.0, a[0], a[1], a[2], d[0], d[1], d[2])
                _cross_acc(scu, 2.0 / 3.0, c[0], c[1], c[2], b[0], b[1], b[2])
            else:
                if i == 0:
                    tp, vp = prev_th[k], prev_v[k]
                else:
                    tp, vp = dtheta[k, i - 1], dv[k, i - 1]
                for j in range(3):
                    th[j] = dtheta[k, i, j]
                    v[j] = dv[k, i, j]
                # "Previous-interval" one-sample terms (Savage ch. 7).
                _cross_acc(con, 1.0 / 12.0, tp[0], tp[1], tp[2], th[0], th[1], th[2])
                _cross_acc(scu, 1.0 / 12.0, tp[0], tp[1], tp[2], v[0], v[1], v[2])
                _cross_acc(scu, 1.0 / 12.0, vp[0], vp[1], vp[2], th[0], th[1], th[2])
            # Exact between-block parts: 1/2 alpha_start x dtheta_B, 1/2 (alpha x dv_B +
            # upsilon x dtheta_B).
            _cross_acc(con, 0.5, alpha[0], alpha[1], alpha[2], th[0], th[1], th[2])
            _cross_acc(scu, 0.5, alpha[0], alpha[1], alpha[2], v[0], v[1], v[2])
            _cross_acc(scu, 0.5, ups[0], ups[1], ups[2], th[0], th[1], th[2])
            for j in range(3):
                alpha[j] += th[j]
                ups[j] += v[j]
        for j in range(3):
            phi[k, j] = alpha[j] + con[j]
            dv_nav[k, j] = ups[j] + scu[j]
        # Rotation compensation 1/2 alpha x upsilon of the whole interval.
        _cross_acc(dv_nav[k], 0.5, alpha[0], alpha[1], alpha[2], ups[0], ups[1], ups[2])
