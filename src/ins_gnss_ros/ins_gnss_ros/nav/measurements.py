"""Measurement models of the error-state filter: residual z, matrix H, noise covariance R.

Every model returns an :class:`Innovation` with z = predicted - measured ("computed minus
measured", seed 004 eq. 2.1.3 and section 2.6), predicted from the current navigation solution
and the running sensor/clock estimates, and H the Jacobian of the prediction with respect to the
error state of :class:`~ins_gnss_ros.nav.ekf.StateSpace` (conventions in ekf.py: navigation errors
computed minus true, C_nb_computed = (I - [phi x]) C_nb_true; other states true minus estimate).

Attitude terms come from d(C l) = -[phi x] C l = [(C l) x] phi. Lever arms l_b are the sensor's
position relative to the IMU in body FLU (:mod:`ins_gnss_ros.nav.lever_arm`, Groves,
"Principles of GNSS, Inertial and Multisensor Integrated Navigation", 2nd ed., section 14.2.4
and eqs. 14.121-14.122 for the lever-arm terms of the loosely coupled measurement matrix).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from . import _kernels
from .conventions import azimuth_from_yaw, wrap_pi
from .earth import WGS84, earth_rate_enu, ecef_to_enu_matrix, geodetic_to_ecef, normal_gravity
from .error_model import system_matrix
from .lever_arm import lever_arm_position, lever_arm_velocity, lever_arm_velocity_jacobians
from .rotations import cross, quat_to_dcm, skew
from .vehicle_constraint import turned


@dataclass(frozen=True)
class Innovation:
    """A linearised measurement: z = H dx + noise, noise ~ N(0, R).

    Attributes
    ----------
    name : str
    z : ndarray, shape (m,)
        Predicted minus measured.
    H : ndarray, shape (m, n)
    R : ndarray, shape (m, m)
    """

    name: str
    z: np.ndarray
    H: np.ndarray
    R: np.ndarray

    def rows(self, index, name=None):
        """These rows alone (their noise's covariance with the others dropped), as kind `name`
        (default this one's)."""
        index = np.asarray(index)
        return Innovation(self.name if name is None else name, self.z[index], self.H[index],
                          self.R[np.ix_(index, index)])


_I3 = np.eye(3)


def _zeros(space, m):
    return np.zeros((m, space.size))


def _add_time_offset(space, H, dzdt):
    """Column of the "td" state: a measurement stamped t refers to the epoch t - td, so the
    prediction made at t - td_estimate has the residual error dz/dt (td - td_estimate)."""
    if dzdt is not None and "td" in space:
        H[:, space["td"].start] = dzdt


def _with_stamp_noise(R, dzdt, stamp_sigma):
    """R with a stamp's own timing error of standard deviation stamp_sigma (s) added: it moves
    the measurement by dz/dt times that error, as "td" does with its constant part."""
    R = np.asarray(R, float)
    if stamp_sigma > 0.0 and dzdt is not None:
        dzdt = np.asarray(dzdt, float)
        R = R + stamp_sigma ** 2 * np.outer(dzdt, dzdt)
    return R


def _add_lever_arm(space, H, dzdl):
    """Columns of the "lever_*" consider blocks: each is the true lever arm minus the
    configured one along its axis ("true minus estimate", ekf.py), so z moves by -dz/dl."""
    for axis, j in space.lever_arm:
        H[:, j] = -dzdl[:, axis]


def _gyro_columns(space, H, block):
    """Put `block` (m, 3) into the columns of every gyro-bias block of the space."""
    for name in ("bg", "gmg"):
        if name in space:
            H[:, space[name]] = block


def position_residual_enu(lat, lon, h, lat_ref, lon_ref, h_ref, ell=WGS84):
    """(lat, lon, h) - (lat_ref, lon_ref, h_ref) as ENU metres at the reference position.

    Uses the curvilinear scaling of the error state (error_model.py), exact to first order.
    Positions are floats (rad, rad, m).
    """
    return np.array(_kernels.position_residual(lat, lon, h, lat_ref, lon_ref, h_ref, ell.a,
                                               ell.e2))


def gnss_position(space, state, lat, lon, h, cov_enu, lever_b=np.zeros(3), dzdt=None, P=None,
                  stamp_sigma=0.0):
    """GNSS antenna position (loose coupling).

    Parameters
    ----------
    space : StateSpace
    state : NavState
        IMU solution at the measurement epoch.
    lat, lon, h : float
        Measured antenna position (rad, rad, m).
    cov_enu : (3, 3) array_like
        Its covariance in ENU, m^2.
    lever_b : array_like, shape (3,)
        Antenna relative to the IMU, FLU, m.
    dzdt : array_like, shape (3,), optional
        Antenna velocity ENU (m/s), for the time-offset state and the stamp's noise.
    P : (n, n) array_like, optional
        The filter's covariance: with "lever_*" blocks, R gains the second-order term of the
        attitude error times the lever arm's error (:func:`_lever_attitude_variance`).
    stamp_sigma : float
        Standard deviation of the stamp about the epoch, s (GnssFix.stamp_sigma).

    Returns
    -------
    Innovation
        z in ENU metres; H = [I, 0, [(C l) x]] (+ time offset, - C for the "lever_*" blocks).
    """
    # Antenna minus measured = (IMU minus measured) + C l, resolved in the ENU frame of the
    # measured point; the curvature neglected is |l|^2 / R ~ 1e-7 m for a metre-long arm.
    # Compiled: one filter update's model, where numpy's per-call overhead on 3-vectors was
    # most of the cost.
    z, H = np.empty(3), _zeros(space, 3)
    _kernels.gnss_position(state.lat, state.lon, state.h, state.q_nb,
                           np.ascontiguousarray(lever_b, dtype=float), lat, lon, h, WGS84.a,
                           WGS84.e2, z, H, space["pos"].start, space["att"].start)
    _add_time_offset(space, H, dzdt)
    R = _with_stamp_noise(cov_enu, dzdt, stamp_sigma)
    if space.lever_arm:
        C = quat_to_dcm(state.q_nb)
        _add_lever_arm(space, H, C)
        if P is not None:
            R = R + _lever_attitude_variance(space, np.asarray(P, float), C)
    return Innovation("gnss_pos", z, H, R)


#: skew(e_a) of the unit vectors: [phi x] = sum over a of phi_a _SKEW_BASIS[a].
_SKEW_BASIS = np.array([skew(e) for e in _I3])


def _lever_attitude_variance(space, P, C):
    """Covariance of the antenna displacement -[phi x] C dl (m^2, ENU, 3 x 3) by the attitude
    error phi and the error dl of the configured lever arm (its "lever_*" blocks) together.

    The filter linearises at its estimate: the "lever_*" columns are -C of the estimated
    attitude, and the attitude columns take the configured arm, while the antenna hangs on the
    true attitude at the true arm; the difference is the product -[phi x] C dl of two errors,
    which neither column holds. With phi and u = C dl independent and zero-mean its covariance
    is the sum over a, b of P_phi[a, b] S_a U S_b^T (S_a = [e_a x], U = C P_ll C^T): the
    second-order term of the Gaussian second-order filter for a bilinear measurement (Gelb
    (ed.), "Applied Optimal Estimation", 1974, ch. 6; Maybeck, "Stochastic Models, Estimation
    and Control", vol. 2, 1982, ch. 12). It matters where the arm is known to a metre only
    (default.yaml's antenna height) and the fixes to centimetres: 1 m times a tilt error of 5
    mrad is 5 mm. The product is as slow as the attitude error, which a variance cannot say
    (docs/results/product_path.md, "2026-12-05 (session 27)").
    """
    axes, cols = zip(*space.lever_arm)
    Cl = C[:, axes]
    U = Cl @ P[np.ix_(cols, cols)] @ Cl.T
    att = space["att"]
    return np.einsum("ab,aij,jk,blk->il", P[att, att], _SKEW_BASIS, U, _SKEW_BASIS)


#: Physical range of the GNSS velocity's latency estimate ("vd" state), s: a receiver's velocity
#: does not precede its epoch, and a solution averaged over a second lags by half of it.
VELOCITY_LATENCY_RANGE = (0.0, 0.5)


def gnss_velocity(space, state, v_enu, cov_enu, omega_ib_b, lever_b=np.zeros(3), dzdt=None,
                  latency=0.0, lever_rate=None, stamp_sigma=0.0):
    """GNSS antenna velocity (loose coupling).

    Predicted v_a = v + C (omega_ib x l) - omega_ie x (C l) (Groves eq. 2.167). Its error:
    dv + [C (omega x l) x] phi - [omega_ie x][(C l) x] phi - C [l x] d_omega, with d_omega the
    residual gyro error.

    With a "vd" state, the velocity of the epoch t - latency (a receiver's velocity is often a
    filtered or averaged Doppler solution, so it lags its fix, which "td" would move as well):
    predicted v_a(t) - a latency, whose error adds a (vd - latency) for the true latency vd; an
    unknown latency modelled as a state of the filter, with the acceleration as its measurement
    coefficient, as Groves (2nd ed., ch. 14, on INS/GNSS time synchronisation) treats an
    unknown time offset. Observable in accelerations (turns, braking) only.

    Parameters
    ----------
    v_enu : array_like, shape (3,)
        Measured antenna velocity, ENU, m/s.
    cov_enu : (3, 3) array_like
        Its covariance, (m/s)^2.
    omega_ib_b : array_like, shape (3,)
        Compensated angular rate, FLU, rad/s.
    lever_b : array_like, shape (3,)
    dzdt : array_like, shape (3,), optional
        Antenna acceleration ENU (m/s^2), for the time-offset and velocity-latency states and
        the stamp's noise.
    latency : float
        The running estimate of the velocity's latency ("vd" state), s.
    lever_rate : array_like, shape (3,), optional
        The angular rate of the "lever_*" columns (default ``omega_ib_b``): the true rotation
        is their coefficient, and a measured rate's noise would pass for rotation that tells
        the lever arm (a vehicle at rest), so the caller may give a smoothed one.
    stamp_sigma : float
        Standard deviation of the stamp about the epoch, s (GnssVelocity.stamp_sigma).

    Returns
    -------
    Innovation
    """
    pred = lever_arm_velocity(state.v_enu, state.q_nb, omega_ib_b, lever_b, state.lat)
    d_att, d_gyro = lever_arm_velocity_jacobians(state.q_nb, omega_ib_b, lever_b, state.lat)
    H = _zeros(space, 3)
    H[:, space["vel"]] = _I3
    H[:, space["att"]] = d_att
    _gyro_columns(space, H, d_gyro)
    _add_time_offset(space, H, dzdt)
    if space.lever_arm:  # d v_a/d l = C [w x] - [w_ie x] C
        C = quat_to_dcm(state.q_nb)
        rate = omega_ib_b if lever_rate is None else lever_rate
        _add_lever_arm(space, H, C @ skew(rate) - skew(earth_rate_enu(state.lat)) @ C)
    if dzdt is not None and "vd" in space:
        pred = pred - np.asarray(dzdt, float) * latency
        H[:, space["vd"].start] = dzdt
    return Innovation("gnss_vel", pred - np.asarray(v_enu, float), H,
                      _with_stamp_noise(cov_enu, dzdt, stamp_sigma))


#: Kind of the receiver velocity's vertical row, updated apart from its horizontal ones
#: ("gnss_vel"): gated on its own, it does not vouch for the solution (integrity.NOT_VOUCHING).
GNSS_VEL_UP = "gnss_vel_up"


def azimuth_of_axis(q_nb, axis_b=(1.0, 0.0, 0.0)):
    """Azimuth (clockwise from north, rad) of a body axis, and its gradient w.r.t. phi.

    Returns
    -------
    azimuth : float
        In [0, 2 pi).
    grad : ndarray, shape (3,)
        d azimuth / d phi, from d c = -[phi x] c = [c x] phi for the axis c = C axis_b.
    """
    grad = np.empty(3)
    c = _kernels.axis_direction(np.asarray(q_nb, float), np.asarray(axis_b, float), grad)
    # azimuth = pi/2 - yaw (numpy's arctan2: it differs from math.atan2 in the last bit).
    return azimuth_from_yaw(float(np.arctan2(c[1], c[0]))), grad


_X_AXIS = np.array([1.0, 0.0, 0.0])


def heading(space, state, azimuth, variance, baseline_yaw_b=0.0, name="heading"):
    """True heading (e.g. dual-antenna GNSS baseline): azimuth of a horizontal body axis.

    Parameters
    ----------
    azimuth : float
        Measured azimuth of the axis, clockwise from north, rad.
    variance : float
        rad^2.
    baseline_yaw_b : float
        Axis direction in the body, counter-clockwise from body x in the body x-y plane, rad.

    Returns
    -------
    Innovation
        z = azimuth_pred - azimuth (wrapped); for a level vehicle H_att = [0, 0, 1] (seed 004
        section 2.5: H_K(1,1) = +1, z_K = K_pr - K_ext = phi_h).
    """
    axis = _X_AXIS if baseline_yaw_b == 0.0 else \
        (np.cos(baseline_yaw_b), np.sin(baseline_yaw_b), 0.0)
    pred, grad = azimuth_of_axis(state.q_nb, axis)
    H = _zeros(space, 1)
    H[0, space["att"]] = grad
    return Innovation(name, np.array([wrap_pi(pred - azimuth)]), H, np.array([[variance]]))


def biased_heading(space, state, azimuth, variance, bias=0.0, block="mag", field_enu=None):
    """A heading with a bias of its own: a magnetic compass (seed 004 section 2.8:
    z_MK = K_pr - K_mk = phi_h - dK_mk - noise) or an IMU's orientation, already corrected for
    declination.

    With the extra state `block` ("mag", "ahrs") the source's bias b (measured minus true) is
    estimated; `bias` is its running estimate, the state is the residual b - bias, so
    H_block = -1.

    A compass levelled with this filter's own roll and pitch (``field_enu`` given) errs by the
    filter's tilt error: it measures the forward axis against the field's horizontal part as
    the INS attitude C' = (I - [phi x]) C carries the body field into the level frame, so its
    reading is az(C' x_b) - az(F'), F' = (I - [phi x]) F, and z = pred - reading = az(F') -
    az(F) (plus the bias and the noise): H_att is the gradient of the field's azimuth, whose
    tilt columns are the tangent of the inclination (3.3 at St Petersburg: 1 deg of tilt about
    magnetic north is 3.3 deg of heading) and whose yaw column is the axis' own. Fused as a
    yaw alone, the tilt a simulated car's turn left (2-3 deg at a sigma of 2) turned its yaw
    9 deg off (docs/results/product_path.md, "2026-12-06 (session 35)").

    Parameters
    ----------
    azimuth : float
        True azimuth from the compass (magnetic plus declination), rad.
    variance : float
        rad^2.
    bias : float
        Current compass-bias estimate, rad.
    field_enu : array_like, shape (3,), optional
        The Earth field's direction (ENU, any length) where the reading was levelled with the
        filter's roll and pitch; None for a source that levels itself.
    """
    pred, grad = azimuth_of_axis(state.q_nb)
    if field_enu is not None:
        _, grad = azimuth_of_axis(state.q_nb, quat_to_dcm(state.q_nb).T @ field_enu)
    H = _zeros(space, 1)
    H[0, space["att"]] = grad
    if block in space:
        H[0, space[block]] = -1.0
    return Innovation(HEADING_NAMES[block], np.array([wrap_pi(pred + bias - azimuth)]), H,
                      np.array([[variance]]))


#: Innovation names of the biased headings by bias block.
HEADING_NAMES = {"mag": "mag_heading", "ahrs": "imu_heading"}


def phase_differences(space, state, baseline_b, geometry, value, cov):
    """Fixed carrier-phase double differences as attitude measurements: the seeds' second
    differences fused directly (extract_004 sections 2.2.2-2.2.3 and 2.5) instead of the
    attitude solved from them, so the filter weighs each satellite pair with the full DD
    covariance and keeps the pairs' correlations.

    Row j predicts g_j . (C b_j), with b_j the antenna baseline (body FLU) and g_j the
    difference of the unit lines of sight (ENU); the baseline is the same from the IMU as from
    any other point, so no lever arm to the IMU enters. With C_computed = (I - [phi x]) C_true,
    z_j = g_j . (-[phi x] C b_j) = g_j . ((C b_j) x phi), hence H_att row j = (g_j x C b_j)^T.

    Parameters
    ----------
    baseline_b : array_like, shape (m, 3)
        Remote minus master antenna of each row, body FLU, m.
    geometry : array_like, shape (m, 3)
        e_ref - e_sat of each row (unit lines of sight toward the satellites, ENU).
    value : array_like, shape (m,)
        Measured double differences with the integers removed, m.
    cov : array_like, shape (m, m)
        Their covariance, m^2.

    Returns
    -------
    Innovation
        "phase_dd", z in metres.
    """
    g = np.asarray(geometry, float)
    p = np.asarray(baseline_b, float) @ quat_to_dcm(state.q_nb).T   # C b_j, row by row
    H = _zeros(space, len(g))
    H[:, space["att"]] = np.cross(g, p)
    return Innovation("phase_dd", np.einsum("ij,ij->i", g, p) - np.asarray(value, float), H,
                      np.asarray(cov, float))


def zero_velocity(space, state, sigma):
    """ZUPT: the vehicle is at rest, v_enu = 0 (sigma m/s per axis)."""
    H = _zeros(space, 3)
    H[:, space["vel"]] = np.eye(3)
    return Innovation("zupt", np.asarray(state.v_enu, float).copy(), H, sigma ** 2 * np.eye(3))


def horizontal_acceleration(space, state, a_enu, omega_ib_b, sigma):
    """The vehicle's horizontal acceleration is unknown to sigma (m/s^2 per axis): the INS's
    computed one is its error (the tilt's share of gravity, the accelerometers' errors: the
    system matrix's horizontal velocity rows) plus the vehicle's own. Its yaw column is left
    out: a yaw error turns the vehicle's acceleration, which stays as unknown (the heading may
    not be known at all).

    Parameters
    ----------
    a_enu : array_like, shape (3,)
        The INS's mean acceleration over its last segment (ENU, m/s^2).
    omega_ib_b : array_like, shape (3,)
        Compensated angular rate, rad/s.
    """
    g_n = np.array([0.0, 0.0, normal_gravity(state.lat, state.h)])
    f_b = quat_to_dcm(state.q_nb).T @ (np.asarray(a_enu, float) + g_n)
    F = system_matrix(space.layout, state, f_b, omega_ib_b)  # (the core states' block)
    vel, H = space["vel"].start, _zeros(space, 2)
    H[:, :len(F)] = F[vel:vel + 2]
    H[:, space["pos"]] = H[:, space["vel"]] = 0.0  # (Coriolis and transport terms: negligible)
    H[:, space["att"].start + 2] = 0.0
    return Innovation("horizontal_acceleration", np.asarray(a_enu, float)[:2].copy(), H,
                      sigma ** 2 * np.eye(2))


def zero_angular_rate(space, state, omega_ib_b, sigma):
    """ZARU: at rest the body turns only with the Earth, omega_ib_b = C^T omega_ie.

    Parameters
    ----------
    omega_ib_b : array_like, shape (3,)
        Compensated gyro output averaged over the still period, rad/s.
    sigma : float
        rad/s per axis (the white-noise density over the averaging time, plus vibration).

    Returns
    -------
    Innovation
        H = I on the residual gyro-bias states (the attitude term times the Earth rate is
        negligible).
    """
    C = quat_to_dcm(state.q_nb)
    z = np.asarray(omega_ib_b, float) - C.T @ earth_rate_enu(state.lat)
    H = _zeros(space, 3)
    _gyro_columns(space, H, np.eye(3))
    return Innovation("zaru", z, H, sigma ** 2 * np.eye(3))


def vertical_rate_error(space, state, rate, variance):
    """The compensated gyros' rate error about the vertical, measured: a run of fixes' track
    against the INS's yaw (nav/course.py, run_velocity). The residual gyro bias d_omega (body)
    turns the yaw by e_U^T C d_omega per second.

    Parameters
    ----------
    rate : float
        rad/s, counter-clockwise about the up axis.
    variance : float
        (rad/s)^2.
    """
    H = _zeros(space, 1)
    _gyro_columns(space, H, quat_to_dcm(state.q_nb)[2:3])
    return Innovation("course_rate", np.array([float(rate)]), H, np.array([[float(variance)]]))


def nonholonomic(space, state, sigma_lateral, sigma_vertical, omega_ib_b=np.zeros(3),
                 lever_b=np.zeros(3), boresight=np.zeros(2), axes=np.eye(3)):
    """Non-holonomic constraint of a wheeled vehicle: no lateral or vertical velocity at the
    constraint point (the rear axle's centre).

    v_point_b = C^T v_n + omega x l (the Earth rate is negligible over a lever arm); its error is
    C^T dv - C^T [v x] phi - [l x] d_omega (from C_computed^T = C^T (I + [phi x]) and the
    residual gyro error d_omega). The vehicle's forward, lateral and vertical axes are ``axes``
    in the body (the IMU's axes: the identity for an IMU mounted square, or as learned,
    vehicle_constraint.py), turned by small boresight angles (pitch theta, yaw psi): lateral
    v_l - v_f psi and vertical v_v + v_f theta, with v_f, v_l, v_v the body velocity's components
    on the axes. With an "nhc" extra state (the residual boresight, true minus `boresight`)
    H_nhc = [[0, v_f], [-v_f, 0]].

    Parameters
    ----------
    sigma_lateral, sigma_vertical : float
        Constraint noise, m/s (skid, suspension motion).
    omega_ib_b : array_like, shape (3,)
        Compensated angular rate, FLU, rad/s.
    lever_b : array_like, shape (3,)
        Constraint point relative to the IMU, FLU, m.
    boresight : array_like, shape (2,)
        Current estimate of the vehicle-axes pitch and yaw relative to ``axes``, rad.
    axes : array_like, shape (3, 3)
        Rows: the vehicle's forward, lateral and vertical axes as unit vectors in the body.

    Returns
    -------
    Innovation
        z = predicted (lateral, vertical) velocity of the point in vehicle axes - 0.
    """
    # Lateral and vertical vehicle-axes components of a body vector.
    forward, *A = turned(np.asarray(axes, float), boresight)
    A = np.array(A)
    v_b, H = _point_velocity_rows(space, state, omega_ib_b, lever_b, A)
    if "nhc" in space:
        v_f = forward @ v_b
        H[:, space["nhc"]] = [[0.0, v_f], [-v_f, 0.0]]
    z = A @ v_b
    return Innovation("nhc", z, H, np.diag([sigma_lateral ** 2, sigma_vertical ** 2]))


def _point_velocity_rows(space, state, omega_ib_b, lever_b, A):
    """Body-axes velocity v_b = C^T v + omega x l of the point lever_b (FLU, m) and the rows
    A (m, 3) of its Jacobian: A C^T dv - A C^T [v x] phi - A [l x] d_omega (the Earth rate is
    negligible over a lever arm). Returns v_b (3,) and H (m, n)."""
    lever_b = np.asarray(lever_b, float)
    C = quat_to_dcm(state.q_nb)
    v = np.asarray(state.v_enu, float)
    v_b = C.T @ v + cross(omega_ib_b, lever_b)
    H = _zeros(space, len(A))
    H[:, space["vel"]] = A @ C.T
    H[:, space["att"]] = -A @ C.T @ skew(v)
    _gyro_columns(space, H, -A @ skew(lever_b))
    return v_b, H


def wheel_velocity(space, state, velocity_b, variance, omega_ib_b, lever_b=np.zeros(3),
                   scale=0.0):
    """Wheel odometry: the body-axes velocity of its reference point (the rear-axle centre).

    The wheels measure the forward speed (1 + s) v_x, s their scale error (tyre radius); the
    lateral and vertical velocities v_y, v_z they allow are zero when nothing skids (the
    non-holonomic constraint, as in :func:`nonholonomic`), v_b = C^T v + omega x l. With a
    "wheel" extra block (the residual scale error, true minus `scale`) H_wheel = -v_x on the
    forward row (as the speed log's scale column in :func:`speed_log`).

    Parameters
    ----------
    velocity_b : array_like, shape (3,)
        Measured velocity of the point, FLU, m/s (forward from the wheels, lateral and vertical
        usually zero).
    variance : array_like, shape (3,)
        Per-axis variances, (m/s)^2; an infinite one leaves that axis out.
    omega_ib_b : array_like, shape (3,)
        Compensated angular rate, FLU, rad/s.
    lever_b : array_like, shape (3,)
        Reference point relative to the IMU, FLU, m.
    scale : float
        Current scale-error estimate, -.

    Returns
    -------
    Innovation
        z = predicted - measured velocity of the point, one row per axis kept.
    """
    rows = np.isfinite(variance)
    A = np.diag([1.0 + scale, 1.0, 1.0])[rows]
    v_b, H = _point_velocity_rows(space, state, omega_ib_b, lever_b, A)
    if "wheel" in space and rows[0]:
        H[0, space["wheel"]] = -v_b[0]
    z = A @ v_b - np.asarray(velocity_b, float)[rows]
    return Innovation("wheel", z, H, np.diag(np.asarray(variance, float)[rows]))


def speed_log(space, state, speed, variance, current_enu=np.zeros(2), scale=0.0):
    """Speed log: water-relative speed along the body x axis (seed 004 section 2.8).

    V_L = (1 + s) r^T (v - w), r = C e_x the body x axis in ENU, w the horizontal water current
    (ENU) and s the log scale error. Seed 004 writes the same as two components
    V_pr - V_L (sin K, cos K) with the current and log errors lumped into dV^L; here they are
    states: with a "log" extra block [w_E, w_N, s] (residuals, true minus `current_enu` and
    `scale`) H_log = [(1 + s) r_E, (1 + s) r_N, -r^T (v - w)]. The attitude column
    -(1 + s) (C^T [(v - w) x])_x carries seed 004's heading terms (H_L(1,1) = -V_N,
    H_L(2,1) = +V_E).

    Parameters
    ----------
    speed : float
        Measured speed through the water, m/s (positive ahead).
    variance : float
        (m/s)^2.
    current_enu : array_like, shape (2,)
        Current estimate (velocity of the water over ground, E and N), m/s.
    scale : float
        Log scale-error estimate.

    Returns
    -------
    Innovation
    """
    C = quat_to_dcm(state.q_nb)
    w = np.array([current_enu[0], current_enu[1], 0.0])
    rel = np.asarray(state.v_enu, float) - w
    r = C[:, 0]
    H = _zeros(space, 1)
    H[0, space["vel"]] = (1.0 + scale) * r
    H[0, space["att"]] = -(1.0 + scale) * (C.T @ skew(rel))[0]
    if "log" in space:
        H[0, space["log"]] = [(1.0 + scale) * r[0], (1.0 + scale) * r[1], -(r @ rel)]
    return Innovation("speed_log", np.array([(1.0 + scale) * (r @ rel) - speed]), H,
                      np.array([[variance]]))


def _line_of_sight(state, sat_pos_ecef, lever_b):
    """Antenna ECEF position, unit vectors to the satellites (ENU rows) and ranges."""
    lat, lon, h = lever_arm_position(state.lat, state.lon, state.h, state.q_nb, lever_b)
    r = geodetic_to_ecef(lat, lon, h)
    d = np.atleast_2d(np.asarray(sat_pos_ecef, float)) - r
    rho = np.linalg.norm(d, axis=1)
    u_ecef = d / rho[:, None]
    u_enu = u_ecef @ ecef_to_enu_matrix(state.lat, state.lon).T
    return u_ecef, u_enu, rho


def pseudoranges(space, state, sat_pos_ecef, sat_clock_m, pseudorange, variance, clock_m=0.0,
                 lever_b=np.zeros(3)):
    """GNSS pseudoranges of any number of satellites (tight coupling; fewer than 4 is fine).

    rho_pred = |r_sat - r_ant| + clock - sat_clock (seed 004 section 2.4, eq. 2.1.1-2.1.6). The
    satellite positions must be at transmission time, expressed in the ECEF frame of reception
    time (Earth rotation during the signal flight applied by the caller), and the pseudoranges
    corrected for the atmosphere.

    Parameters
    ----------
    sat_pos_ecef : array_like, shape (k, 3)
        Satellite positions, m.
    sat_clock_m : array_like, shape (k,)
        Satellite clock offsets times c, m (positive: the satellite clock is ahead).
    pseudorange : array_like, shape (k,)
        Measured pseudoranges, m.
    variance : float or array_like, shape (k,)
        m^2.
    clock_m : float
        Current receiver clock-offset estimate, m.
    lever_b : array_like, shape (3,)

    Returns
    -------
    Innovation
        H_pos = -u_enu^T, H_att = -u_enu^T [(C l) x], H_clock = -1 (seed 004 H_i(1,22) = -1).
    """
    lever_b = np.asarray(lever_b, float)
    _, u_enu, rho = _line_of_sight(state, sat_pos_ecef, lever_b)
    pred = rho + clock_m - np.asarray(sat_clock_m, float)
    k = len(rho)
    H = _zeros(space, k)
    H[:, space["pos"]] = -u_enu
    H[:, space["att"]] = -u_enu @ skew(quat_to_dcm(state.q_nb) @ lever_b)
    if "clock" in space:
        H[:, space["clock"].start] = -1.0
    R = np.diag(np.broadcast_to(np.asarray(variance, float), (k,)).copy())
    return Innovation("pseudorange", pred - np.asarray(pseudorange, float), H, R)


def range_rates(space, state, sat_pos_ecef, sat_vel_ecef, sat_clock_drift, range_rate,
                variance, omega_ib_b, clock_drift=0.0, lever_b=np.zeros(3)):
    """GNSS range rates (Doppler times -wavelength) of any number of satellites.

    rhodot_pred = u . (v_sat - v_ant) + clock_drift - sat_clock_drift (seed 004 eq. 2.1.1),
    u the unit vector from the antenna to the satellite, v_ant the Earth-relative antenna velocity
    in ECEF.

    Parameters
    ----------
    sat_vel_ecef : array_like, shape (k, 3)
        m/s.
    sat_clock_drift : array_like, shape (k,)
        Satellite clock drift times c, m/s.
    range_rate : array_like, shape (k,)
        Measured range rates = -wavelength * doppler, m/s.
    variance : float or array_like, shape (k,)
        (m/s)^2.
    omega_ib_b : array_like, shape (3,)
        Compensated angular rate, rad/s (for the lever arm).
    clock_drift : float
        Current receiver clock-drift estimate, m/s.

    Returns
    -------
    Innovation
        H_vel = -u_enu^T, lever-arm attitude and gyro terms as in :func:`gnss_velocity`,
        H_drift = -1.
    """
    u_ecef, u_enu, _ = _line_of_sight(state, sat_pos_ecef, lever_b)
    v_ant_enu = lever_arm_velocity(state.v_enu, state.q_nb, omega_ib_b, lever_b, state.lat)
    v_ant_ecef = ecef_to_enu_matrix(state.lat, state.lon).T @ v_ant_enu
    pred = np.einsum("ij,ij->i", u_ecef, np.atleast_2d(sat_vel_ecef) - v_ant_ecef) \
        + clock_drift - np.asarray(sat_clock_drift, float)
    k = len(pred)
    H = _zeros(space, k)
    H[:, space["vel"]] = -u_enu
    d_att, d_gyro = lever_arm_velocity_jacobians(state.q_nb, omega_ib_b, lever_b, state.lat)
    H[:, space["att"]] = -u_enu @ d_att
    _gyro_columns(space, H, -u_enu @ d_gyro)
    if "clock" in space:
        H[:, space["clock"].start + 1] = -1.0
    R = np.diag(np.broadcast_to(np.asarray(variance, float), (k,)).copy())
    return Innovation("range_rate", pred - np.asarray(range_rate, float), H, R)
