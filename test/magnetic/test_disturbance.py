"""Magnetic disturbance gating: a steel mass parked next to the compass for 30 s.

The mass is modelled as the dipole induced by the Earth field in soft steel, m = k F / μ0 ... in
practice m = χ_eff V F / μ0; here k F/|F| with k = 150 A·m² (a few hundred kg of steel), and its
field at offset r is μ0/(4π) (3 r̂ (r̂·m) - m) / r³ (Jackson, Classical Electrodynamics, eq. 5.56).
It drives in from 25 m to 2.5 m in 2 s, stays 30 s, and drives away in 2 s, while the unit turns
slowly at 2 deg/s with a 5 deg roll.
"""
import numpy as np
import pytest

from ins_gnss_ros.magnetic.compass import MagneticCompass, level_field
from ins_gnss_ros.magnetic.disturbance import (NOISE_MARGIN, DisturbanceDetector,
                                               total_and_inclination)
from ins_gnss_ros.magnetic.wmm import field_elements
from ins_gnss_ros.nav.conventions import wrap_pi, yaw_from_azimuth
from ins_gnss_ros.nav.rotations import dcm_from_euler

DEG = np.pi / 180
MU0_4PI = 1e-7
FIELD = field_elements(59.94 * DEG, 30.31 * DEG, 10.0, 2026.0)
RATE = 10.0
T_IN, T_OUT = 100.0, 130.0  # the mass is parked from T_IN to T_OUT


def _dipole_field(r_enu, m_enu):
    r = np.linalg.norm(r_enu, axis=-1, keepdims=True)
    u = r_enu / r
    return MU0_4PI * (3 * u * np.sum(u * m_enu, -1, keepdims=True) - m_enu) / r ** 3


def _distance(t):
    """Mass distance, m: 25 m far away, 2.5 m parked, linear 2 s drives in and out."""
    d = np.full_like(t, 25.0)
    d = np.where((t >= T_IN - 2) & (t < T_IN), 25.0 - (t - T_IN + 2) / 2 * 22.5, d)
    d = np.where((t >= T_IN) & (t <= T_OUT), 2.5, d)
    d = np.where((t > T_OUT) & (t <= T_OUT + 2), 2.5 + (t - T_OUT) / 2 * 22.5, d)
    return d


def _scenario(rng):
    t = np.arange(0.0, 240.0, 1 / RATE)
    az = 2 * DEG * t
    roll = np.full_like(t, 5 * DEG)
    pitch = np.zeros_like(t)
    direction = np.array([np.cos(30 * DEG), np.sin(30 * DEG), -0.3])  # to the mass, ENU
    direction /= np.linalg.norm(direction)
    m = 150.0 * FIELD.enu / FIELD.total
    f_enu = FIELD.enu + _dipole_field(_distance(t)[:, None] * direction, m)
    c_nb = dcm_from_euler(roll, pitch, yaw_from_azimuth(az))
    raw = np.einsum("nji,nj->ni", c_nb, f_enu) + rng.normal(0, 50e-9, (len(t), 3))
    tilt = 0.05 * DEG  # INS roll/pitch noise
    return t, raw, roll + rng.normal(0, tilt, t.shape), pitch + rng.normal(0, tilt, t.shape), az


def test_steel_mass_flagged_and_no_heading_published():
    rng = np.random.default_rng(9)
    t, raw, roll, pitch, az = _scenario(rng)
    det = DisturbanceDetector(FIELD.total, FIELD.inclination)
    compass = MagneticCompass(detector=det, field_std=50e-9)  # the scenario's noise
    published = np.zeros(len(t), bool)
    flagged = np.zeros(len(t), bool)
    err = np.full(len(t), np.nan)
    for i in range(len(t)):
        reading, status = compass.update(t[i], raw[i], roll[i], pitch[i], FIELD.declination)
        flagged[i] = status.disturbed
        if reading is not None:
            published[i] = True
            err[i] = wrap_pi(reading.true_azimuth - az[i])
    during = (t >= T_IN) & (t <= T_OUT)
    undisturbed = abs(_distance(t) - 25.0) < 1e-9
    # What the mass does to an unprotected compass.
    bad = np.degrees(np.max(abs(wrap_pi(np.arctan2(*level_field(raw, roll, pitch)[:, 1::-1].T)
                                        + FIELD.declination - az)[during])))
    print(f"\nunprotected heading error during the disturbance up to {bad:.1f} deg; "
          f"flagged {flagged.sum() / RATE:.1f} s; max published error "
          f"{np.degrees(np.nanmax(abs(err))):.2f} deg")
    assert bad > 3.0
    assert not published[during].any()
    assert flagged[during].all()
    # Before and well after, headings flow and are right.
    assert published[t < T_IN - 2].all()
    assert published[t > T_OUT + 10].all()
    assert np.degrees(np.nanmax(abs(err[undisturbed]))) < 1.0


