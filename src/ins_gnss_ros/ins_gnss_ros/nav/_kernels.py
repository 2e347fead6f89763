"""Numba kernels of the hot loops: strapdown mechanisation, coning/sculling, and the filter
maths (system matrix, Picard series, Joseph update, lever-arm velocity and its Jacobians).

This module only holds compiled inner loops; the equations, frames and references are
documented in :mod:`ins_gnss_ros.nav.strapdown`, :mod:`ins_gnss_ros.nav.coning`,
:mod:`ins_gnss_ros.nav.error_model`, :mod:`ins_gnss_ros.nav.discretize`,
:mod:`ins_gnss_ros.nav.ekf` and :mod:`ins_gnss_ros.nav.lever_arm`. Numba
caches the machine code next to the source (``cache=True``): the first call after a change
compiles for a few seconds, a later process loads it in about a second (docs/results/replay.md);
``scripts/setup.sh`` builds that cache (``scripts/warm_numba.py``), so a first run does not.
Quaternion arithmetic is written out on scalars here (rather than calling
:mod:`ins_gnss_ros.nav.rotations`, which works on stacked numpy arrays) so that a step allocates
almost nothing. Earth-model formulas are the ones of :mod:`ins_gnss_ros.nav.earth`, compiled
from the same source.
"""
from __future__ import annotations

import math

import numpy as np
from numba import guvectorize, njit

from . import earth

_radii = njit(cache=True)(earth._radii)
_ecef = njit(cache=True)(earth._ecef)
_normal_gravity = njit(cache=True)(earth._normal_gravity)


@njit(cache=True)
def geodetic_to_ecef(lat, lon, h, a, e2):
    """(x, y, z) of one point; see earth.geodetic_to_ecef."""
    return _ecef(lat, lon, h, _radii(lat, a, e2)[1], e2)


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
def correct_by_state(lat, lon, h, v, q, dx, pos, vel, att, a, e2, out_v, out_q):
    """:func:`correct` by the position, velocity and attitude errors of an error state dx
    (its blocks of 3 from `pos`, `vel`, `att`): the filter's feedback without slicing dx."""
    return correct(lat, lon, h, v, q, dx[pos:pos + 3], dx[vel:vel + 3], dx[att:att + 3], a, e2,
                   out_v, out_q)


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
def _compensated(measured, dt, bias, scale):
    """One axis of an increment over dt compensated as increments.SensorErrors.compensate
    does: (measured - bias dt) / (1 + scale)."""
    return (measured - dt * bias) / (1.0 + scale)


@njit(cache=True)
def mech_segment(lat, lon, h, v, q, th, dv, cth, cdv, dts, gyro_bias, gyro_scale, accel_bias,
                 accel_scale, accel_cross_z, dt, ell_par, sums, track):
    """The navigator's time update of one segment of raw samples on the solution (lat, lon,
    h, v, q): each increment compensated as increments.SensorErrors.compensate does
    ((measured - bias dts) / (1 + scale)), then the z accelerometer's reading of the x and y
    increments taken out (accel_cross_z, the "nz" states: the strapdown node does not apply
    them, the filter's corrections carry them to it), its coning/sculling terms cth, cdv added,
    and mechanised by :func:`mech_step` at the common step dt with a free vertical channel.

    v and q are updated in place (mech_step reads them before it writes); sums gets the sums
    of the compensated gyro and accelerometer increments (2, 3), in numpy's order (row after
    row, from the first); track (m, 10) the solution (lat, lon, h, v, q) after each of the
    first m samples (m = 0: none kept). Returns (lat, lon, h).
    """
    rot = np.empty(3)
    dvn = np.empty(3)
    for i in range(th.shape[0]):
        for j in range(3):
            a = _compensated(th[i, j], dts[i], gyro_bias[j], gyro_scale[j])
            b = _compensated(dv[i, j], dts[i], accel_bias[j], accel_scale[j])
            if i == 0:
                sums[0, j], sums[1, j] = a, b
            else:
                sums[0, j] += a
                sums[1, j] += b
            rot[j] = a + cth[i, j]
            dvn[j] = b
        cross = accel_cross_z[0] * dvn[0] + accel_cross_z[1] * dvn[1]
        dvn[2] -= cross
        sums[1, 2] -= cross
        for j in range(3):
            dvn[j] += cdv[i, j]
        lat, lon, h = mech_step(lat, lon, h, v, q, rot, dvn, dt, ell_par, math.nan, 0.0, 0.0,
                                v, q)
        if i < track.shape[0]:
            track[i, 0], track[i, 1], track[i, 2] = lat, lon, h
            track[i, 3:6] = v
            track[i, 6:10] = q
    return lat, lon, h


