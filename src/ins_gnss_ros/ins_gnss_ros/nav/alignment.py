"""Initial alignment: static levelling and gyrocompassing, in-motion heading, and the
iterative steepest-descent alignment of seed 002 (Naumchenko).

Frames: navigation ENU, body FLU, ROS Euler angles C_nb = Rz(yaw) Ry(pitch) Rx(roll).
Attitude-error covariances are for φ of :mod:`ins_gnss_ros.nav.error_model`
(C̃_nb = (I - [φ×]) C_nb).

Static alignment (Groves §5.6; Titterton & Weston, Strapdown Inertial Navigation
Technology, ch. 10).  At rest the accelerometers
sense f_b = C_nb^T [0, 0, g] and the gyros ω_b = C_nb^T ω_ie, so

    roll  = atan2(f_y, f_z),   pitch = atan2(-f_x, √(f_y² + f_z²))
    yaw   = atan2(w_x, w_y),   w = Ry(pitch) Rx(roll) ω_b  (ω_ie in the levelled body axes)

Error theory (derived from C̃ f̃_b = g e_z and (C̃ ω̃_b)_E = 0 to first order):

    φ_E = -b_N / g,   φ_N = b_E / g,   φ_U = -ε_E / (Ω cos L) + φ_N tan L

with b and ε the accelerometer and gyro errors resolved in ENU.  When ε ≳ Ω cos L (MEMS),
heading is unobservable from the gyros: the covariance then reports a uniform heading.

The navigator's alignment (navigator.py) levels on the IMU data before the first fix
(:class:`Levelling`, :func:`levelled_state`) and starts the filter with the yaw out of it
(:func:`initial_covariance`); the heading follows from the first motion
(:func:`yaw_error_from_motion`) or heading fix (:func:`yaw_error_from_heading`), and
:func:`rotate_yaw` turns the solution and its covariance onto it.
"""

from dataclasses import dataclass, field, replace

import numpy as np

from .conventions import wrap_pi
from .course import ACCELERATION_CHANGE, WINDOW_S
from .earth import WGS84, normal_gravity
from .error_model import system_matrix
from .lever_arm import lever_arm_position, lever_arm_velocity
from .measurements import Innovation, gnss_position, position_residual_enu
from .propagation import extrapolate
from .rotations import quat_from_euler, quat_from_rotvec, quat_mul, quat_normalize, \
    quat_rotate, quat_to_dcm
from .strapdown import NavState, apply_correction

#: Variance of a heading uniformly distributed on [-π, π) [rad²].
UNIFORM_HEADING_VAR = np.pi ** 2 / 3.0
#: 1σ of the angle between the body x axis and the course over ground at the IMU [rad]: a
#: car's body slip angle stays within a few degrees short of skidding (what stability control
#: keeps it to), a wheeled robot's is less; a ship's drift angle in a cross current may exceed
#: it, where a heading source or the motion alignment against the INS velocity (no side-slip
#: assumed) is the better path.
SIDE_SLIP_SIGMA = np.radians(3.0)
#: Largest 1 sigma of a course the heading is aligned on while the IMU is still [rad]: a speed
#: of five standard deviations of the velocity across it. Still, the vehicle stands or moves
#: steadily straight on; a noisy receiver's speed at rest passes the alignment speed by noise
#: alone (0.3 m/s per axis: 0.5 m/s on a quarter of the epochs) with a random course, five
#: sigmas once in exp(12.5) = 270,000 epochs.
MAX_STILL_COURSE_SIGMA = 0.2
#: Smallest INS horizontal speed, as a share of the receiver's, whose direction a heading
#: aligns against (:func:`yaw_error_from_motion`): slower, motion started before the filter.
MIN_INS_SPEED_SHARE = 0.3


def level(f_b):
    """Roll and pitch from the mean specific force of a static IMU.

    Parameters
    ----------
    f_b : array_like, shape (3,)
        Mean specific force in body (FLU) axes [m/s²].

    Returns
    -------
    roll, pitch : float [rad]
    """
    fx, fy, fz = f_b
    return float(np.arctan2(fy, fz)), float(np.arctan2(-fx, np.hypot(fy, fz)))


def gyrocompass(w_ib_b, roll, pitch):
    """Yaw from the mean angular rate of a static, levelled IMU.

    Parameters
    ----------
    w_ib_b : array_like, shape (3,)
        Mean angular rate in body axes [rad/s] (the Earth rate plus sensor errors).
    roll, pitch : float
        From :func:`level` [rad].

    Returns
    -------
    float
        Yaw [rad], counter-clockwise from East.
    """
    w = quat_to_dcm(quat_from_euler(roll, pitch, 0.0)) @ np.asarray(w_ib_b, float)
    # In the levelled axes ω_ie = Ω cos L (sin yaw, cos yaw, ·).
    return float(np.arctan2(w[0], w[1]))


