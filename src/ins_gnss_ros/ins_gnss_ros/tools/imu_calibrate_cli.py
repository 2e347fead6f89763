"""Six-position static IMU calibration from a labelled recording.

Usage::

    imu_calibrate_cli static_faces.csv --lat-deg 59.94 --height 10 --out imu_calibration.yaml

The CSV has a header with the columns ``face,gx,gy,gz,ax,ay,az``: raw readings in rad/s and m/s²,
``face`` one of +x, -x, +y, -y, +z, -z (the body axis pointing up; see
:mod:`ins_gnss_ros.imu.six_position`), all faces recorded with the same heading ``--yaw-deg``
(ENU, counter-clockwise from east; it only matters for the Earth-rate term). The result is an
:class:`~ins_gnss_ros.imu.calibration.ImuCalibration` dict (accelerometer bias, scale and
non-orthogonality; gyro bias) written as YAML.
"""
from __future__ import annotations

import argparse
import sys

import numpy as np
import pandas as pd

from ins_gnss_ros.tools import write_yaml
from ins_gnss_ros.imu.calibration import ImuCalibration, TriadCalibration
from ins_gnss_ros.imu.six_position import (FACES, face_attitude, fit_accel_known_faces,
                                           fit_gyro_bias, static_specific_force)
from ins_gnss_ros.nav.earth import normal_gravity


def main(argv=None) -> int:
    p = argparse.ArgumentParser(prog="imu_calibrate_cli", description=__doc__.splitlines()[0])
    p.add_argument("csv", help="CSV with columns face,gx,gy,gz,ax,ay,az (rad/s, m/s²)")
    p.add_argument("--lat-deg", type=float, required=True, help="geodetic latitude, deg")
    p.add_argument("--height", type=float, default=0.0, help="ellipsoidal height, m")
    p.add_argument("--yaw-deg", type=float, default=0.0, help="heading of the faces (ENU yaw), deg")
    p.add_argument("--no-earth-rate", action="store_true",
                   help="do not remove Earth rate from the gyro means (MEMS grade)")
    p.add_argument("--temperature-ref", type=float, default=20.0, help="°C")
    p.add_argument("--out", help="YAML file to write (default: print)")
    args = p.parse_args(argv)

    frame = pd.read_csv(args.csv, skipinitialspace=True, dtype={"face": str})
    cols = ["gx", "gy", "gz", "ax", "ay", "az"]
    missing = [c for c in ["face"] + cols if c not in frame.columns]
    if missing:
        raise SystemExit(f"columns not in the file: {missing}")
    frame["face"] = frame["face"].str.strip()
    faces = [f for f in FACES if f in set(frame["face"])]
    unknown = set(frame["face"]) - set(FACES)
    if unknown or len(faces) < 4:
        raise SystemExit(f"need at least 4 of the faces {list(FACES)}; unknown labels {sorted(unknown)}")
    means = frame.groupby("face")[cols].mean().loc[faces].to_numpy()
    lat = np.radians(args.lat_deg)
    g = float(normal_gravity(lat, args.height))
    c_nb = np.array([face_attitude(f, np.radians(args.yaw_deg)) for f in faces])
    f_true = static_specific_force(c_nb, g)
    accel = fit_accel_known_faces(means[:, 3:], f_true)
    gyro_bias = fit_gyro_bias(means[:, :3], None if args.no_earth_rate else c_nb, lat)

    cal = ImuCalibration(gyro=TriadCalibration(bias=gyro_bias, label="gyro"), accel=accel,
                         temperature_ref=args.temperature_ref)
    resid = accel.correct(means[:, 3:], 0.0) - f_true
    print(f"faces {faces}, gravity {g:.5f} m/s²")
    print(f"accel bias {np.round(accel.bias[0], 5)} m/s², scale {np.round(accel.scale[0] * 1e6)} ppm")
    print(f"gyro bias {np.round(np.degrees(gyro_bias) * 3600, 2)} deg/h")
    print(f"residual RMS {np.sqrt(np.mean(resid ** 2)):.2e} m/s²")
    write_yaml({"imu_calibration": cal.to_dict()}, args.out)
    return 0


if __name__ == "__main__":
    sys.exit(main())