@njit(cache=True)
def mech_step_compensated(lat, lon, h, v, q, th, dv, dt, gyro_bias, gyro_scale, accel_bias,
                          accel_scale, ell_par, out_v, out_q, comp):
    """One :func:`mech_step` with a free vertical channel of the increments (th, dv) over dt
    compensated as increments.SensorErrors.compensate does ((measured - bias dt) /
    (1 + scale)), the compensated increments written into comp (2, 3): the strapdown
    node's per-increment path in one call. Returns (lat, lon, h)."""
    for j in range(3):
        comp[0, j] = _compensated(th[j], dt, gyro_bias[j], gyro_scale[j])
        comp[1, j] = _compensated(dv[j], dt, accel_bias[j], accel_scale[j])
    return mech_step(lat, lon, h, v, q, comp[0], comp[1], dt, ell_par, math.nan, 0.0, 0.0,
                     out_v, out_q)


@njit(cache=True)
def turn_attitude(q, th, cth, dts, gyro_bias, gyro_scale, omega, tail, out_q):
    """q turned by the body rotations of samples (th, cth over dts) compensated as
    :func:`mech_segment` compensates them, then by omega (rad/s) over tail (s); the earth's
    and transport rate left out (navigator.Navigator.attitude_at). Writes out_q."""
    qw, qx, qy, qz = q[0], q[1], q[2], q[3]
    for i in range(th.shape[0]):
        rx = _compensated(th[i, 0], dts[i], gyro_bias[0], gyro_scale[0]) + cth[i, 0]
        ry = _compensated(th[i, 1], dts[i], gyro_bias[1], gyro_scale[1]) + cth[i, 1]
        rz = _compensated(th[i, 2], dts[i], gyro_bias[2], gyro_scale[2]) + cth[i, 2]
        rw, rx, ry, rz = _quat_rotvec(rx, ry, rz)
        qw, qx, qy, qz = _qmul(qw, qx, qy, qz, rw, rx, ry, rz)
    rw, rx, ry, rz = _quat_rotvec(omega[0] * tail, omega[1] * tail, omega[2] * tail)
    qw, qx, qy, qz = _qmul(qw, qx, qy, qz, rw, rx, ry, rz)
    s = 1.0 / math.sqrt(qw * qw + qx * qx + qy * qy + qz * qz)
    out_q[0], out_q[1], out_q[2], out_q[3] = qw * s, qx * s, qy * s, qz * s


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


# --------------------------------------------------------------------------------------------
# Error-state filter: system matrix, Picard propagation, measurement update, lever arm
# (equations in error_model.py, discretize.py, ekf.py and lever_arm.py). These kernels replace
# per-epoch chains of small numpy operations, each of which cost more than its arithmetic.
# They do the same operations in the same order, matrix products with `@` (the same BLAS
# routines as numpy's), so that the filter's results are those of the numpy formulation bit
# for bit (a gate or mode decision can hinge on the last bit; see correct()). One known
# exception: a square x ** 2 is an exact product here, numpy's float64 ** 2 is libm's pow,
# which differs in the last bit for ~0.1 % of arguments (system_matrix's d/dh column).
# --------------------------------------------------------------------------------------------

_normal_gravity_dh = njit(cache=True)(earth._normal_gravity_dh)

#: Sensor-error column kinds of :func:`system_matrix` (error_model.StateLayout.sensor_plan):
#: VERTICAL_CROSS_AXIS is NONORTHOGONALITY's last two terms (ZX, ZY) alone.
BIAS, SCALE, NONORTHOGONALITY, G_SENSITIVITY, VERTICAL_CROSS_AXIS = 0, 1, 2, 3, 4