def coarse_alignment_covariance(lat, accel_sigma, gyro_sigma, ell=WGS84):
    """Covariance of φ after static levelling and gyrocompassing (module docstring).

    Parameters
    ----------
    lat : float
        Latitude [rad].
    accel_sigma : float
        1σ of the horizontal accelerometer error averaged over the alignment [m/s²].
    gyro_sigma : float
        1σ of the east gyro error averaged over the alignment [rad/s].

    Returns
    -------
    (3, 3) ndarray [rad²]
    """
    g = normal_gravity(lat, 0.0, ell)
    var_tilt = (accel_sigma / g) ** 2
    P = np.diag([var_tilt, var_tilt, 0.0])
    horizontal_rate = ell.omega * np.cos(lat)
    var_u = (gyro_sigma / horizontal_rate) ** 2 + np.tan(lat) ** 2 * var_tilt
    if var_u < UNIFORM_HEADING_VAR:
        P[2, 2] = var_u
        P[1, 2] = P[2, 1] = np.tan(lat) * var_tilt
    else:
        P[2, 2] = UNIFORM_HEADING_VAR
    return P


@dataclass(frozen=True)
class Alignment:
    """Result of an alignment.

    Attributes
    ----------
    q_nb : (4,) ndarray
        Attitude, ENU <- FLU.
    cov_phi : (3, 3) ndarray
        Covariance of the attitude error φ [rad²].
    iterations : int
        Iterations used (0 for closed-form methods).
    """

    q_nb: np.ndarray
    cov_phi: np.ndarray
    iterations: int = 0


def coarse_alignment(dthetas, dvs, dt, lat, grade=None, ell=WGS84):
    """Static levelling and gyrocompassing from increments recorded at rest.

    Parameters
    ----------
    dthetas, dvs : array_like, shape (N, 3)
        Angle [rad] and velocity [m/s] increments in body axes.
    dt : float
        Increment interval [s].
    lat : float
        Latitude [rad].
    grade : ImuGrade, optional
        Sensor budget for the covariance (turn-on + Gauss-Markov bias, white noise averaged
        over the N dt seconds, gravity through non-orthogonality and g-sensitivity); without
        it cov_phi is NaN.

    Returns
    -------
    Alignment
    """
    duration = len(dthetas) * dt
    f_b = np.sum(dvs, axis=0) / duration
    w_b = np.sum(dthetas, axis=0) / duration
    roll, pitch = level(f_b)
    yaw = gyrocompass(w_b, roll, pitch)
    if grade is None:
        cov = np.full((3, 3), np.nan)
    else:
        g = normal_gravity(lat, 0.0, ell)

        def averaged(t, gravity_term):
            return np.sqrt(t.bias_sigma ** 2 + t.gm_sigma ** 2 + t.white_density ** 2 / duration
                           + gravity_term ** 2)
        # A level horizontal sensor also sees g through its non-orthogonality (accelerometer)
        # or g-sensitivity (gyro).
        cov = coarse_alignment_covariance(
            lat, averaged(grade.accel, grade.accel.misalign_sigma * g),
            averaged(grade.gyro, grade.g_sensitivity_sigma * g), ell)
    return Alignment(quat_from_euler(roll, pitch, yaw), cov)


def course_gradient(v_enu):
    """Gradient of the course atan2(v_N, v_E) with respect to the velocity (ENU, m/s): the
    horizontal unit vector across v over its speed, e_U x v / |v_h|^2 [rad/(m/s)]."""
    ve, vn = v_enu[0], v_enu[1]
    return np.array([-vn, ve, 0.0]) / (ve * ve + vn * vn)


def yaw_from_velocity(v_enu, cov_enu):
    """Yaw from the course over ground of a vehicle moving forward without side-slip.

    Parameters
    ----------
    v_enu : array_like, shape (3,)
        GNSS velocity [m/s].
    cov_enu : (3, 3) array_like
        Its covariance [(m/s)^2].

    Returns
    -------
    yaw, sigma_yaw : float [rad]
        sigma_yaw^2 = c' S c / |v_h|^2, c the horizontal unit vector across v and S its
        covariance: the course's error is the cross-track velocity error over the speed.
    """
    grad = course_gradient(v_enu)
    return float(np.arctan2(v_enu[1], v_enu[0])), float(np.sqrt(grad @ np.asarray(cov_enu) @ grad))


def course_is_known(v_enu, cov_enu):
    """The course over ground of a GNSS velocity (ENU, m/s; covariance (m/s)^2) is known well
    enough to align the heading on while the IMU is still: its sigma is at most
    MAX_STILL_COURSE_SIGMA (a zero velocity has no course)."""
    return bool(v_enu[0] or v_enu[1]) and \
        yaw_from_velocity(v_enu, cov_enu)[1] <= MAX_STILL_COURSE_SIGMA


