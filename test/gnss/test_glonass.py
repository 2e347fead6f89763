"""GLONASS state-vector propagation against an independent inertial-frame integration.

The library integrates the ICD equations in the rotating PZ-90 frame with fixed-step RK4.
The reference here integrates Newton's law in an inertial frame (the PZ-90 axes frozen at
tb), where there are no Coriolis or centrifugal terms, with scipy's adaptive DOP853 at
tight tolerances, and converts back to the rotating frame at the end.  The broadcast
luni-solar acceleration, constant in the rotating frame per the ICD, turns with the frame.
"""
import math

import numpy as np
import pytest
from scipy.integrate import solve_ivp

from ins_gnss_ros.gnss.glonass import GlonassEphemeris, glonass_sat_position

MU = 398600.4418e9      # PZ-90 (GLONASS ICD ed. 5.1)
AE = 6378136.0
J2 = 1082625.75e-9
WE = 7.292115e-5


def _rz(angle):
    """Active rotation about z."""
    c, s = math.cos(angle), math.sin(angle)
    return np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]])


def _inertial_reference(eph, dt):
    r0 = np.array(eph.pos, float)
    v0 = np.array(eph.vel, float) + np.cross([0, 0, WE], r0)
    acc_rot = np.array(eph.acc, float)

    def rhs(t, y):
        r, v = y[:3], y[3:]
        rn = np.linalg.norm(r)
        zr2 = (r[2] / rn) ** 2
        j2 = -1.5 * J2 * MU * AE ** 2 / rn ** 5 * r * np.array([1 - 5 * zr2, 1 - 5 * zr2, 3 - 5 * zr2])
        return np.concatenate([v, -MU * r / rn ** 3 + j2 + _rz(WE * t) @ acc_rot])

    sol = solve_ivp(rhs, (0.0, dt), np.concatenate([r0, v0]), method="DOP853",
                    rtol=1e-13, atol=1e-7)
    r_i, v_i = sol.y[:3, -1], sol.y[3:, -1]
    back = _rz(-WE * dt)
    r_e = back @ r_i
    return r_e, back @ v_i - np.cross([0, 0, WE], r_e)


# A realistic GLONASS state (orbit radius 25,510 km, inclination 64.8 deg).
EPH = GlonassEphemeris(prn=1, freq_slot=1, toe=1.44e9,
                       pos=(-14060951.2, -21402236.3, 3537587.9),
                       vel=(-229.3, -374.6, -3508.2),
                       acc=(1.86e-6, 9.3e-7, -2.79e-6), tau_n=2.0e-5, gamma_n=1.8e-12,
                       health=0, age_days=0)


@pytest.mark.parametrize("dt", [-900.0, -300.0, 450.0, 900.0])
def test_rk4_matches_inertial_integration(dt):
    xyz, clock, vel, drift = glonass_sat_position(EPH, EPH.toe + dt)
    ref_r, ref_v = _inertial_reference(EPH, dt)
    assert np.linalg.norm(xyz - ref_r) < 0.01
    assert np.linalg.norm(vel - ref_v) < 1e-4
    # GLONASS ICD: t_sys = t_sv + tau_n - gamma_n (t - tb); clock = sv - sys.
    assert clock == pytest.approx(-2.0e-5 + 1.8e-12 * dt, abs=1e-18)
    assert drift == 1.8e-12


def test_state_at_tb_is_broadcast_state():
    xyz, _, vel, _ = glonass_sat_position(EPH, EPH.toe)
    assert np.allclose(xyz, EPH.pos) and np.allclose(vel, EPH.vel)