@njit(cache=True)
def _skew(x, y, z):
    """[v x] of v = (x, y, z)."""
    S = np.zeros((3, 3))
    S[0, 1], S[0, 2] = -z, y
    S[1, 0], S[1, 2] = z, -x
    S[2, 0], S[2, 1] = -y, x
    return S


@njit(cache=True)
def _dcm(q):
    """C_nb of a unit quaternion (rotations.quat_to_dcm)."""
    w, x, y, z = q[0], q[1], q[2], q[3]
    C = np.empty((3, 3))
    C[0, 0] = w * w + x * x - y * y - z * z
    C[0, 1] = 2 * (x * y - w * z)
    C[0, 2] = 2 * (x * z + w * y)
    C[1, 0] = 2 * (x * y + w * z)
    C[1, 1] = w * w - x * x + y * y - z * z
    C[1, 2] = 2 * (y * z - w * x)
    C[2, 0] = 2 * (x * z - w * y)
    C[2, 1] = 2 * (y * z + w * x)
    C[2, 2] = w * w - x * x - y * y + z * z
    return C


@njit(cache=True)
def system_matrix(F, lat, h, v, q, f_b, w_ib_b, ell_par, sensors, misalign_index):
    """Fill the continuous system matrix F (zeroed, n x n) of error_model.system_matrix.

    sensors : (k, 3) int rows (kind, first column, 1 for a gyro block / 0 for an accelerometer
    block); misalign_index : (6, 2) int, sensor_errors.MISALIGN_INDEX.
    """
    a, f, e2, m, omega, gamma_e, ksom = ell_par
    ve, vn, vu = v[0], v[1], v[2]
    rm, rn = _radii(lat, a, e2)
    RM, RN = rm + h, rn + h
    s, c = math.sin(lat), math.cos(lat)
    t = s / c
    w = 1.0 - e2 * s * s
    drn = rn * e2 * s * c / w          # d R_N / d lat
    drm = 3.0 * rm * e2 * s * c / w    # d R_M / d lat
    w_ie = (0.0, omega * c, omega * s)
    w_en = (-vn / RM, ve / RN, ve * math.tan(lat) / RN)

    # Partial derivatives of omega_ie and omega_en w.r.t. dp (ENU metres) and dv. Nothing
    # depends on longitude, and d lat = dp_N / RM, d h = dp_U.
    dwie_dp = np.zeros((3, 3))
    dwie_dp[1, 1] = -omega * s / RM
    dwie_dp[2, 1] = omega * c / RM
    dwen_dp = np.zeros((3, 3))
    dwen_dp[0, 1] = vn * drm / RM ** 2 / RM
    dwen_dp[1, 1] = -ve * drn / RN ** 2 / RM
    dwen_dp[2, 1] = (ve / (c * c * RN) - ve * t * drn / RN ** 2) / RM
    dwen_dp[0, 2] = vn / RM ** 2
    dwen_dp[1, 2] = -ve / RN ** 2
    dwen_dp[2, 2] = -ve * t / RN ** 2
    dwen_dv = np.zeros((3, 3))
    dwen_dv[0, 1] = -1.0 / RM
    dwen_dv[1, 0] = 1.0 / RN
    dwen_dv[2, 0] = t / RN

    # Position rows: d/dt[(RN cos lat) dlon] and d/dt[RM dlat]; the d RM/d lat terms cancel
    # exactly, the d RN/d lat ones do not.
    F[0, 0] = vu / RN - vn * t / RM + vn * drn / (RN * RM)
    F[0, 1] = ve * t / RM - ve * drn / (RN * RM)
    F[0, 2] = -ve / RN
    F[1, 1] = vu / RM
    F[1, 2] = -vn / RM
    for i in range(3):
        F[i, 3 + i] = 1.0

    # Velocity rows.
    V = _skew(ve, vn, vu)
    Vp = V @ (2.0 * dwie_dp + dwen_dp)
    Vv = -_skew(2.0 * w_ie[0] + w_en[0], 2.0 * w_ie[1] + w_en[1], 2.0 * w_ie[2] + w_en[2]) \
        + V @ dwen_dv
    C = _dcm(q)
    f_n = C @ f_b
    Va = _skew(f_n[0], f_n[1], f_n[2])
    # Gravity [0, 0, -g(lat, h)]: vertical gradient, and the (tiny) latitude variation.
    dg_dlat = (_normal_gravity(lat + 1e-6, h, a, f, e2, m, gamma_e, ksom)
               - _normal_gravity(lat - 1e-6, h, a, f, e2, m, gamma_e, ksom)) / 2e-6
    Vp[2, 1] += -dg_dlat / (rm + h)
    Vp[2, 2] += -_normal_gravity_dh(lat, h, _normal_gravity(lat, 0.0, a, f, e2, m, gamma_e, ksom),
                                    a, f, m)
    # Attitude rows.
    Ap = dwie_dp + dwen_dp
    Aa = -_skew(w_ie[0] + w_en[0], w_ie[1] + w_en[1], w_ie[2] + w_en[2])
    for i in range(3):
        for j in range(3):
            F[3 + i, j] = Vp[i, j]
            F[3 + i, 3 + j] = Vv[i, j]
            F[3 + i, 6 + j] = Va[i, j]
            F[6 + i, j] = Ap[i, j]
            F[6 + i, 3 + j] = dwen_dv[i, j]
            F[6 + i, 6 + j] = Aa[i, j]

    # Sensor errors enter through C df (velocity rows) and -C dw (attitude rows), df and dw
    # the increment errors of a triad measuring x_b (f_b or w_ib_b).
    for k in range(sensors.shape[0]):
        kind, col, gyro = sensors[k, 0], sensors[k, 1], sensors[k, 2]
        row, sign = (6, -1.0) if gyro else (3, 1.0)
        x_b = w_ib_b if gyro else f_b
        for i in range(3):
            if kind == BIAS:
                for j in range(3):
                    F[row + i, col + j] = sign * C[i, j]
            elif kind == SCALE:
                for j in range(3):
                    F[row + i, col + j] = sign * (C[i, j] * x_b[j])
            elif kind == NONORTHOGONALITY or kind == VERTICAL_CROSS_AXIS:
                # C Gamma(x_b), Babich eq. 5.4: column k is C[:, r] x_b[s] for the (r, s) term.
                first = 0 if kind == NONORTHOGONALITY else 4
                for j in range(6 - first):
                    m = first + j
                    F[row + i, col + j] = sign * (C[i, misalign_index[m, 0]]
                                                  * x_b[misalign_index[m, 1]])
            else:  # G_SENSITIVITY: C kron(I, f_b^T), rate error = G f_b with G row-major.
                for r in range(3):
                    for j in range(3):
                        F[row + i, col + 3 * r + j] = sign * (C[i, r] * f_b[j])