def yaw_from_heading(azimuth, sigma_azimuth, baseline_yaw_b=0.0):
    """Body yaw from a heading (azimuth) measurement, e.g. a dual-antenna GNSS baseline.

    Parameters
    ----------
    azimuth : float
        Clockwise from North [rad] (ins_gnss_msgs/Heading).
    sigma_azimuth : float [rad]
    baseline_yaw_b : float
        Direction of the measured axis in body axes, counter-clockwise from body x [rad]
        (0 for a baseline along the forward axis).

    Returns
    -------
    yaw, sigma_yaw : float [rad]
        yaw counter-clockwise from East, not wrapped (a rotation by the difference of two yaws
        does not need it, and wrapping would change the last bits of the navigator's result).
    """
    return float(0.5 * np.pi - azimuth - baseline_yaw_b), float(sigma_azimuth)


def initial_attitude(roll, pitch, yaw, sigma_tilt, sigma_yaw):
    """Attitude and φ covariance from separately determined tilt and yaw.

    For small tilts a yaw error δψ is φ_U = -δψ and roll/pitch errors are horizontal φ.

    Returns
    -------
    Alignment
    """
    return Alignment(quat_from_euler(roll, pitch, yaw),
                     np.diag([sigma_tilt ** 2, sigma_tilt ** 2, sigma_yaw ** 2]))


@dataclass(frozen=True)
class Levelling:
    """IMU increments summed over the data before the first fix, for its levelling.

    Attributes
    ----------
    dv_sum, dtheta_sum : (3,) ndarray
        Sums of the raw velocity [m/s] and angle [rad] increments, body FLU.
    time : float
        Time they cover [s].
    """

    dv_sum: np.ndarray = field(default_factory=lambda: np.zeros(3))
    time: float = 0.0
    dtheta_sum: np.ndarray = field(default_factory=lambda: np.zeros(3))

    def add(self, dtheta, dv, dt):
        """The levelling with increments dtheta, dv (N, 3) [rad, m/s] of dt [s] each added."""
        return Levelling(self.dv_sum + dv.sum(axis=0), self.time + len(dv) * dt,
                         self.dtheta_sum + dtheta.sum(axis=0))

    def gyro_bias(self, gyro_psd, bias_sigma):
        """The gyro bias of a static start: the mean rate [rad/s, FLU], and its variance
        [rad^2/s^2] (the Earth rate the mean also holds, unknown without the heading, plus the
        white noise over the levelling time), or None where the gyros are too good for it: a
        bias sigma below ten Earth rates is better known than the mean tells (tactical and
        navigation grades gyrocompass instead)."""
        if bias_sigma < 10.0 * WGS84.omega or self.time <= 0.0:
            return None
        return self.dtheta_sum / self.time, WGS84.omega ** 2 + gyro_psd / self.time

    def mean_specific_force(self):
        """The mean specific force levelled on, body FLU [m/s^2]."""
        return self.dv_sum / self.time

    def attitude(self):
        """Levelled attitude q_nb with yaw 0 (:func:`level` of the mean specific force)."""
        roll, pitch = level(self.mean_specific_force())
        return quat_from_euler(roll, pitch, 0.0)


def take_static_gyro_bias(levelling, space, noise, P, estimates):
    """At a static start, the gyro bias from the stationary mean (:meth:`Levelling.gyro_bias`)
    into the running ``estimates`` and the covariance ``P`` (in place). A MEMS unit's turn-on
    bias (degrees per second on the data sheets) left to the filter makes the tilt drift faster
    than the aiding corrects it, and the updates are gated. Returns whether it was taken."""
    bias = levelling.gyro_bias(noise.gyro_psd, noise.blocks["bg"].sigma0) \
        if "bg" in space else None
    if bias is not None:
        block = space["bg"]
        estimates["bg"] = bias[0]
        P[block, block] = np.eye(3) * bias[1]
    return bias is not None


def levelled_state(levelling, lat, lon, h, lever_b, speed, t, climb=0.0):
    """The first solution: levelled with yaw 0 at the IMU below an antenna fix.

    Parameters
    ----------
    levelling : Levelling
    lat, lon, h : float
        Antenna position [rad, rad, m].
    lever_b : (3,) ndarray
        Antenna relative to the IMU, FLU [m].
    speed : float
        Horizontal speed [m/s]: 0 at rest, the last GNSS speed in motion (NaN if none yet).
    t : float
        Time of the state [s].
    climb : float
        The receiver's vertical velocity in motion [m/s, up] (0 where it has none).

    Returns
    -------
    NavState
        At rest, or moving at speed along the body x axis (started in motion: no side-slip
        assumed in the yaw-free frame), horizontally, climbing as the receiver says: the
        levelled x axis is pitched by the grade and by whatever the vehicle's acceleration
        left in the levelling, so its pitch tells neither (a simulated car speeding up at
        0.7-1.4 m/s^2, levelled 5.7 deg off, started climbing at 1.1 m/s along it, took it for
        160 mg of z accelerometer bias and ran dead reckoning for most of 90 s:
        docs/results/product_path.md, "2026-12-07 (session 45)").
    """
    q = levelling.attitude()
    lat, lon, h = lever_arm_position(lat, lon, h, q, -lever_b)
    v = np.zeros(3)
    if np.isfinite(speed) and speed > 0.0:
        x = quat_rotate(q, [1.0, 0.0, 0.0])
        v[:2] = speed * x[:2] / np.hypot(x[0], x[1])
        v[2] = climb
    return NavState(lat, lon, h, v, q, t)


