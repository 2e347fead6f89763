"""mag_calibrate_cli end to end on a simulated Lab-3 recording with tilted revolutions."""
import numpy as np
import pytest
import yaml

from ins_gnss_ros.magnetic.compass import MagneticCompass
from ins_gnss_ros.magnetic.ellipsoid_fit import HardSoftIron
from ins_gnss_ros.magnetic.turntable_kf import lab3_profile
from ins_gnss_ros.magnetic.wmm import field_elements
from ins_gnss_ros.nav.conventions import wrap_pi, yaw_from_azimuth
from ins_gnss_ros.nav.rotations import dcm_from_euler
from ins_gnss_ros.tools.mag_calibrate_cli import main

DEG = np.pi / 180
FIELD = field_elements(59.94 * DEG, 30.31 * DEG, 10.0, 2026.0)
ARGS = ["--lat-deg", "59.94", "--lon-deg", "30.31", "--height", "10", "--year", "2026.0"]


def test_cli_turntable_mode(tmp_path):
    rng = np.random.default_rng(17)
    t, roll, pitch, az = lab3_profile(rate_hz=2.0, pause=60.0,
                                      calibration_tilts=[(30 * DEG, 0), (-30 * DEG, 0),
                                                         (0, 30 * DEG), (0, -30 * DEG)])
    truth = HardSoftIron(offset=[8e-6, -5e-6, 4e-6],
                         matrix=np.linalg.inv([[1.08, 0.03, 0.0], [0.03, 0.95, 0.02], [0.0, 0.02, 1.02]]))
    heading_bias = 1.0 * DEG  # yaw misalignment of the triad
    c_nb = dcm_from_euler(roll, pitch, yaw_from_azimuth(az + heading_bias))
    raw = truth.distort(np.einsum("nji,j->ni", c_nb, FIELD.enu)) + rng.normal(0, 50e-9, (len(t), 3))
    csv = tmp_path / "lab3.csv"
    np.savetxt(csv, np.column_stack([t, raw * 1e6, roll, pitch, az]), delimiter=",",
               header="t,mx,my,mz,roll,pitch,azimuth", comments="")
    out = tmp_path / "mag.yaml"
    assert main([str(csv), "--unit", "uT", "--attitude", "--turntable", "--out", str(out)] + ARGS) == 0
    d = yaml.safe_load(out.read_text())["mag_calibration"]
    cal = HardSoftIron.from_dict(d)
    assert np.linalg.norm(cal.offset - truth.offset) < 0.005 * FIELD.total
    compass = MagneticCompass(calibration=cal, heading_bias=d["heading_bias"])
    err = [wrap_pi(compass.update(0.0, m, r, p, FIELD.declination)[0].true_azimuth - a)
           for m, r, p, a in zip(raw[::5], roll[::5], pitch[::5], az[::5])]
    assert np.degrees(np.sqrt(np.mean(np.square(err)))) < 0.5


def test_cli_needs_field(tmp_path):
    csv = tmp_path / "m.csv"
    csv.write_text("mx,my,mz\n1,2,3\n")
    with pytest.raises(SystemExit, match="WMM"):
        main([str(csv)])


def test_cli_reference_heading_mode_on_seed_recording(tmp_path):
    """Known-attitude fit on the seed's Lab-3 recording alone (no tilted revolutions), with a
    1 deg zero offset of the reference heading column."""
    rng = np.random.default_rng(23)
    t, roll, pitch, az = lab3_profile(rate_hz=2.0, pause=60.0)
    truth = HardSoftIron(offset=[8e-6, -5e-6, 4e-6],
                         matrix=np.linalg.inv([[1.08, 0.03, 0.0], [0.03, 0.95, 0.02], [0.0, 0.02, 1.02]]))
    zero_offset = 1.0 * DEG
    c_nb = dcm_from_euler(roll, pitch, yaw_from_azimuth(az + zero_offset))
    raw = truth.distort(np.einsum("nji,j->ni", c_nb, FIELD.enu)) + rng.normal(0, 50e-9, (len(t), 3))
    roll_m = roll + rng.normal(0, 0.05 * DEG, len(t))
    pitch_m = pitch + rng.normal(0, 0.05 * DEG, len(t))
    csv = tmp_path / "lab3.csv"
    np.savetxt(csv, np.column_stack([t, raw * 1e9, roll_m, pitch_m, az]), delimiter=",",
               header="t,mx,my,mz,roll,pitch,ison_heading", comments="")
    out = tmp_path / "mag.yaml"
    assert main([str(csv), "--unit", "nT", "--reference-heading", "ison_heading",
                 "--out", str(out)] + ARGS) == 0
    d = yaml.safe_load(out.read_text())["mag_calibration"]
    cal = HardSoftIron.from_dict(d)
    # Only 60 s of tilt at 2 Hz here: the vertical offset has σ ≈ 200 nT (printed by the CLI).
    assert np.linalg.norm(cal.offset - truth.offset) < 0.01 * FIELD.total
    assert d["heading_bias"] == pytest.approx(zero_offset, abs=0.05 * DEG)
    # Random attitudes with tilts up to 30 deg: the compass reads the reference heading.
    n = 500
    r2, p2 = rng.uniform(-30, 30, (2, n)) * DEG
    a2 = rng.uniform(0, 2 * np.pi, n)
    c_nb2 = dcm_from_euler(r2, p2, yaw_from_azimuth(a2 + zero_offset))
    raw2 = truth.distort(np.einsum("nji,j->ni", c_nb2, FIELD.enu))
    compass = MagneticCompass(calibration=cal, heading_bias=d["heading_bias"])
    err = [wrap_pi(compass.update(0.0, m, r, p, FIELD.declination)[0].true_azimuth - a)
           for m, r, p, a in zip(raw2, r2, p2, a2)]
    assert np.degrees(np.sqrt(np.mean(np.square(err)))) < 0.5
    with pytest.raises(SystemExit):  # the two turntable modes exclude each other
        main([str(csv), "--turntable", "--reference-heading", "ison_heading"] + ARGS)
