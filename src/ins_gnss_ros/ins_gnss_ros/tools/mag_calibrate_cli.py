"""Magnetometer hard/soft-iron calibration (and optional seed-004 turntable filter) from a recording.

Usage::

    mag_calibrate_cli rotation.csv --lat-deg 59.94 --lon-deg 30.31 --height 10 --year 2026.0 \\
        [--unit uT] [--attitude] [--turntable | --reference-heading COLUMN] \\
        --out mag_calibration.yaml

The CSV has a header with columns ``mx,my,mz`` (body FLU axes), and with ``--attitude`` also
``roll,pitch`` (INS, rad), used by the fit to pin down the axis along the field (see
:func:`ins_gnss_ros.magnetic.ellipsoid_fit.calibrate`). The field magnitude comes from the WMM at
the given position and date, or from ``--field-nt``. With ``--turntable`` (needs ``roll,pitch``
and ``azimuth``, the table's reference heading clockwise from north, rad) the seven-state filter
of :mod:`ins_gnss_ros.magnetic.turntable_kf` then runs on the calibrated readings; its zero
offsets are folded into the hard iron and its heading correction is written as
``heading_bias`` (rad, to subtract from the magnetic azimuth together with the WMM declination).

With ``--reference-heading COLUMN`` (needs ``roll,pitch`` and that column, the reference heading
clockwise from north, rad) the attitude of every reading is known and the calibration is the
linear known-attitude fit of :mod:`ins_gnss_ros.magnetic.attitude_calibration` instead of the
ellipsoid fit: it also determines the axis along a steep field from the seed's Lab-3 recording
alone. Its estimated constant heading offset (table zero, yaw mounting) is written as
``heading_bias``.
"""
from __future__ import annotations

import argparse
import sys

import numpy as np
import pandas as pd

from ins_gnss_ros.tools import write_yaml
from ins_gnss_ros.magnetic.attitude_calibration import calibrate_with_attitude
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
    mode = p.add_mutually_exclusive_group()
    mode.add_argument("--turntable", action="store_true",
                      help="run the seven-state turntable filter on azimuth,roll,pitch")
    mode.add_argument("--reference-heading", metavar="COLUMN",
                      help="known-attitude fit with this reference-heading column (rad)")
    p.add_argument("--field-std-nt", type=float, default=50.0,
                   help="magnetometer noise per axis, nT (--reference-heading weights)")
    p.add_argument("--tilt-std-deg", type=float, default=0.05,
                   help="roll/pitch noise, deg (--reference-heading weights)")
    p.add_argument("--out", help="YAML file to write (default: print)")
    args = p.parse_args(argv)

    frame = pd.read_csv(args.csv, skipinitialspace=True).dropna()
    reference = args.reference_heading
    need = ["mx", "my", "mz"]
    need += ["roll", "pitch"] if args.attitude or args.turntable or reference else []
    need += ["azimuth"] if args.turntable else [reference] if reference else []
    missing = [c for c in need if c not in frame.columns]
    if missing:
        raise SystemExit(f"columns not in the file: {missing}")
    have_position = None not in (args.lat_deg, args.lon_deg, args.year)
    needs_wmm = args.field_nt is None or args.turntable or reference
    if needs_wmm and not have_position:
        raise SystemExit("give --lat-deg, --lon-deg and --year (WMM), or --field-nt")
    field = (field_elements(np.radians(args.lat_deg), np.radians(args.lon_deg), args.height,
                            args.year) if have_position else None)
    magnitude = args.field_nt * 1e-9 if args.field_nt is not None else field.total

    raw = frame[["mx", "my", "mz"]].to_numpy(float) * UNITS[args.unit]
    roll = frame["roll"].to_numpy(float) if "roll" in need else None
    pitch = frame["pitch"].to_numpy(float) if "pitch" in need else None
    print(f"{len(raw)} readings, field {magnitude * 1e9:.0f} nT")
    if reference:
        tilt_std = np.radians(args.tilt_std_deg)
        res = calibrate_with_attitude(raw, roll, pitch, frame[reference].to_numpy(float),
                                      field.enu, field_std=args.field_std_nt * 1e-9,
                                      roll_std=tilt_std, pitch_std=tilt_std)
        print(f"known-attitude fit: hard iron {np.round(res.calibration.offset * 1e9)} nT "
              f"(σ {np.round(res.offset_std * 1e9, 1)}), heading offset "
              f"{np.degrees(res.heading_offset):.3f} ± "
              f"{np.degrees(res.heading_offset_std):.3f} deg, "
              f"residual RMS {res.residual_rms * 1e9:.1f} nT")
        write_yaml({"mag_calibration": {**res.calibration.to_dict(),
                                        "heading_bias": res.heading_offset}}, args.out)
        return 0
    cal = calibrate(raw, magnitude, roll if args.attitude else None,
                    pitch if args.attitude else None)
    norm = np.linalg.norm(cal.apply(raw), axis=1)
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