def initial_covariance(space, noise, sigma_pos, sigma_vel, sigma_tilt):
    """Covariance of the filter started on a levelled state.

    The yaw is unknown until the first motion or heading fix: its variance is kept out of the
    filter (set by :func:`rotate_yaw`) so that no update leans on it.

    Parameters
    ----------
    space : StateSpace
    noise : FilterNoise
        Initial sigmas of the sensor-error blocks.
    sigma_pos, sigma_vel, sigma_tilt : float
        Position [m], velocity [m/s] and tilt [rad] standard deviations.

    Returns
    -------
    (n, n) ndarray
    """
    sig = np.zeros(space.size)
    sig[space["pos"]] = sigma_pos
    sig[space["vel"]] = sigma_vel
    sig[space["att"]] = [sigma_tilt, sigma_tilt, 0.0]
    for name in space.blocks[3:]:
        if name in space.extras:
            sig[space[name]] = space.extras[name].sigma0
        elif name == "clock":
            sig[space[name]] = (3e5, 100.0, 0.1)
        else:
            sig[space[name]] = noise.blocks[name].sigma0
    return np.diag(sig ** 2)


def couple_start_to_lever_arm(P, space, q_nb):
    """The start's covariance P (n, n; in place) with the position error that of the
    antenna's place less the lever arm: the filter places the IMU at the first fix less
    C l (C of the levelled attitude ``q_nb``), so where the lever arm is uncertain (its
    consider blocks "lever_*", true minus configured, ekf.py) the IMU's position errs by C dl
    as well: cov(dp, dl) = C P_ll and P_pp gains C P_ll C'. Without it the start stood for an
    independent measurement of the IMU's place, and the antenna's fixes then narrowed the
    IMU's height below what the unknown antenna height allows (a simulated RTK drive, antenna
    1.5 m above the IMU, default lever sigma 1 m: height error 1.07 m against a published
    0.42 m)."""
    C, pos = quat_to_dcm(q_nb), space["pos"]
    for axis, j in space.lever_arm:
        column = C[:, axis] * P[j, j]
        P[pos, j] = P[j, pos] = column
        P[pos, pos] += np.outer(C[:, axis], column)


def couple_tilt_to_accelerometers(P, space, nav, f_b, sigma_level):
    """The start's covariance P (n, n; in place) with the levelled tilt's error that of the
    accelerometers' biases: levelling makes the computed horizontal specific force zero, so
    the tilt error is the one that cancels the biases' horizontal part, psi_h = M b (M from the
    system matrix's velocity rows at the levelled state), plus the levelling's own error of
    sigma_level (rad; vibration, the vehicle's own sway): P[tilt, tilt] = M P_bb M' +
    sigma_level^2, P[tilt, ba] = M P_bb. Taken as independent, a tilt known to 1 deg held a
    MEMS unit's 50 mg biases to 16 mg from the first rest on (docs/results/product_path.md,
    "2026-12-06 (session 30)").

    Parameters
    ----------
    nav : NavState
        The levelled solution.
    f_b : (3,) array_like
        The mean specific force levelled on, body FLU [m/s^2].
    """
    if "ba" not in space:
        return
    F = system_matrix(space.layout, nav, f_b, np.zeros(3))
    att, ba = space["att"], space["ba"]
    vel_h = slice(space["vel"].start, space["vel"].start + 2)
    tilt = slice(att.start, att.start + 2)
    M = -np.linalg.solve(F[vel_h, tilt], F[vel_h, ba])
    P_bb = P[ba, ba]
    P[tilt, tilt] = M @ P_bb @ M.T + sigma_level ** 2 * np.eye(2)
    P[tilt, ba] = M @ P_bb
    P[ba, tilt] = P[tilt, ba].T


def yaw_of_x(q_nb):
    """Yaw of the body x axis [rad, counter-clockwise from East]."""
    x = quat_to_dcm(q_nb)[:, 0]
    return np.arctan2(x[1], x[0])