@njit(cache=True)
def picard_transition(F, dt, order):
    """sum_{i=0..order} (F dt)^i / i!; see discretize.picard_transition."""
    term = np.eye(F.shape[0])
    phi = term.copy()
    for i in range(1, order + 1):
        term = term @ F * (dt / i)
        phi += term
    return phi


@njit(cache=True)
def lyapunov_series(F, P0, Q, dt, order):
    """sum_{i=0..order} K_i dt^i / i!, K_0 = P0, K_1 = F K_0 + K_0 F^T + Q,
    K_{i+1} = F K_i + K_i F^T, symmetrised; see discretize._lyapunov_series."""
    K = P0
    out = K.copy()
    coeff = 1.0
    for i in range(1, order + 1):
        FK = F @ K
        # Each K_i is symmetric, so F K + K F^T = FK + FK^T: one product per order.
        K = FK + FK.T
        if i == 1:
            K = K + Q
        coeff *= dt / i
        out += K * coeff
    return 0.5 * (out + out.T)


@njit(cache=True)
def picard_step(F, P, Q, dt, order):
    """Transition matrix and predicted covariance of one step (ekf.ErrorStateEKF.predict): the
    two series above in one call."""
    return picard_transition(F, dt, order), lyapunov_series(F, P, Q, dt, order)


