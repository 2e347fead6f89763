"""Allan-variance noise characterisation of a static IMU recording.

Usage::

    allan_cli static.csv --rate 200 --gyro-cols gx,gy,gz --accel-cols ax,ay,az \\
        --gyro-unit deg/s --accel-unit g --out noise.yaml [--ros-node ekf]

Reads a CSV with a header line, fits white noise, bias instability and random walk per axis
(:mod:`ins_gnss_ros.imu.allan`) and writes the ``imu_noise`` section of a parameter file in SI
units (optionally wrapped as ``NODE: ros__parameters:``).
"""
from __future__ import annotations

import argparse
import sys

import numpy as np
import pandas as pd

from ins_gnss_ros.tools import write_yaml
from ins_gnss_ros.imu.allan import characterise, noise_section

GYRO_UNITS = {"rad/s": 1.0, "deg/s": np.pi / 180.0}
ACCEL_UNITS = {"m/s2": 1.0, "g": 9.80665}


def _columns(frame: pd.DataFrame, spec: str) -> np.ndarray:
    names = [c.strip() for c in spec.split(",") if c.strip()]
    missing = [c for c in names if c not in frame.columns]
    if missing:
        raise SystemExit(f"columns not in the file: {missing} (have {list(frame.columns)})")
    return frame[names].to_numpy(float)


def main(argv=None) -> int:
    p = argparse.ArgumentParser(prog="allan_cli", description=__doc__.splitlines()[0])
    p.add_argument("csv", help="static recording, CSV with a header line")
    p.add_argument("--rate", type=float, required=True, help="sample rate, Hz")
    p.add_argument("--gyro-cols", default="gx,gy,gz")
    p.add_argument("--accel-cols", default="ax,ay,az")
    p.add_argument("--gyro-unit", choices=sorted(GYRO_UNITS), default="rad/s")
    p.add_argument("--accel-unit", choices=sorted(ACCEL_UNITS), default="m/s2")
    p.add_argument("--out", help="YAML file to write (default: print only)")
    p.add_argument("--ros-node", help="wrap the section as NODE: ros__parameters:")
    args = p.parse_args(argv)

    frame = pd.read_csv(args.csv, skipinitialspace=True).dropna()
    gyro = _columns(frame, args.gyro_cols) * GYRO_UNITS[args.gyro_unit]
    accel = _columns(frame, args.accel_cols) * ACCEL_UNITS[args.accel_unit]
    g, a = characterise(gyro, args.rate), characterise(accel, args.rate)

    print(f"{len(frame)} samples, {len(frame) / args.rate:.0f} s at {args.rate:g} Hz")
    print("axis   ARW deg/sqrt(h)   BI deg/h   RRW deg/h/sqrt(h)")
    for i, c in enumerate(g):
        r2d = 180.0 / np.pi
        print(f"g{i}     {c.white * r2d * 60:12.4f}   {c.bias_instability * r2d * 3600:8.3f}"
              f"   {c.random_walk * r2d * 3600 * 60:12.4f}")
    print("axis   VRW m/s/sqrt(h)   BI ug      ARW_acc m/s2/sqrt(s)")
    for i, c in enumerate(a):
        print(f"a{i}     {c.white * 60:12.5f}   {c.bias_instability / 9.80665e-6:8.1f}"
              f"   {c.random_walk:12.3e}")

    section = noise_section(g, a)
    if args.ros_node:
        section = {args.ros_node: {"ros__parameters": section}}
    write_yaml(section, args.out)
    return 0


if __name__ == "__main__":
    sys.exit(main())