def test_hysteresis_and_running_norm():
    det = DisturbanceDetector(50e-6, 70 * DEG, clear_time=2.0)
    f = 50e-6 * np.array([np.cos(70 * DEG), 0.0, -np.sin(70 * DEG)])
    assert total_and_inclination(f) == pytest.approx((50e-6, 70 * DEG))
    t = 0.0
    for _ in range(50):
        assert not det.update(t, f).disturbed
        t += 0.1
    # +3 % magnitude: inside the model tolerance (8 %), outside the running one (1 %).
    s = det.update(t, 1.03 * f)
    assert s.disturbed and s.reasons == ("running_total",)
    # Back to +0.7 %: below the threshold but above the release level, the flag stays up.
    for _ in range(40):
        t += 0.1
        assert det.update(t, 1.007 * f).disturbed
    # Quiet again: the flag drops only after clear_time.
    states = []
    for _ in range(40):
        t += 0.1
        states.append(det.update(t, f).disturbed)
    assert states[0] and states[15] and not states[-1]
    assert states.index(False) == pytest.approx(20, abs=1)


def _clean_drive(rng, seconds=120.0, rate=50.0, field_std=100e-9, tilt_step=0.6 * DEG):
    """A level field at 50 Hz with 100 nT of noise per axis, levelled with an attitude whose
    pitch error steps by ``tilt_step`` half-way (a filter correcting a MEMS INS's tilt)."""
    t = np.arange(0.0, seconds, 1 / rate)
    pitch_error = np.where(t < seconds / 2, 0.0, tilt_step)
    az = 0.5 * DEG * t
    c_nb = dcm_from_euler(np.zeros_like(t), np.zeros_like(t), yaw_from_azimuth(az))
    raw = np.einsum("nji,nj->ni", c_nb, np.broadcast_to(FIELD.enu, (len(t), 3)))
    raw = raw + rng.normal(0, field_std, raw.shape)
    return t, np.array([level_field(m, 0.0, p) for m, p in zip(raw, pitch_error)])


def test_noise_floor_raises_the_tolerances():
    det = DisturbanceDetector(FIELD.total, FIELD.inclination, field_std=100e-9,
                              tilt_std=0.3 * DEG)
    tol = det.tolerances()
    assert tol["model_total"] == 0.08 and tol["model_inclination"] == pytest.approx(4 * DEG)
    assert tol["running_total"] == pytest.approx(NOISE_MARGIN * 100e-9 / FIELD.total)
    assert tol["running_inclination"] == pytest.approx(
        NOISE_MARGIN * np.hypot(100e-9 / FIELD.total, 0.3 * DEG))
    # The noise they were chosen for leaves the defaults as they are.
    det.set_noise(50e-9, 0.05 * DEG)
    assert det.tolerances() == det.tol


def test_noisy_clean_field_is_not_held_up_and_a_disturbance_still_is():
    """100 nT at 50 Hz with a MEMS INS's tilt (0.3 deg, corrected by 0.6 deg half-way): given
    that noise the detector passes every sample; without it (the tolerances of a 50 nT, 0.05
    deg set-up) it trips on the noise and the correction and then withholds for good. A +5 %
    step of |F| is flagged either way."""
    t, level = _clean_drive(np.random.default_rng(4))
    noisy = DisturbanceDetector(FIELD.total, FIELD.inclination, field_std=100e-9,
                                tilt_std=0.3 * DEG)
    blind = DisturbanceDetector(FIELD.total, FIELD.inclination)
    flagged = {"noisy": [], "blind": []}
    for ti, f in zip(t, level):
        flagged["noisy"].append(noisy.update(ti, f).disturbed)
        flagged["blind"].append(blind.update(ti, f).disturbed)
    assert not any(flagged["noisy"])
    assert np.mean(flagged["blind"][len(t) // 2:]) > 0.9
    s = noisy.update(t[-1] + 0.02, 1.05 * level[-1])
    assert s.disturbed and s.reasons == ("running_total",)