@njit(cache=True)
def covariance_step(F, refresh, lat, h, v, q, f_b, w_ib_b, ell_par, sensors, misalign_index, P,
                    Q, dt, order):
    """ekf.ErrorStateEKF.predict: when `refresh`, the navigation and sensor rows of F (its
    other entries the model's constant ones, error_model.constant_system_matrix) filled by
    :func:`system_matrix` at the solution (lat, h, v, q) with the compensated specific force
    and rate f_b, w_ib_b; then :func:`picard_step`. Returns (phi, P)."""
    if refresh:
        system_matrix(F, lat, h, v, q, f_b, w_ib_b, ell_par, sensors, misalign_index)
    return picard_step(F, P, Q, dt, order)


@njit(cache=True)
def numpy_sum(a):
    """ndarray.sum of a float64 array (n,), with its bits: numpy's pairwise summation, in its
    order (blocks of up to 128 values by :func:`_block_sum`; a longer run is split into halves,
    the first cut down to a multiple of 8, each summed so and the two sums added). The halving
    is a stack of tasks here: numba's cache does not keep recursive functions safely."""
    tasks = np.empty((192, 2), np.int64)  # (first, length), length -1: add the last two sums
    sums = np.empty(64)
    tasks[0, 0], tasks[0, 1] = 0, a.shape[0]
    n_tasks, n_sums = 1, 0
    while n_tasks:
        n_tasks -= 1
        lo, n = tasks[n_tasks, 0], tasks[n_tasks, 1]
        if n < 0:
            n_sums -= 1
            sums[n_sums - 1] += sums[n_sums]
        elif n <= 128:
            sums[n_sums] = _block_sum(a, lo, n)
            n_sums += 1
        else:
            half = n // 2
            half -= half % 8
            # Run in the reverse order of pushing: the first half, the second, their sum.
            tasks[n_tasks, 0], tasks[n_tasks, 1] = 0, -1
            tasks[n_tasks + 1, 0], tasks[n_tasks + 1, 1] = lo + half, n - half
            tasks[n_tasks + 2, 0], tasks[n_tasks + 2, 1] = lo, half
            n_tasks += 3
    return sums[0]


@njit(cache=True)
def _block_sum(a, lo, n):
    """numpy's sum of a[lo:lo + n], n <= 128: a plain loop under 8 values, else eight partial
    sums over blocks of 8, added pairwise, then the rest one by one."""
    if n < 8:
        res = 0.0
        for i in range(lo, lo + n):
            res += a[i]
        return res
    r = a[lo:lo + 8].copy()
    i = 8
    while i < n - n % 8:
        for j in range(8):
            r[j] += a[lo + i + j]
        i += 8
    res = ((r[0] + r[1]) + (r[2] + r[3])) + ((r[4] + r[5]) + (r[6] + r[7]))
    for k in range(i, n):
        res += a[lo + k]
    return res


@njit(cache=True)
def time_update(lat, lon, h, v, q, t0, t, th, dv, cth, cdv, gyro_bias, gyro_scale, accel_bias,
                accel_scale, accel_cross_z, ell_par, out_v, out_q, a_enu, omega, F, refresh,
                sensors, misalign_index, P, Q, order, track):
    """The navigator's time update of one segment (propagation.propagate): the samples' steps
    from their end times t (N,) after the solution's time t0 (at least 1 us each) and their
    sum T; the solution (lat, lon, h, v, q) mechanised over the samples by
    :func:`mech_segment` at their mean step T / N into (returned lat, lon, h) out_v, out_q
    (and the solution after each of the first m samples into track, (m, 10));
    the segment's mean acceleration (ENU) and compensated rate into a_enu, omega; the
    covariance by :func:`covariance_step` with the model at the segment's start and its mean
    specific force. Returns (lat, lon, h, T, phi, P).
    """
    dts = np.empty(t.shape[0])
    prev = t0
    for i in range(t.shape[0]):
        d = t[i] - prev
        dts[i] = 1e-6 if d < 1e-6 else d  # np.maximum's, a NaN kept
        prev = t[i]
    T = numpy_sum(dts)
    sums = np.empty((2, 3))
    out_v[:] = v
    out_q[:] = q
    lat1, lon1, h1 = mech_segment(lat, lon, h, out_v, out_q, th, dv, cth, cdv, dts, gyro_bias,
                                  gyro_scale, accel_bias, accel_scale, accel_cross_z,
                                  T / th.shape[0], ell_par, sums, track)
    f_b = np.empty(3)
    for j in range(3):
        a_enu[j] = (out_v[j] - v[j]) / T
        omega[j] = sums[0, j] / T
        f_b[j] = sums[1, j] / T
    phi, P = covariance_step(F, refresh, lat, h, v, q, f_b, omega, ell_par, sensors,
                             misalign_index, P, Q, T, order)
    return lat1, lon1, h1, T, phi, P