def yaw_error_from_motion(v_gnss, cov_gnss, v_ins, q_nb):
    """Yaw rotation onto the GNSS course of an INS levelled with an arbitrary yaw.

    The INS has run levelled but with an arbitrary yaw since the first fix, so its horizontal
    velocity is the true one rotated by minus the yaw error: the angle between the two velocity
    vectors is that error (no side-slip assumption). If the INS velocity is too small to
    compare (motion started before the filter), the course of the GNSS velocity is taken as the
    heading of the body x axis instead (:func:`yaw_error_from_course`).

    Parameters
    ----------
    v_gnss : (3,) array_like
        GNSS velocity, ENU [m/s].
    cov_gnss : (3, 3) array_like
        Its covariance [(m/s)^2].
    v_ins : (3,) array_like
        INS velocity, ENU [m/s].
    q_nb : (4,) array_like
        INS attitude.

    Returns
    -------
    delta, sigma : float [rad]
        Rotation about Up to apply, and the standard deviation of the GNSS course in it.
    velocity_gain : (3,) ndarray or None
        The course's gradient at the INS velocity (:func:`course_gradient`): the rotation also
        carries the error of the INS velocity's direction, which :func:`rotate_yaw` takes from
        the velocity covariance (the yaw variance after it is sigma^2 + c' P_vv c / |v_ins|^2).
        None where the body x axis was compared instead.
    """
    if np.hypot(*v_ins[:2]) > MIN_INS_SPEED_SHARE * np.hypot(*v_gnss[:2]):
        course, sigma = yaw_from_velocity(v_gnss, cov_gnss)
        return course - np.arctan2(v_ins[1], v_ins[0]), sigma, course_gradient(v_ins)
    return (*yaw_error_from_course(v_gnss, cov_gnss, q_nb), None)


def yaw_error_from_course(v_gnss, cov_gnss, q_nb):
    """Yaw rotation of an INS attitude q_nb that puts its body x axis on the course of the GNSS
    velocity v_gnss (ENU, m/s) of covariance cov_gnss ((m/s)^2).

    Returns
    -------
    delta, sigma : float [rad]
        Rotation about Up to apply, and the yaw standard deviation after it: the course's
        (:func:`yaw_from_velocity`) and the body's side-slip angle (SIDE_SLIP_SIGMA).
    """
    course, sigma = yaw_from_velocity(v_gnss, cov_gnss)
    return course - yaw_of_x(q_nb), float(np.hypot(sigma, SIDE_SLIP_SIGMA))


def without_cross_track(innov, v_enu):
    """A velocity innovation (3 rows, ENU) reduced to its along-track and vertical rows, across
    the velocity v_enu (m/s) whose course a motion alignment (:func:`rotate_yaw` with a
    velocity gain) has just turned the solution onto: the solution's cross-track velocity error
    is then that velocity's own, and an update with it would count the course twice."""
    u = np.array([v_enu[0], v_enu[1], 0.0]) / np.hypot(v_enu[0], v_enu[1])
    rows = np.array([u, [0.0, 0.0, 1.0]])
    return Innovation(innov.name, rows @ innov.z, rows @ innov.H, rows @ innov.R @ rows.T)


def restart_velocity(nav, P, space, v_enu, cov_enu, gain):
    """The solution's velocity replaced by a measured one (ENU, m/s) of covariance cov_enu (3,
    3, (m/s)^2): for an INS that ran unaided too long to know it, just aligned on that
    velocity's course. gain: :func:`course_error_gain` with ``restarted``; the yaw (and what
    turned with it) keeps its correlation with the velocity error both came from."""
    k = space["vel"]
    P = P.copy()
    cross = np.asarray(gain) @ np.asarray(cov_enu, float)  # cov(errors, velocity error)
    P[:, k] = cross
    P[k, :] = cross.T
    P[k, k] = cov_enu
    return replace(nav, v_enu=np.asarray(v_enu, float).copy()), P


def yaw_error_gain(nav, space, run):
    """How a yaw error phi_U of a solution just turned onto a heading (:func:`rotate_yaw`)
    shows in its other errors (n,): the velocity turned with it errs by v x e_U phi_U (the
    velocity error equation, error_model.py, integrated over the accelerations since the rest),
    the distance run (ENU, m) turned with it by run x e_U phi_U."""
    g = np.zeros(space.size)
    g[space["att"].stop - 1] = 1.0
    g[space["vel"]] = np.cross(nav.v_enu, [0.0, 0.0, 1.0])
    g[space["pos"]] = np.cross(run, [0.0, 0.0, 1.0])
    return g


def course_error_gain(nav, space, v_enu, pivot=None, restarted=False):
    """The errors (n, 3) of a solution just aligned on the course of velocity v_enu (ENU, m/s)
    per unit error of that velocity: the yaw takes -c'e_v (c its :func:`course_gradient`; the
    course errs by c'e_v), and the rest with it by :func:`yaw_error_gain` (pivot: lat, lon, h
    the solution was turned about, as for :func:`rotate_yaw`); ``restarted``
    (:func:`restart_velocity`): the solution's velocity is v_enu, its error e_v itself."""
    run = np.zeros(3) if pivot is None else \
        position_residual_enu(nav.lat, nav.lon, nav.h, *pivot)
    g = yaw_error_gain(nav, space, run)
    if restarted:
        g[space["vel"]] = 0.0
    gain = -np.outer(g, course_gradient(v_enu))
    if restarted:
        gain[space["vel"], :] = np.eye(3)
    return gain


