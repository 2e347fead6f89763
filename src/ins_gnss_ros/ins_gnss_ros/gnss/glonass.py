"""GLONASS broadcast ephemeris: numerical integration of the PZ-90 state vector.

GLONASS satellites broadcast position, velocity and luni-solar acceleration at an epoch
tb every 30 minutes.  The user propagates them with the equations of motion of GLONASS
ICD ed. 5.1 Appendix A.3.1.2: central field with the J2 zonal term, centrifugal and
Coriolis terms of the rotating PZ-90 frame, plus the broadcast (constant) luni-solar
acceleration, integrated with 4th-order Runge-Kutta.

Frame: PZ-90.11 differs from WGS-84 (G1762) by millimetres to a few centimetres
(transformation parameters of the ICD, Table A.3): treated as identical here, which is
far below single-point accuracy.
"""
import math
from dataclasses import dataclass

import numpy as np

from .constants import A_E_GLO, GM_GLO, J2_GLO, OMEGA_E_GLO

#: Largest Runge-Kutta step [s]; the ICD recommends integrating within +-15 min of tb,
#: where 30 s steps keep the integration error at millimetres.
RK_STEP = 30.0


@dataclass(frozen=True)
class GlonassEphemeris:
    """GLONASS immediate navigation data of one satellite (strings 1-4).

    Attributes
    ----------
    prn : int
        Orbital slot number.
    freq_slot : int
        FDMA frequency number k.
    toe : float
        Epoch tb of the state vector [GPS s].
    pos, vel, acc : tuple of float
        PZ-90 position [m], velocity [m/s], luni-solar acceleration [m/s^2] at tb.
    tau_n : float
        Satellite clock offset from GLONASS time, tau_n(tb) [s] (t_sys = t_sv + tau_n).
    gamma_n : float
        Relative frequency offset gamma_n(tb).
    health : int
        MSB of B_n (1 = unhealthy).
    age_days : int
        Age of the data E_n [days].
    """

    prn: int
    freq_slot: int
    toe: float
    pos: tuple
    vel: tuple
    acc: tuple
    tau_n: float
    gamma_n: float
    health: int
    age_days: int

    @property
    def sat_id(self):
        """RINEX satellite identifier, e.g. "R05"."""
        return f"R{self.prn:02d}"


def glonass_derivatives(state, acc):
    """Time derivative of the PZ-90 state [x, y, z, vx, vy, vz] (ICD ed. 5.1 A.3.1.2).

    Parameters
    ----------
    state : numpy.ndarray, shape (6,)
        Position [m] and velocity [m/s] in the rotating PZ-90 frame.
    acc : numpy.ndarray, shape (3,)
        Luni-solar acceleration [m/s^2], held constant over the interval.
    """
    x, y, z, vx, vy, vz = state
    r2 = x * x + y * y + z * z
    r = math.sqrt(r2)
    mu_r3 = GM_GLO / (r2 * r)
    j2_term = 1.5 * J2_GLO * GM_GLO * A_E_GLO ** 2 / (r2 * r2 * r)
    z2_r2 = z * z / r2
    w2 = OMEGA_E_GLO ** 2
    return np.array([
        vx, vy, vz,
        -mu_r3 * x - j2_term * x * (1.0 - 5.0 * z2_r2) + w2 * x + 2.0 * OMEGA_E_GLO * vy + acc[0],
        -mu_r3 * y - j2_term * y * (1.0 - 5.0 * z2_r2) + w2 * y - 2.0 * OMEGA_E_GLO * vx + acc[1],
        -mu_r3 * z - j2_term * z * (3.0 - 5.0 * z2_r2) + acc[2]])


def glonass_sat_position(eph, t):
    """Satellite position, clock, velocity and clock drift at GPS time `t`.

    Parameters
    ----------
    eph : GlonassEphemeris
    t : float
        Time of transmission [GPS s]; valid within about 15 min of `eph.toe`.

    Returns
    -------
    xyz : numpy.ndarray, shape (3,)  ECEF position [m]
    clock_bias : float  satellite clock minus system time [s] (-tau_n + gamma_n (t - tb))
    vel : numpy.ndarray, shape (3,)  ECEF velocity [m/s]
    clock_drift : float  [s/s]
    """
    state = np.concatenate([eph.pos, eph.vel]).astype(float)
    acc = np.asarray(eph.acc, dtype=float)
    span = t - eph.toe
    steps = max(1, int(math.ceil(abs(span) / RK_STEP)))
    h = span / steps
    for _ in range(steps):
        k1 = glonass_derivatives(state, acc)
        k2 = glonass_derivatives(state + 0.5 * h * k1, acc)
        k3 = glonass_derivatives(state + 0.5 * h * k2, acc)
        k4 = glonass_derivatives(state + h * k3, acc)
        state = state + h / 6.0 * (k1 + 2.0 * k2 + 2.0 * k3 + k4)
    clock_bias = -eph.tau_n + eph.gamma_n * span
    return state[:3], clock_bias, state[3:], eph.gamma_n