@njit(cache=True)
def _solve_lower(L, B):
    """L^-1 B by forward substitution, L lower triangular (m, m), B (m, p)."""
    Y = B.copy()
    for i in range(L.shape[0]):
        for k in range(i):
            a = L[i, k]
            for j in range(Y.shape[1]):
                Y[i, j] -= a * Y[k, j]
        for j in range(Y.shape[1]):
            Y[i, j] /= L[i, i]
    return Y


@njit(cache=True)
def _solve_upper_t(L, B):
    """L^-T B by back substitution, L lower triangular (m, m), B (m, p)."""
    X = B.copy()
    for i in range(L.shape[0] - 1, -1, -1):
        for k in range(i + 1, L.shape[0]):
            a = L[k, i]
            for j in range(X.shape[1]):
                X[i, j] -= a * X[k, j]
        for j in range(X.shape[1]):
            X[i, j] /= L[i, i]
    return X


@njit(cache=True)
def _times_ht(A, H, cols):
    """A H^T (p, m) over the columns `cols` of H that hold its nonzero entries."""
    out = np.zeros((A.shape[0], H.shape[0]))
    for i in range(A.shape[0]):
        for j in range(H.shape[0]):
            acc = 0.0
            for k in cols:
                acc += A[i, k] * H[j, k]
            out[i, j] = acc
    return out


@njit(cache=True)
def kalman_update(P, x, H, R, z, gate, force, joseph, min_variance, consider, nu, s_diag, x_new,
                  P_new):
    """Gated update of ekf.ErrorStateEKF.update.

    nu = z - H x, S = H P H^T + R (symmetrised), NIS = |L^-1 nu|^2 with L the Cholesky factor
    of S (gating.normalised_innovation). If NIS <= gate or `force`: K = P H^T S^-1 (through
    L), x + K nu and the Joseph form (I - K H) P (I - K H)^T + K R K^T (or P - K H P),
    symmetrised, with the diagonal floored at min_variance. The gain rows of the states
    `consider` (int64 indices) are zero (Schmidt-Kalman: ekf.ExtraState.consider); the Joseph
    form holds for any gain, P - K H P only for the optimal one.

    Written out in loops over the columns H touches (a handful of the state's): the dense BLAS
    and LAPACK calls it replaces cost more in their set-up and in the zeros of H and I - K H
    than in the arithmetic that matters. The Joseph form is formed as B = P - K (H P),
    B - (B H^T - K R) K^T: the same products regrouped.

    The results go into the caller's arrays (returning new ones costs the call more than the
    arithmetic): nu (m,), diag(S) into s_diag (m,), and, when the measurement is applied, x
    into x_new (n,) and P into P_new (n, n). Returns (nis, applied). Raises LinAlgError if S is
    not positive definite, as np.linalg.cholesky does.
    """
    n, m = P.shape[0], H.shape[0]
    cols = np.empty(n, np.int64)
    used = 0
    for k in range(n):
        for i in range(m):
            if H[i, k] != 0.0:
                cols[used] = k
                used += 1
                break
    cols = cols[:used]
    PHt = _times_ht(P, H, cols)
    S = _times_ht(H, np.ascontiguousarray(PHt.T), cols) + R
    S = 0.5 * (S + S.T)
    for j in range(m):
        s_diag[j] = S[j, j]
        nu[j] = z[j]
        for k in cols:
            nu[j] -= H[j, k] * x[k]
    L = np.linalg.cholesky(S)
    w = _solve_lower(L, nu.reshape((m, 1)))
    nis = 0.0
    for i in range(m):
        nis += w[i, 0] * w[i, 0]
    if not (nis <= gate or force):
        return nis, False
    Kt = _solve_upper_t(L, _solve_lower(L, np.ascontiguousarray(PHt.T)))
    for i in consider:
        Kt[:, i] = 0.0
    K = np.ascontiguousarray(Kt.T)
    for i in range(n):
        x_new[i] = x[i]
        for j in range(m):
            x_new[i] += K[i, j] * nu[j]
    # B = (I - K H) P = P - K (H P), with H P by the rows of P that H touches.
    HP = np.zeros((m, n))
    for i in range(m):
        for k in cols:
            a = H[i, k]
            for j in range(n):
                HP[i, j] += a * P[k, j]
    B = P_new
    B[:, :] = P
    for i in range(n):
        for k in range(m):
            a = K[i, k]
            for j in range(n):
                B[i, j] -= a * HP[k, j]
    if joseph:
        # B A^T + K R K^T = B - (B H^T - K R) K^T.
        C = _times_ht(B, H, cols)
        for i in range(n):
            for j in range(m):
                for k in range(m):
                    C[i, j] -= K[i, k] * R[k, j]
        for i in range(n):
            for k in range(m):
                a = C[i, k]
                for j in range(n):
                    B[i, j] -= a * Kt[k, j]
    # Symmetrised in place (the mean of B and B^T) and the diagonal floored.
    for i in range(n):
        for j in range(i + 1, n):
            B[i, j] = B[j, i] = 0.5 * (B[i, j] + B[j, i])
        if B[i, i] < min_variance:
            B[i, i] = min_variance
    return nis, True


