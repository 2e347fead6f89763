"""allan_cli end to end: CSV in (deg/s, g), YAML out (SI)."""
import numpy as np
import pytest
import yaml

from ins_gnss_ros.tools.allan_cli import main


def test_cli_writes_noise_section(tmp_path, capsys):
    rng = np.random.default_rng(5)
    rate, n = 20.0, 24000
    arw_deg, vrw_g = 0.01, 1e-4  # deg/s/√Hz and g/√Hz
    gyro = arw_deg * np.sqrt(rate) * rng.standard_normal((n, 3))
    accel = vrw_g * np.sqrt(rate) * rng.standard_normal((n, 3)) + [0, 0, 1]
    csv = tmp_path / "static.csv"
    np.savetxt(csv, np.column_stack([gyro, accel]), delimiter=",", header="gx,gy,gz,ax,ay,az",
               comments="")
    out = tmp_path / "noise.yaml"
    assert main([str(csv), "--rate", "20", "--gyro-unit", "deg/s", "--accel-unit", "g",
                 "--out", str(out), "--ros-node", "ekf"]) == 0
    sec = yaml.safe_load(out.read_text())["ekf"]["ros__parameters"]["imu_noise"]
    np.testing.assert_allclose(sec["gyro_noise_density"], np.radians(arw_deg), rtol=0.1)
    np.testing.assert_allclose(sec["accel_noise_density"], vrw_g * 9.80665, rtol=0.1)
    assert "ARW" in capsys.readouterr().out


def test_cli_rejects_missing_columns(tmp_path):
    csv = tmp_path / "x.csv"
    csv.write_text("a,b\n1,2\n")
    with pytest.raises(SystemExit, match="columns"):
        main([str(csv), "--rate", "10"])