#: 1 sigma of the jerk that moving a solution by up to a second at its last acceleration
#: leaves out, m/s^3: the change of acceleration the course allows over its window.
EXTRAPOLATION_JERK = ACCELERATION_CHANGE / WINDOW_S


def fixes_with_course(space, nav, P, fixes, epochs, gain, a_enu, omega, lever_b):
    """The fixes a course velocity was made of as one position measurement of the solution
    just aligned on that course, their errors' correlation with its errors accounted for.

    The course turned the yaw (and set the velocity, on a restart), so the solution's errors
    now hold the velocity's error e_v = sum of D_i e_i over the fixes' errors: the fixes are no
    longer independent of the state. With C = cov(state error, measurement noise) the update
    is the one of H' = H + C' P^-1 and R' = R - C' P^-1 C, whose noise is independent of the
    state (the noise split into its regression on the state error and a remainder: Bar-Shalom,
    Li and Kirubarajan, Estimation with Applications to Tracking and Navigation, the
    correlated measurement noise; the gain is (P H' + C) S^-1 as the joint estimator's).

    Parameters
    ----------
    space : StateSpace
    nav : NavState
        The aligned solution at nav.t.
    P : (n, n) ndarray
        Its covariance.
    fixes : sequence of (GnssFix, X)
        GnssVelocity.fixes (X the velocity's error covariance with that fix's) not yet in the
        filter.
    epochs : sequence of float
        Their epochs, s: each predicted by moving nav there at a_enu (m/s^2, ENU), whose error
        over the second or so grows as EXTRAPOLATION_JERK |dt|^3 / 6.
    gain : (n, 3) ndarray
        :func:`course_error_gain`.
    omega : (3,) ndarray
        Compensated angular rate, body FLU, rad/s (the antenna's lever-arm velocity).
    lever_b : (3,) array_like
        Antenna relative to the IMU, FLU, m.

    Returns
    -------
    Innovation
        "gnss_pos", three rows per fix.
    """
    zs, Hs, Rs, Cs = [], [], [], []
    for (fix, cross), epoch in zip(fixes, epochs):
        dt = epoch - nav.t
        st = extrapolate(nav, dt, a_enu)
        v_ant = lever_arm_velocity(st.v_enu, st.q_nb, omega, lever_b, st.lat)
        innov = gnss_position(space, st, fix.lat, fix.lon, fix.h, fix.cov_enu, lever_b,
                              dzdt=v_ant, P=P, stamp_sigma=fix.stamp_sigma)
        H = innov.H.copy()
        H[:, space["vel"]] += dt * H[:, space["pos"]]  # the error at nav.t carried to epoch
        zs.append(innov.z)
        Hs.append(H)
        Rs.append(innov.R + np.eye(3) * (EXTRAPOLATION_JERK * abs(dt) ** 3 / 6.0) ** 2)
        # The filter's noise is -e_i (z = predicted - measured), the state error gain @ e_v.
        Cs.append(-np.asarray(gain) @ np.asarray(cross))
    m = 3 * len(zs)
    R = np.zeros((m, m))
    for i, Ri in enumerate(Rs):
        R[3 * i:3 * i + 3, 3 * i:3 * i + 3] = Ri
    C = np.hstack(Cs)
    PC = np.linalg.solve(P, C)
    R = R - C.T @ PC
    return Innovation("gnss_pos", np.concatenate(zs), np.vstack(Hs) + PC.T, 0.5 * (R + R.T))


def yaw_error_from_heading(azimuth, variance, q_nb):
    """Yaw rotation of an INS attitude q_nb onto a heading fix: azimuth of the body x axis
    [rad, clockwise from North] of the given variance [rad²].

    Returns
    -------
    delta, sigma : float [rad]
        Rotation about Up to apply, and the yaw standard deviation after it.
    """
    yaw, sigma = yaw_from_heading(azimuth, np.sqrt(variance))
    return yaw - yaw_of_x(q_nb), sigma