@njit(cache=True)
def extrapolate(lat, lon, h, v, a_enu, dt, a, e2, out_v):
    """Position and velocity moved by dt at constant acceleration; see
    propagation.extrapolate. Writes the velocity into out_v and returns (lat, lon, h)."""
    rm, rn = _radii(lat, a, e2)
    d0 = v[0] * dt + 0.5 * a_enu[0] * dt * dt
    d1 = v[1] * dt + 0.5 * a_enu[1] * dt * dt
    d2 = v[2] * dt + 0.5 * a_enu[2] * dt * dt
    for j in range(3):
        out_v[j] = v[j] + a_enu[j] * dt
    return lat + d1 / (rm + h), lon + d0 / ((rn + h) * math.cos(lat)), h + d2


@njit(cache=True)
def position_residual(lat, lon, h, lat_ref, lon_ref, h_ref, a, e2):
    """(lat, lon, h) - (lat_ref, lon_ref, h_ref) as ENU metres at the reference; see
    measurements.position_residual_enu."""
    rm, rn = _radii(lat_ref, a, e2)
    dlon = (lon - lon_ref + math.pi) % (2.0 * math.pi) - math.pi
    return (rn + h_ref) * math.cos(lat_ref) * dlon, (rm + h_ref) * (lat - lat_ref), h - h_ref


@njit(cache=True)
def _rotate_dcm(q, x):
    """C x with C = _dcm(q), each row summed left to right (numpy's 3x3 @ 3 may round
    differently in the last bit: where both are used, this kernel is the reference)."""
    C = _dcm(q)
    return (C[0, 0] * x[0] + C[0, 1] * x[1] + C[0, 2] * x[2],
            C[1, 0] * x[0] + C[1, 1] * x[1] + C[1, 2] * x[2],
            C[2, 0] * x[0] + C[2, 1] * x[1] + C[2, 2] * x[2])


@njit(cache=True)
def gnss_position(lat, lon, h, q, lever, lat_m, lon_m, h_m, a, e2, z, H, pos, att):
    """Residual z (3,) and the position and attitude columns (from `pos`, `att`) of H (3, n)
    of a GNSS position; see measurements.gnss_position."""
    l0, l1, l2 = _rotate_dcm(q, lever)
    e, n, u = position_residual(lat, lon, h, lat_m, lon_m, h_m, a, e2)
    z[0], z[1], z[2] = e + l0, n + l1, u + l2
    for i in range(3):
        H[i, pos + i] = 1.0
    # [(C l) x]
    H[0, att + 1], H[0, att + 2] = -l2, l1
    H[1, att], H[1, att + 2] = l2, -l0
    H[2, att], H[2, att + 1] = -l1, l0


