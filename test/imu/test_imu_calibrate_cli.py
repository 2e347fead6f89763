"""imu_calibrate_cli end to end on a simulated six-face recording."""
import numpy as np
import pytest
import yaml

from ins_gnss_ros.imu.calibration import ImuCalibration, TriadCalibration
from ins_gnss_ros.imu.six_position import FACES, face_attitude, static_earth_rate, static_specific_force
from ins_gnss_ros.nav.earth import normal_gravity
from ins_gnss_ros.tools.imu_calibrate_cli import main


def test_cli_recovers_errors(tmp_path):
    rng = np.random.default_rng(21)
    lat = np.radians(59.94)
    truth = ImuCalibration(
        gyro=TriadCalibration(bias=[3e-4, -2e-4, 1e-4]),
        accel=TriadCalibration(bias=[0.04, -0.02, 0.07], scale=[2e-3, -3e-3, 1e-3],
                               nonorthogonality=[[0, 1e-3, -5e-4], [8e-4, 0, 2e-4], [-1e-3, 3e-4, 0]]))
    rows = []
    for face in FACES:
        c = face_attitude(face, np.radians(30.0))
        n = 1000
        w = np.tile(static_earth_rate(c, lat), (n, 1))
        f = np.tile(static_specific_force(c, normal_gravity(lat, 10.0)), (n, 1))
        g_raw, a_raw = truth.simulate_raw(w, f)
        g_raw += rng.normal(0, 1e-3, g_raw.shape)
        a_raw += rng.normal(0, 5e-3, a_raw.shape)
        rows += [f"{face},{','.join(f'{v:.9e}' for v in np.r_[gr, ar])}" for gr, ar in zip(g_raw, a_raw)]
    csv = tmp_path / "faces.csv"
    csv.write_text("face,gx,gy,gz,ax,ay,az\n" + "\n".join(rows) + "\n")
    out = tmp_path / "cal.yaml"
    assert main([str(csv), "--lat-deg", "59.94", "--height", "10", "--yaw-deg", "30",
                 "--out", str(out)]) == 0
    cal = ImuCalibration.from_dict(yaml.safe_load(out.read_text())["imu_calibration"])
    np.testing.assert_allclose(cal.gyro.bias[0], truth.gyro.bias[0], atol=1e-4)
    np.testing.assert_allclose(cal.accel.bias[0], truth.accel.bias[0], atol=1e-3)
    np.testing.assert_allclose(cal.accel.scale[0], truth.accel.scale[0], atol=2e-4)
    np.testing.assert_allclose(cal.accel.nonorthogonality, truth.accel.nonorthogonality, atol=2e-4)


def test_cli_needs_faces(tmp_path):
    csv = tmp_path / "bad.csv"
    csv.write_text("face,gx,gy,gz,ax,ay,az\n+q,0,0,0,0,0,9.8\n")
    with pytest.raises(SystemExit, match="faces"):
        main([str(csv), "--lat-deg", "0"])
