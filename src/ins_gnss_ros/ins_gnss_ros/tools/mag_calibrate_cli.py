"""Magnetometer hard/soft-iron calibration (and optional seed-004 turntable filter) from a recording.

Usage::

    mag_calibrate_cli rotation.csv --lat-deg 59.94 --lon-deg 30.31 --height 10 --year 2026.0 \\
        [--unit uT] [--attitude] [--turntable] --out mag_calibration.yaml

The CSV has a header with columns ``mx,my,mz`` (body FLU axes), and with ``--attitude`` also
``roll,pitch`` (INS, rad), used by the fit to pin down the axis along the field (see
:func:`ins_gnss_ros.magnetic.ellipsoid_fit.calibrate`). The field magnitude comes from the WMM at
the given position and date, or from ``--field-nt``. With ``--turntable`` (needs ``roll,pitch``
and ``azimuth``, the table's reference heading clockwise from north, rad) the seven-state filter
of :mod:`ins_gnss_ros.magnetic.turntable_kf` then runs on the calibrated readings; its zero
offsets are folded into the hard iron and its heading correction is written as
``heading_bias`` (rad, to subtract from the magnetic azimuth together with the WMM declination).
"""
from __future__ import annotations

import argparse
import sys

import numpy as np
import pandas as pd

from ins_gnss_ros.tools import write_yaml
from ins_gnss_ros.magnetic.ellipsoid_fit import HardSoftIron, calibrate
from ins_gnss_ros.magnetic.turntable_kf import TurntableCalibrationKF
from ins_gnss_ros.magnetic.wmm import field_elements

UNITS = {"T": 1.0, "uT": 1e-6, "nT": 1e-9, "gauss": 1e-4}


def main(argv=None) -> int:
    p = argparse.ArgumentParser(prog="mag_calibrate_cli", description=__doc__.splitlines()[0])
    p.add_argument("csv", help="CSV with mx,my,mz [roll,pitch] [azimuth]")
    p.add_argument("--unit", choices=sorted(UNITS), default="T", help="unit of mx,my,mz")
    p.add_argument("--field-nt", type=float, help="local field magnitude, nT (instead of WMM)")
    p.add_argument("--lat-deg", type=float)
    p.add_argument("--lon-deg", type=float)
    p.add_argument("--height", type=float, default=0.0, help="ellipsoidal height, m")
    p.add_argument("--year", type=float, help="decimal year for the WMM")
    p.add_argument("--attitude", action="store_true", help="use the roll,pitch columns in the fit")
    p.add_argument("--turntable", action="store_true",
                   help="run the seven-state turntable filter on azimuth,roll,pitch")
    p.add_argument("--out", help="YAML file to write (default: print)")
    args = p.parse_args(argv)

    frame = pd.read_csv(args.csv, skipinitialspace=True).dropna()
    need = ["mx", "my", "mz"] + (["roll", "pitch"] if args.attitude or args.turntable else [])
    need += ["azimuth"] if args.turntable else []
    missing = [c for c in need if c not in frame.columns]
    if missing:
        raise SystemExit(f"columns not in the file: {missing}")
    have_position = None not in (args.lat_deg, args.lon_deg, args.year)
    if args.field_nt is None and not have_position or args.turntable and not have_position:
        raise SystemExit("give --lat-deg, --lon-deg and --year (WMM), or --field-nt")
    field = (field_elements(np.radians(args.lat_deg), np.radians(args.lon_deg), args.height,
                            args.year) if have_position else None)
    magnitude = args.field_nt * 1e-9 if args.field_nt is not None else field.total

    raw = frame[["mx", "my", "mz"]].to_numpy(float) * UNITS[args.unit]
    roll = frame["roll"].to_numpy(float) if "roll" in need else None
    pitch = frame["pitch"].to_numpy(float) if "pitch" in need else None
    cal = calibrate(raw, magnitude, roll if args.attitude else None,
                    pitch if args.attitude else None)
    norm = np.linalg.norm(cal.apply(raw), axis=1)
    print(f"{len(raw)} readings, field {magnitude * 1e9:.0f} nT")
    print(f"hard iron {np.round(cal.offset * 1e9)} nT; |field| residual RMS "
          f"{np.sqrt(np.mean((norm - magnitude) ** 2)) * 1e9:.1f} nT")
    out = {"mag_calibration": cal.to_dict()}

    if args.turntable:
        kf = TurntableCalibrationKF(field.enu)
        t = frame["t"].to_numpy(float) if "t" in frame.columns else np.arange(len(raw), dtype=float)
        mag = cal.apply(raw)
        az = frame["azimuth"].to_numpy(float)
        for i in range(len(raw)):
            kf.update(t[i], mag[i], roll[i], pitch[i], az[i])
        # b = W (m - c) - ΔF = W (m - c - W^-1 ΔF): fold the offsets into the hard iron.
        cal = HardSoftIron(cal.offset + np.linalg.solve(cal.matrix, kf.offsets), cal.matrix)
        bias = kf.heading_correction(field.declination)
        print(f"turntable filter: offsets {np.round(kf.offsets * 1e9, 1)} nT "
              f"(σ {np.round(kf.std[3:6] * 1e9, 1)}), heading correction {np.degrees(bias):.3f} deg")
        out = {"mag_calibration": {**cal.to_dict(), "heading_bias": bias}}

    write_yaml(out, args.out)
    return 0


if __name__ == "__main__":
    sys.exit(main())