@njit(cache=True)
def axis_direction(q, axis, grad):
    """ENU direction c = C axis of a body axis, returned, and the gradient of its azimuth
    with respect to phi, minus that of its yaw atan2(c_N, c_E), written into grad; see
    measurements.azimuth_of_axis."""
    c0, c1, c2 = _rotate_dcm(q, axis)
    r2 = c0 ** 2 + c1 ** 2
    # -(c_E [c x]_N - c_N [c x]_E) / r2, the rows of [c x] with their zeros, as numpy forms it.
    grad[0] = -((c0 * c2 - c1 * 0.0) / r2)
    grad[1] = -((c0 * 0.0 - c1 * -c2) / r2)
    grad[2] = -((c0 * -c0 - c1 * c1) / r2)
    return c0, c1, c2


@njit(cache=True)
def _rotate(q, x0, x1, x2):
    """q ⊗ [0, x] ⊗ q* in the expanded form of rotations.quat_rotate:
    x + 2w (u × x) + 2 u × (u × x), u = vector part (the same operations in the same order)."""
    u0, u1, u2 = q[1], q[2], q[3]
    t0 = 2.0 * (u1 * x2 - u2 * x1)
    t1 = 2.0 * (u2 * x0 - u0 * x2)
    t2 = 2.0 * (u0 * x1 - u1 * x0)
    return (x0 + q[0] * t0 + (u1 * t2 - u2 * t1),
            x1 + q[0] * t1 + (u2 * t0 - u0 * t2),
            x2 + q[0] * t2 + (u0 * t1 - u1 * t0))


@njit(cache=True)
def point_velocity(v, q, w, l, lat, omega, out):
    """v + C (w × l) - w_ie × (C l) of one point (3-vectors; lever_arm.point_velocity, at
    every GNSS fix, where the gufunc's broadcasting costs more than the arithmetic)."""
    l0, l1, l2 = _rotate(q, l[0], l[1], l[2])
    a0, a1, a2 = _rotate(q, w[1] * l[2] - w[2] * l[1], w[2] * l[0] - w[0] * l[2],
                         w[0] * l[1] - w[1] * l[0])
    # w_ie = earth_rate_enu = (0, e1, e2); its zero kept in the products, as rotations.cross
    # has it (a NaN lever arm gives NaN in every component there too).
    e1, e2 = omega * math.cos(lat), omega * math.sin(lat)
    out[0] = v[0] + a0 - (e1 * l2 - e2 * l1)
    out[1] = v[1] + a1 - (e2 * l0 - 0.0 * l2)
    out[2] = v[2] + a2 - (0.0 * l1 - e1 * l0)


@guvectorize(["void(float64[:], float64[:], float64[:], float64[:], float64, float64, "
              "float64[:])"], "(n),(m),(n),(n),(),()->(n)", cache=True)
def lever_arm_velocity(v, q, w, l, lat, omega, out):
    """:func:`point_velocity` over the leading dimensions; see lever_arm.lever_arm_velocity
    (a gufunc: numpy broadcasts them, at a fraction of the cost of a chain of array
    operations)."""
    point_velocity(v, q, w, l, lat, omega, out)


@njit(cache=True)
def lever_arm_velocity_jacobians(q, w, l, lat, omega):
    """d v_point / d phi = [(C (w × l)) ×] - [w_ie ×][(C l) ×] and d v_point / d(gyro error)
    = -C [l ×]; see lever_arm.lever_arm_velocity_jacobians."""
    C = _dcm(q)
    a = C @ np.array([w[1] * l[2] - w[2] * l[1], w[2] * l[0] - w[0] * l[2],
                      w[0] * l[1] - w[1] * l[0]])
    b = C @ l
    d_att = _skew(a[0], a[1], a[2]) \
        - _skew(0.0, omega * math.cos(lat), omega * math.sin(lat)) @ _skew(b[0], b[1], b[2])
    d_gyro = -C @ _skew(l[0], l[1], l[2])
    return d_att, d_gyro