def rotate_yaw(nav, P, space, delta, sigma, sigma_floor, pivot=None, velocity_gain=None,
               run_turn=None):
    """Turn a solution and its covariance by delta about Up (the heading alignment).

    Parameters
    ----------
    nav : NavState
    P : (n, n) ndarray
        Covariance with the yaw out of the filter (:func:`initial_covariance`).
    space : StateSpace
    delta : float
        Rotation, counter-clockwise [rad].
    sigma, sigma_floor : float
        Standard deviation of the error the measured heading (or course) brings into delta,
        and the floor of the yaw standard deviation [rad].
    pivot : tuple of 3 float, optional
        (lat, lon, h) where the solution last met the truth (the antenna of the last fix it
        took): its offset from there (the lever arm, the distance run since) went the wrong way
        too and is turned about that point.
    velocity_gain : (3,) array_like, optional
        For a rotation measured against the INS velocity's direction
        (:func:`yaw_error_from_motion`): the gradient of that direction with respect to the
        velocity error before the turn (ENU, rad/(m/s)). The yaw error after the turn is then
        phi_U = velocity_gain . dv - n (n the measured course's error, of sigma): correlated
        with the velocity error it came from, whose cross-track part it cancels.
    run_turn : float, optional
        The rotation of the offset from the pivot [rad], where it is not delta: a yaw aligned
        on the body x axis while the INS velocity, which the distance run followed, had turned
        off it.

    Returns
    -------
    nav : NavState
    P : (n, n) ndarray
    """
    rz = quat_from_rotvec([0.0, 0.0, delta])
    run = np.zeros(3)  # the distance turned with the yaw, ENU m
    if pivot is not None:
        d = position_residual_enu(nav.lat, nav.lon, nav.h, *pivot)
        run = quat_rotate(rz if run_turn is None else quat_from_rotvec([0.0, 0.0, run_turn]), d)
        nav = apply_correction(nav, d - run, np.zeros(3), np.zeros(3))
    nav = replace(nav, q_nb=quat_normalize(quat_mul(rz, nav.q_nb)),
                  v_enu=quat_rotate(rz, nav.v_enu))
    # The ENU-resolved errors turn with the solution (C' = Rz (I - [phi x]) C =
    # (I - [(Rz phi) x]) Rz C): rotate their covariance, including the correlations of the
    # tilt with the accelerometer biases that levelling built up.
    T = np.eye(space.size)
    R = quat_to_dcm(rz)
    for name in ("pos", "vel", "att"):
        T[space[name], space[name]] = R
    P = T @ P @ T.T
    k = space["att"].stop - 1
    P[k, :] = 0.0
    P[:, k] = 0.0
    # The velocity and the distance run since the rest were turned by the new yaw, so they
    # carry its error (yaw_error_gain). With these correlations the first fixes after the
    # alignment correct the yaw through the distance run, instead of taking the turned
    # distance's error for a position error alone (fixes at 1 Hz after a course of seconds).
    g = yaw_error_gain(nav, space, run)
    # The new errors are x + g phi_U with phi_U = h' x - n, x the errors turned with the
    # solution and h the yaw's dependence on them (zero for a heading fix or the body axis on a
    # course): x' = (I + g h') x - g n. The floor tops up n where the yaw would be below it.
    h = np.zeros(space.size)
    if velocity_gain is not None:
        h[space["vel"]] = R @ np.asarray(velocity_gain, float)
    A = np.eye(space.size) + np.outer(g, h)
    var_n = max(sigma ** 2, sigma_floor ** 2 - h @ P @ h)
    P = A @ P @ A.T + var_n * np.outer(g, g)
    if "bg" in space:
        # While the yaw was unknown the mechanisation removed the horizontal Earth rate in the
        # wrong direction and the filter took the difference for gyro bias: widen the bias
        # uncertainty by that rate (up to Omega cos(lat) on any axis).
        s = space["bg"]
        P[s, s] += (WGS84.omega * np.cos(nav.lat)) ** 2 * np.eye(3)
    return nav, P


def _readings(angles, f_b, w_b):
    """Virtual-platform readings of the three channels (dimensionless), and the up checks.

    roll : y-accelerometer of the roll-rotated axes, pitch : x-accelerometer of the levelled
    axes, yaw : east gyro of the platform.  Each is divided by the magnitude of the signal in
    its plane of rotation (a reading, not a model value) and signed so that
    A = sin(α - α*) exactly, given the other channels' current angles.

    Returns
    -------
    A : (3,) ndarray
    upright : (2,) ndarray
        z-accelerometer of the levelled axes and north gyro: positive at the right solution,
        negative at the 180°-off zero of the same reading.
    """
    roll, pitch, yaw = angles
    cr, sr, cp, sp, cy, sy = (np.cos(roll), np.sin(roll), np.cos(pitch), np.sin(pitch),
                              np.cos(yaw), np.sin(yaw))
    fy_r = cr * f_b[1] - sr * f_b[2]
    fz_r = sr * f_b[1] + cr * f_b[2]
    fx_l = cp * f_b[0] + sp * fz_r
    fz_l = -sp * f_b[0] + cp * fz_r
    w = quat_to_dcm(quat_from_euler(roll, pitch, 0.0)) @ w_b
    w_east = cy * w[0] - sy * w[1]
    w_north = sy * w[0] + cy * w[1]
    A = np.array([-fy_r / np.hypot(f_b[1], f_b[2]), fx_l / np.hypot(f_b[0], fz_r),
                  -w_east / np.hypot(w[0], w[1])])
    return A, np.array([fz_l, w_north])


