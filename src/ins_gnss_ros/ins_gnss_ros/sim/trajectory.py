"""Truth trajectories and their exact inertial measurements.

A trajectory is described kinematically (speed, course, attitude as smooth functions of time),
then :func:`generate` integrates the position on the WGS-84 ellipsoid and computes what an ideal
strapdown IMU senses:

    ω_ib^b = ω_nb^b + C_bn (ω_ie^n + ω_en^n)
    f^b    = C_bn (dv^n/dt + (2 ω_ie^n + ω_en^n) × v^n − g^n)

(Groves, "Principles of GNSS, Inertial and Multisensor Integrated Navigation", 2nd ed., eqs.
5.53-5.54 in ENU; Savage, "Strapdown Analytics", §4.1). The IMU increments Δθ = ∫ω_ib^b dt and
Δv = ∫f^b dt over each sensor interval are integrated on an oversampled grid with Simpson's
rule, so coning and sculling are present in them exactly as a real integrating sensor would
deliver them: a strapdown run of the increments reproduces the truth up to the error of the
strapdown algorithm itself.

Frames: navigation ENU, body FLU, q_nb Hamilton scalar-first (see nav/rotations.py).

Motion segments are superpositions of quintic "smooth steps" (zero first and second derivative at
both ends), so speed, yaw rate and attitude are C2 and their integrals have closed forms. That
keeps the angular rate and the acceleration continuous, which a physical vehicle requires and
which makes the quadrature of the increments accurate to rounding.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import NamedTuple, Protocol

import numpy as np
from scipy.integrate import cumulative_trapezoid

from ins_gnss_ros.nav import earth
from ins_gnss_ros.nav.rotations import quat_from_euler, quat_to_dcm
from ins_gnss_ros.nav.track import Track


# ---------------------------------------------------------------------------------------------
# Smooth profiles
# ---------------------------------------------------------------------------------------------
def _smoothstep(x):
    """Quintic smooth step S(x) = 10x³ − 15x⁴ + 6x⁵ on [0, 1], with S' and ∫₀ˣS.

    S(0) = 0, S(1) = 1 and S', S'' vanish at both ends. x must lie in [0, 1].
    """
    x2 = x * x
    s = x * x2 * (10.0 - 15.0 * x + 6.0 * x2)
    ds = 30.0 * x2 * (1.0 - x) ** 2
    integral = x2 * x2 * (2.5 - 3.0 * x + x2)
    return s, ds, integral


#: Peak of S'(x) (at x = 1/2): a step of size Δ over T has a peak rate of 1.875 Δ/T.
SMOOTHSTEP_PEAK_RATE = 1.875


@dataclass
class SmoothSteps:
    """Scalar signal x(t) = x0 + Σ_i Δ_i S((t − t_i)/T_i) made of quintic smooth steps.

    Attributes
    ----------
    x0 : float
        Value before the first step.
    steps : list of (t_start, duration, delta)
    """

    x0: float = 0.0
    steps: list = field(default_factory=list)

    def add(self, t_start: float, duration: float, delta: float) -> None:
        """Append a step of size ``delta`` that starts at ``t_start`` (s) and lasts ``duration``."""
        if duration <= 0.0:
            raise ValueError("step duration must be positive")
        self.steps.append((float(t_start), float(duration), float(delta)))

    def final_value(self) -> float:
        """Value after all steps have completed."""
        return self.x0 + sum(d for _, _, d in self.steps)

    def evaluate(self, t):
        """Integral from t = 0, value and rate at ascending times ``t``.

        Parameters
        ----------
        t : ndarray, shape (n,)
            Ascending times, s (t >= 0).

        Returns
        -------
        integral, value, rate : ndarray, shape (n,)
            ∫₀ᵗ x dt [x·s], x(t) [x], dx/dt [x/s].
        """
        t = np.asarray(t, float)
        integral = np.zeros_like(t)
        value = np.zeros_like(t)
        rate = np.zeros_like(t)
        # After a step has completed it adds delta to the value and delta·(t − t0 − dur/2) to
        # the integral (∫₀¹S = 1/2): collect these as jumps of a constant and of a slope, and
        # sum them once with cumsum instead of touching every later sample per step.
        jump_value = np.zeros(len(t) + 1)
        jump_offset = np.zeros(len(t) + 1)
        for t0, dur, delta in self.steps:
            i0, i1 = np.searchsorted(t, [t0, t0 + dur])
            s, ds, si = _smoothstep((t[i0:i1] - t0) / dur)
            value[i0:i1] += delta * s
            rate[i0:i1] += delta * ds / dur
            integral[i0:i1] += delta * dur * si
            jump_value[i1] += delta
            jump_offset[i1] -= delta * (t0 + 0.5 * dur)
        done = np.cumsum(jump_value)[:-1]
        value += self.x0 + done
        integral += self.x0 * t + done * t + np.cumsum(jump_offset)[:-1]
        return integral, value, rate


class Route:
    """Horizontal path built segment by segment: forward speed and yaw-rate profiles.

    The route clock ``t`` advances with each motion segment. Pitch and bank ramps
    (:meth:`set_pitch`, :meth:`set_bank`) start at the current clock and do not advance it, so
    they overlap the motion segments that follow (a grade while driving straight).

    Parameters
    ----------
    yaw0 : float
        Initial yaw (ENU, counter-clockwise from East), rad.
    speed0 : float
        Initial speed, m/s.
    ramp : float
        Default duration of yaw-rate transitions (turn entry and exit), s.
    pitch0 : float
        Initial pitch (ROS: positive nose down), rad: a route begun on a grade.
    """

    def __init__(self, yaw0: float = 0.0, speed0: float = 0.0, ramp: float = 1.5,
                 pitch0: float = 0.0):
        self.yaw0 = float(yaw0)
        self.speed = SmoothSteps(float(speed0))
        self.yaw_rate = SmoothSteps()
        self.pitch = SmoothSteps(float(pitch0))
        self.bank = SmoothSteps()
        self.ramp = float(ramp)
        self.t = 0.0
        self.max_lateral_accel = 0.0

    @property
    def current_speed(self) -> float:
        """Speed at the end of the route so far, m/s."""
        return self.speed.final_value()

    def hold(self, duration: float) -> "Route":
        """Keep speed and yaw rate for ``duration`` s (straight line, or a stop at zero speed)."""
        self.t += float(duration)
        return self

    def change_speed(self, speed: float, accel: float) -> "Route":
        """Accelerate or brake to ``speed`` (m/s) with peak longitudinal acceleration ``accel``."""
        delta = float(speed) - self.current_speed
        if delta != 0.0:
            dur = SMOOTHSTEP_PEAK_RATE * abs(delta) / float(accel)
            self.speed.add(self.t, dur, delta)
            self.t += dur
        return self

    def stop(self, duration: float, decel: float = 2.0) -> "Route":
        """Brake to a standstill and wait ``duration`` s."""
        return self.change_speed(0.0, decel).hold(duration)

    def _yaw_rate_for(self, radius, lateral_accel):
        v = self.current_speed
        if v <= 0.0:
            raise ValueError("a turn needs forward speed")
        if (radius is None) == (lateral_accel is None):
            raise ValueError("give exactly one of radius and lateral_accel")
        rate = v / radius if radius is not None else lateral_accel / v
        self.max_lateral_accel = max(self.max_lateral_accel, v * rate)
        return rate

    def turn(self, angle: float, radius: float | None = None,
             lateral_accel: float | None = None) -> "Route":
        """Turn by ``angle`` (rad, positive left / counter-clockwise) at constant speed.

        The yaw rate v/radius (or lateral_accel/v) is entered and left with smooth steps of
        ``ramp`` s; each contributes rate·ramp/2 of heading change, the constant-rate part the
        rest. Short turns shorten the ramps so that no constant-rate part is negative.
        """
        rate = self._yaw_rate_for(radius, lateral_accel) * np.sign(angle)
        ramp = min(self.ramp, abs(angle / rate))
        hold = angle / rate - ramp
        self.yaw_rate.add(self.t, ramp, rate)
        self.t += ramp + hold
        self.yaw_rate.add(self.t, ramp, -rate)
        self.t += ramp
        return self

    def circle(self, radius: float | None = None, lateral_accel: float | None = None,
               laps: int = 1, direction: int = 1) -> "Route":
        """Drive ``laps`` full circles, left for ``direction`` = +1, right for −1."""
        return self.turn(direction * 2.0 * np.pi * laps, radius, lateral_accel)

    def figure_eight(self, radius: float | None = None, lateral_accel: float | None = None,
                     laps: int = 1) -> "Route":
        """Drive ``laps`` figure-eights: a left circle then a right circle, reversing the yaw rate
        in one ramp (the two loops touch at the crossing point)."""
        rate = self._yaw_rate_for(radius, lateral_accel)
        ramp = self.ramp
        if 2.0 * np.pi / rate < ramp:
            raise ValueError("yaw-rate ramp longer than one loop at this rate")
        self.yaw_rate.add(self.t, ramp, rate)
        self.t += ramp
        n_loops = 2 * laps
        for i in range(n_loops):
            sign = 1.0 if i % 2 == 0 else -1.0
            # Each loop turns 2π: the entry and exit ramps add rate·ramp/2 each to the first and
            # last loop, the ±rate reversal ramps between loops are antisymmetric and add nothing.
            hold = 2.0 * np.pi / rate - 0.5 * ramp * ((i == 0) + (i == n_loops - 1))
            self.t += hold
            last = i == n_loops - 1
            self.yaw_rate.add(self.t, ramp, -sign * rate * (1.0 if last else 2.0))
            self.t += ramp
        return self

    def set_pitch(self, pitch: float, duration: float) -> "Route":
        """Ramp the pitch (ROS: positive nose down, i.e. downhill) to ``pitch`` rad over
        ``duration`` s, starting now, without advancing the route clock."""
        self.pitch.add(self.t, duration, float(pitch) - self.pitch.final_value())
        return self

    def set_bank(self, bank: float, duration: float) -> "Route":
        """Ramp the bank (road camber / list, positive right side down) to ``bank`` rad."""
        self.bank.add(self.t, duration, float(bank) - self.bank.final_value())
        return self


# ---------------------------------------------------------------------------------------------
# Kinematics of the vehicle
# ---------------------------------------------------------------------------------------------
class Kinematics(NamedTuple):
    """Vehicle motion at a set of times.

    Attributes
    ----------
    v_enu, a_enu : ndarray, shape (n, 3)
        Velocity (m/s) and its time derivative (m/s²) relative to the Earth, in ENU.
    rpy, rpy_rate : ndarray, shape (n, 3)
        ROS Euler angles roll, pitch, yaw of q_nb (rad) and their time derivatives (rad/s).
    """

    v_enu: np.ndarray
    a_enu: np.ndarray
    rpy: np.ndarray
    rpy_rate: np.ndarray


class MotionModel(Protocol):
    """Anything that gives :class:`Kinematics` at ascending times."""

    def evaluate(self, t: np.ndarray) -> Kinematics: ...


def _route_channels(route: Route, t):
    """Speed and yaw of a route at times t: (s, ds/dt, yaw, yaw rate, yaw acceleration)."""
    _, s, s_dot = route.speed.evaluate(t)
    yaw_int, yaw_rate, yaw_acc = route.yaw_rate.evaluate(t)
    return s, s_dot, route.yaw0 + yaw_int, yaw_rate, yaw_acc


@dataclass
class CarMotion:
    """Land vehicle without slip: the velocity lies along the body x (forward) axis.

    The attitude follows the road (pitch = grade, bank = camber) plus a body roll of
    ``roll_gain`` rad per m/s² of centripetal acceleration (suspension roll, outward: a left turn
    rolls the car right-side down, i.e. positive ROS roll).

    Attributes
    ----------
    route : Route
    roll_gain : float
        Suspension roll gradient, rad/(m/s²); 0.006 ≈ 3.4 °/g, a typical passenger car.
    """

    route: Route
    roll_gain: float = 0.006

    def evaluate(self, t) -> Kinematics:
        s, s_dot, yaw, r, r_dot = _route_channels(self.route, t)
        _, pitch, pitch_rate = self.route.pitch.evaluate(t)
        _, bank, bank_rate = self.route.bank.evaluate(t)
        roll = bank + self.roll_gain * s * r
        roll_rate = bank_rate + self.roll_gain * (s_dot * r + s * r_dot)
        cp, sp, cy, sy = np.cos(pitch), np.sin(pitch), np.cos(yaw), np.sin(yaw)
        # Body x axis in ENU for C_nb = Rz(yaw) Ry(pitch) Rx(roll): [cp cy, cp sy, -sp].
        u = np.stack([cp * cy, cp * sy, -sp], -1)
        du = np.stack([-sp * pitch_rate * cy - cp * sy * r,
                       -sp * pitch_rate * sy + cp * cy * r,
                       -cp * pitch_rate], -1)
        v = s[:, None] * u
        a = s_dot[:, None] * u + s[:, None] * du
        return Kinematics(v, a, np.stack([roll, pitch, yaw], -1),
                          np.stack([roll_rate, pitch_rate, r], -1))


@dataclass
class ShipMotion:
    """Vessel: the route gives the mean course and speed through the ground; waves add roll,
    pitch, yaw oscillations and heave (see :mod:`ins_gnss_ros.sim.waves`).

    The horizontal velocity follows the mean course, so the heading oscillation about it shows as
    a small sway velocity in the body frame, as on a real ship.

    Attributes
    ----------
    route : Route
    waves : object with ``evaluate(t) -> (values, rates, accels)``, each (n, 4) ordered
        roll, pitch, yaw, heave (rad, rad, rad, m), or None for calm water.
    """

    route: Route
    waves: object = None

    def evaluate(self, t) -> Kinematics:
        s, s_dot, course, r, _ = _route_channels(self.route, t)
        _, pitch, pitch_rate = self.route.pitch.evaluate(t)
        _, bank, bank_rate = self.route.bank.evaluate(t)
        n = len(t)
        w, w_rate, w_acc = (self.waves.evaluate(t) if self.waves is not None
                            else (np.zeros((n, 4)),) * 3)
        cc, sc = np.cos(course), np.sin(course)
        v = np.stack([s * cc, s * sc, w_rate[:, 3]], -1)
        a = np.stack([s_dot * cc - s * sc * r, s_dot * sc + s * cc * r, w_acc[:, 3]], -1)
        rpy = np.stack([bank + w[:, 0], pitch + w[:, 1], course + w[:, 2]], -1)
        rpy_rate = np.stack([bank_rate + w_rate[:, 0], pitch_rate + w_rate[:, 1],
                             r + w_rate[:, 2]], -1)
        return Kinematics(v, a, rpy, rpy_rate)


# ---------------------------------------------------------------------------------------------
# Truth record and IMU generation
# ---------------------------------------------------------------------------------------------
@dataclass
class Trajectory(Track):
    """Truth record at the IMU rate with ideal IMU outputs.

    Sample k is at time t[k]; increment k covers [t[k], t[k+1]].

    Attributes
    ----------
    t : ndarray, shape (n+1,)
        Time, s.
    lat, lon, h : ndarray, shape (n+1,)
        Geodetic latitude, longitude (rad) and ellipsoidal height (m), WGS-84.
    v_enu : ndarray, shape (n+1, 3)
        Velocity relative to the Earth in ENU, m/s.
    q_nb : ndarray, shape (n+1, 4)
        Attitude, Hamilton scalar-first, body FLU to ENU.
    omega_ib_b : ndarray, shape (n+1, 3)
        Angular rate of the body w.r.t. inertial space in body axes, rad/s.
    f_b : ndarray, shape (n+1, 3)
        Specific force in body axes, m/s².
    dtheta, dv : ndarray, shape (n, 3)
        Ideal angle (rad) and velocity (m/s) increments ∫ω_ib^b dt, ∫f^b dt per interval.
    rpy : ndarray, shape (n+1, 3)
        ROS roll, pitch, yaw of q_nb, rad (continuous, yaw not wrapped).
    """

    omega_ib_b: np.ndarray
    f_b: np.ndarray
    dtheta: np.ndarray
    dv: np.ndarray
    rpy: np.ndarray

    @property
    def dt(self) -> float:
        """IMU sample interval, s."""
        return float(self.t[1] - self.t[0])

    def __len__(self) -> int:
        return len(self.t)

    def decimation(self, rate: float) -> int:
        """Samples of the record per sample of a sensor at ``rate`` Hz.

        Raises
        ------
        ValueError
            If ``rate`` does not divide the record's rate.
        """
        dt = self.dt
        factor = int(round(1.0 / (dt * rate)))
        if factor < 1 or abs(factor * dt * rate - 1.0) > 1e-9:
            raise ValueError(f"{rate:g} Hz does not divide the trajectory rate {1.0 / dt:g} Hz")
        return factor


def euler_rates_to_body_rate(rpy, rpy_rate):
    """Angular rate ω_nb^b (rad/s, body axes) from ROS Euler angles and their rates.

    For C_nb = Rz(ψ) Ry(θ) Rx(φ): ω_nb^b = [φ̇, 0, 0] + Rx(φ)ᵀ[0, θ̇, 0] + Rx(φ)ᵀRy(θ)ᵀ[0, 0, ψ̇]
    (Titterton & Weston, "Strapdown Inertial Navigation Technology", eq. 3.47, in the ZYX order).

    Parameters
    ----------
    rpy, rpy_rate : ndarray, shape (n, 3)

    Returns
    -------
    ndarray, shape (n, 3)
    """
    roll, pitch = rpy[:, 0], rpy[:, 1]
    dr, dp, dy = rpy_rate[:, 0], rpy_rate[:, 1], rpy_rate[:, 2]
    cr, sr, cp, sp = np.cos(roll), np.sin(roll), np.cos(pitch), np.sin(pitch)
    return np.stack([dr - dy * sp, dp * cr + dy * cp * sr, -dp * sr + dy * cp * cr], -1)


def integrate_position(t, v_enu, lat0, lon0, h0):
    """Geodetic position from ENU velocity: lat' = v_N/(R_M+h), lon' = v_E/((R_N+h) cos lat),
    h' = v_U (Groves eq. 5.56).

    The radii depend on the latitude being integrated; two passes of the cumulative trapezoid
    rule (radii at the start latitude, then at the first-pass latitude) converge because R_M
    changes by ~1e-3 relative per radian. On a 1 kHz grid the quadrature error is below 1e-5 m.

    Returns
    -------
    lat, lon, h : ndarray, shape (n,)
    """
    h = h0 + cumulative_trapezoid(v_enu[:, 2], t, initial=0.0)
    lat = np.full_like(t, lat0)
    for _ in range(2):
        rm, rn = earth.radii(lat)
        lat_new = lat0 + cumulative_trapezoid(v_enu[:, 1] / (rm + h), t, initial=0.0)
        lon = lon0 + cumulative_trapezoid(v_enu[:, 0] / ((rn + h) * np.cos(lat)), t, initial=0.0)
        lat = lat_new
    return lat, lon, h


def _simpson_increments(y, m, h):
    """Integrals of y over consecutive blocks of m fine steps (m even) by Simpson's rule.

    y : (n·m + 1, 3) samples on a uniform grid of step h -> (n, 3).
    """
    n = (len(y) - 1) // m
    w = np.ones(m + 1)
    w[1:-1:2], w[2:-1:2] = 4.0, 2.0
    out = np.zeros((n, y.shape[1]))
    for j in range(m + 1):
        out += w[j] * y[j:j + n * m:m]
    return out * (h / 3.0)


def generate(motion: MotionModel, lat0: float, lon0: float, h0: float, duration: float,
             rate: float = 200.0, oversample: int = 4) -> Trajectory:
    """Truth trajectory and ideal IMU outputs at ``rate`` Hz from a motion description.

    Parameters
    ----------
    motion : MotionModel
        :class:`CarMotion`, :class:`ShipMotion` or any object with ``evaluate(t)``.
    lat0, lon0, h0 : float
        Start position: geodetic latitude, longitude (rad), ellipsoidal height (m).
    duration : float
        Length, s (rounded to whole IMU intervals).
    rate : float
        IMU sample rate, Hz (e.g. 200, or 1200 as in seed 004 ISON-1).
    oversample : int
        Even number of fine steps per IMU interval for the Simpson quadrature of the
        increments and the position integration.

    Returns
    -------
    Trajectory
    """
    if oversample < 2 or oversample % 2:
        raise ValueError("oversample must be an even number >= 2")
    n = int(round(duration * rate))
    h_fine = 1.0 / (rate * oversample)
    t = np.arange(n * oversample + 1) * h_fine
    kin = motion.evaluate(t)
    lat, lon, h = integrate_position(t, kin.v_enu, lat0, lon0, h0)

    q_nb = quat_from_euler(kin.rpy[:, 0], kin.rpy[:, 1], kin.rpy[:, 2])
    c_nb = quat_to_dcm(q_nb)
    w_ie = earth.earth_rate_enu(lat)
    w_en = earth.transport_rate_enu(lat, h, kin.v_enu)
    # nav.earth.gravity_enu takes one epoch; this is the same vector for all samples at once.
    g = np.zeros_like(kin.v_enu)
    g[:, 2] = -earth.normal_gravity(lat, h)

    w_nb_b = euler_rates_to_body_rate(kin.rpy, kin.rpy_rate)
    w_ib_b = w_nb_b + np.einsum("kji,kj->ki", c_nb, w_ie + w_en)
    f_n = kin.a_enu + np.cross(2.0 * w_ie + w_en, kin.v_enu) - g
    f_b = np.einsum("kji,kj->ki", c_nb, f_n)

    dtheta = _simpson_increments(w_ib_b, oversample, h_fine)
    dv = _simpson_increments(f_b, oversample, h_fine)
    s = slice(None, None, oversample)
    return Trajectory(t=t[s], lat=lat[s], lon=lon[s], h=h[s], v_enu=kin.v_enu[s],
                      q_nb=q_nb[s], omega_ib_b=w_ib_b[s], f_b=f_b[s], dtheta=dtheta, dv=dv,
                      rpy=kin.rpy[s])
