"""Hard/soft-iron ellipsoid calibration on a simulated seed-004 Lab-3 turntable recording.

Truth: WMM2025 field at St Petersburg (seed 004's ITMO/Elektropribor), hard iron 20 % of the
field, symmetric soft iron with principal gains 1.10/0.93/1.04 (10 %), 50 nT white noise per
axis, INS roll/pitch with 0.05 deg noise (ISON-2 spec, seed 004 §1.3c). The recording is the Lab-3
sequence (three slow revolutions, 10-60 deg steps, 10 deg tilt) plus one revolution at each of
±30 deg roll and pitch on a rotary-tilt table (for the 3-D fit). Run with -s to see the numbers.

This is the second case of issue 7. The done-when case itself, on the seed's recording alone
(where the ellipsoid fit does not even find an ellipsoid), is asserted with the known-attitude
calibration in test_attitude_calibration.py.
"""
import numpy as np
import pytest

from ins_gnss_ros.magnetic.compass import magnetic_azimuth
from ins_gnss_ros.magnetic.ellipsoid_fit import HardSoftIron, calibrate, fit_ellipsoid
from ins_gnss_ros.magnetic.turntable_kf import lab3_profile
from ins_gnss_ros.magnetic.wmm import field_elements
from ins_gnss_ros.nav.conventions import wrap_pi, yaw_from_azimuth
from ins_gnss_ros.nav.rotations import dcm_from_euler

DEG = np.pi / 180
FIELD = field_elements(59.94 * DEG, 30.31 * DEG, 10.0, 2026.0)
TILTS_30 = [(30 * DEG, 0), (-30 * DEG, 0), (0, 30 * DEG), (0, -30 * DEG)]


def _iron(rng):
    q, _ = np.linalg.qr(rng.normal(size=(3, 3)))
    soft = q @ np.diag([1.10, 0.93, 1.04]) @ q.T
    hard = rng.normal(size=3)
    hard *= 0.2 * FIELD.total / np.linalg.norm(hard)
    return HardSoftIron(offset=hard, matrix=np.linalg.inv(soft))  # truth as its own correction


def _measure(rng, truth, roll, pitch, azimuth, noise=50e-9, tilt_noise=0.05 * DEG):
    """Raw readings and the INS roll/pitch seen by the compass."""
    c_nb = dcm_from_euler(roll, pitch, yaw_from_azimuth(azimuth))
    f_b = np.einsum("nji,j->ni", c_nb, FIELD.enu)
    raw = truth.distort(f_b) + rng.normal(0, noise, f_b.shape)
    return raw, roll + rng.normal(0, tilt_noise, roll.shape), pitch + rng.normal(0, tilt_noise, roll.shape)


def _rms_deg(az, truth_az):
    return float(np.degrees(np.sqrt(np.mean(wrap_pi(az - truth_az) ** 2))))


def test_fit_ellipsoid_exact_points():
    rng = np.random.default_rng(0)
    u = rng.normal(size=(200, 3))
    u /= np.linalg.norm(u, axis=1)[:, None]
    a = np.array([[2.0, 0.3, 0.0], [0.3, 1.0, 0.1], [0.0, 0.1, 0.5]])
    c = np.array([1.0, -2.0, 0.5])
    center, p = fit_ellipsoid(u @ a.T + c)
    np.testing.assert_allclose(center, c, atol=1e-9)
    np.testing.assert_allclose(p, np.linalg.inv(a @ a.T), atol=1e-9)
    with pytest.raises(ValueError, match="ellipsoid"):
        fit_ellipsoid(np.column_stack([u[:, :2], np.zeros(200)]))  # one plane only