def steepest_descent_alignment(dthetas, dvs, dt, initial=(0.0, 0.0, 0.0), method="mp",
                               gains=(1.0, 1.0, 1.0), trial_step=np.radians(1.0),
                               gyro_gate=1e-3, tol=1e-9, max_iter=100):
    """Iterative alignment of a virtual platform (seed 002, Naumchenko, eq. 2 and Table 1).

    The platform angles α = (roll, pitch, yaw) are rotated until the channel readings
    A(α) = sin(α - α*) (horizontal accelerometers for levelling, east gyro for
    gyrocompassing; see :func:`_readings`) vanish, all three channels at once:

    * "cp" (classical): α_k = α_{k-1} - h A / (∂A/∂α), the anti-gradient step computed with
      the measurement model and the current angles; h = 1 is Newton's step and |h| - 1 is
      the relative overshoot near the solution (seed 002 Table 3).
    * "mp" (modified): only readings of the current and previous cycle are used, i.e. the
      secant step α_k = α_{k-1} - h A_{k-1} (α_{k-1} - α_{k-2}) / (A_{k-1} - A_{k-2}),
      started by a trial rotation of ``trial_step`` towards smaller |A|.

    Speed regulation (our reading of the paper's ov/dc/dg blocks, whose exact role is not
    stated): a step never exceeds (π/2)|A|, the largest distance to the solution that a
    reading |sin(α - α*)| allows; where the slope is wrong (past the reading's extremum,
    seed 002 §A3.1) the channel steps (π/2)|A| downhill instead; gyrocompassing waits until
    both levelling readings are below ``gyro_gate``.  A solution 180° off (same zero reading)
    is turned round by the sign of the levelled z-accelerometer and of the north gyro (seed
    002 §A4.4).

    Parameters
    ----------
    dthetas, dvs : array_like, shape (N, 3)
        Static increments [rad], [m/s] in body axes.
    dt : float
        Interval [s].
    initial : sequence of 3 float
        Starting roll, pitch, yaw [rad].
    method : {"mp", "cp"}
    gains : sequence of 3 float
        h per channel (roll, pitch, yaw).
    trial_step : float
        First rotation of the "mp" method [rad].
    gyro_gate : float
        The yaw channel moves only once both levelling readings are below this (≈ rad).
    tol : float
        Stop when every |A| < tol (≈ the residual angle in rad).
    max_iter : int

    Returns
    -------
    Alignment
        cov_phi is NaN (use :func:`coarse_alignment_covariance`: the fixed point is the
        closed-form solution); iterations is the number of cycles.
    """
    duration = len(dthetas) * dt
    f_b = np.sum(dvs, axis=0) / duration
    w_b = np.sum(dthetas, axis=0) / duration
    h = np.asarray(gains, float)
    alpha = np.asarray(initial, float).copy()
    A, _ = _readings(alpha, f_b, w_b)
    prev_alpha, prev_A = alpha.copy(), np.full(3, np.nan)
    iterations = 0
    while np.any(np.abs(A) >= tol) and iterations < max_iter:
        active = np.array([True, True, np.all(np.abs(A[:2]) < gyro_gate)])
        downhill = -np.sign(A) * 0.5 * np.pi * np.abs(A)
        if method == "cp":
            eps = 1e-6
            slope = np.array([(_readings(alpha + eps * e, f_b, w_b)[0][i]
                               - _readings(alpha - eps * e, f_b, w_b)[0][i]) / (2 * eps)
                              for i, e in enumerate(np.eye(3))])
            ok = slope > 0.1
            step = np.where(ok, -h * A / np.where(ok, slope, 1.0), downhill)
        elif method == "mp":
            dA = A - prev_A
            da = alpha - prev_alpha
            ok = np.isfinite(dA) & (dA * da > 0.0)
            step = np.where(ok, -h * A * da / np.where(ok, dA, 1.0), downhill)
            # First active cycle of a channel: the trial rotation.
            step = np.where(np.isnan(dA), -np.sign(A) * trial_step, step)
        else:
            raise ValueError(f"unknown method {method!r}")
        limit = 0.5 * np.pi * np.abs(A) * np.maximum(np.abs(h), 1.0)
        step = np.where(active, np.clip(step, -limit, limit), 0.0)
        prev_alpha, prev_A = alpha, np.where(active, A, np.nan)
        alpha = alpha + step
        A, _ = _readings(alpha, f_b, w_b)
        iterations += 1
    _, upright = _readings(alpha, f_b, w_b)
    if upright[0] < 0.0:
        alpha[0] += np.pi
        alpha[1] = -alpha[1]
        alpha[2] += np.pi
        _, upright = _readings(alpha, f_b, w_b)
    if upright[1] < 0.0:
        alpha[2] += np.pi
    alpha = wrap_pi(alpha)
    return Alignment(quat_from_euler(*alpha), np.full((3, 3), np.nan), iterations)