def test_lab3_recording_calibration_heading_accuracy():
    rng = np.random.default_rng(42)
    truth = _iron(rng)
    t, roll, pitch, az = lab3_profile(rate_hz=5.0, calibration_tilts=TILTS_30)
    raw, roll_m, pitch_m = _measure(rng, truth, roll, pitch, az)
    cal = calibrate(raw, FIELD.total, roll_m, pitch_m)

    # Recovered parameters: hard iron within 0.5 % of the field.
    assert np.linalg.norm(cal.offset - truth.offset) < 0.005 * FIELD.total

    # Heading on the Lab-3 recording itself (levels, steps, 10 deg tilt) ...
    lab_raw = _rms_deg(magnetic_azimuth(raw, roll_m, pitch_m), az - FIELD.declination)
    lab_cal = _rms_deg(magnetic_azimuth(cal.apply(raw), roll_m, pitch_m), az - FIELD.declination)
    # ... and on fresh random attitudes with tilts up to 30 deg.
    n = 3000
    roll2, pitch2 = rng.uniform(-30, 30, n) * DEG, rng.uniform(-30, 30, n) * DEG
    az2 = rng.uniform(0, 2 * np.pi, n)
    raw2, roll2_m, pitch2_m = _measure(rng, truth, roll2, pitch2, az2)
    tilt_raw = _rms_deg(magnetic_azimuth(raw2, roll2_m, pitch2_m), az2 - FIELD.declination)
    tilt_cal = _rms_deg(magnetic_azimuth(cal.apply(raw2), roll2_m, pitch2_m), az2 - FIELD.declination)
    print(f"\nheading RMS, deg: Lab-3 recording uncalibrated {lab_raw:.2f} calibrated {lab_cal:.3f}; "
          f"random tilts <=30 deg uncalibrated {tilt_raw:.2f} calibrated {tilt_cal:.3f}; "
          f"hard-iron error {np.linalg.norm(cal.offset - truth.offset) * 1e9:.0f} nT")
    assert lab_cal <= 0.5 and tilt_cal <= 0.5
    assert lab_raw > 5 and tilt_raw > 5


def test_seed_tilts_only_and_no_attitudes():
    """Findings reported in docs/results: with the seed's 10 deg tilts only the z axis is weakly
    determined; without attitudes a full-sphere recording is needed."""
    rng = np.random.default_rng(7)
    truth = _iron(rng)
    t, roll, pitch, az = lab3_profile(rate_hz=5.0, calibration_tilts=[(10 * DEG, 0), (-10 * DEG, 0),
                                                                      (0, 10 * DEG), (0, -10 * DEG)])
    raw, roll_m, pitch_m = _measure(rng, truth, roll, pitch, az)
    cal10 = calibrate(raw, FIELD.total, roll_m, pitch_m)
    err10 = np.linalg.norm(cal10.offset - truth.offset)
    rms10 = {}
    for max_tilt in (10, 30):
        n = 2000
        r2, p2 = rng.uniform(-max_tilt, max_tilt, (2, n)) * DEG
        a2 = rng.uniform(0, 2 * np.pi, n)
        raw2, r2m, p2m = _measure(rng, truth, r2, p2, a2)
        rms10[max_tilt] = _rms_deg(magnetic_azimuth(cal10.apply(raw2), r2m, p2m), a2 - FIELD.declination)
    # Free rotation (full sphere of attitudes), magnitude-only fit.
    n = 4000
    rpy = np.column_stack([rng.uniform(-np.pi, np.pi, n), rng.uniform(-1.5, 1.5, n), rng.uniform(0, 2 * np.pi, n)])
    raw_s, _, _ = _measure(rng, truth, rpy[:, 0], rpy[:, 1], rpy[:, 2])
    cal_s = calibrate(raw_s, FIELD.total)
    print(f"\nseed 10 deg tilts only: hard-iron error {err10 * 1e9:.0f} nT, heading RMS "
          f"{rms10[10]:.2f} deg at tilts <=10 deg, {rms10[30]:.2f} deg at tilts <=30 deg; "
          f"full sphere without attitudes {np.linalg.norm(cal_s.offset - truth.offset) * 1e9:.0f} nT")
    assert err10 < 0.05 * FIELD.total
    assert np.linalg.norm(cal_s.offset - truth.offset) < 0.002 * FIELD.total
    np.testing.assert_allclose(cal_s.matrix, truth.matrix, atol=3e-3)


def test_dict_round_trip_and_validation():
    cal = HardSoftIron(offset=[1e-6, 2e-6, 3e-6], matrix=np.diag([1.1, 0.9, 1.0]))
    back = HardSoftIron.from_dict(cal.to_dict())
    np.testing.assert_array_equal(back.apply([1, 2, 3]), cal.apply([1, 2, 3]))
    with pytest.raises(ValueError, match="offset"):
        HardSoftIron.from_dict({"hard_iron": [0, 0]})
    with pytest.raises(ValueError, match="matrix"):
        HardSoftIron.from_dict({"soft_iron": [[0, 0, 0]] * 3})
