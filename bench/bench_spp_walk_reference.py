#!/usr/bin/env python3
"""Where the ~6 m offset between the project's SPP and the walk's RTK reference comes from.

Data: ``../shared/data/walk_0827/gnss_1730.ubx`` (u-blox RXM-RAWX + RXM-SFRBX + NAV-PVT, 4 Hz,
134 s) and ``gnss_1730_sf.pos`` (the reference of issue 4). Prints, in order:

1. whether the .pos is the receiver's own NAV-PVT solution (epoch by epoch) and its RTK states;
2. SPP minus reference for the solution variants (dual-frequency GPS+Galileo, GPS only, Galileo
   only, single-frequency GPS+Galileo+BeiDou): mean ENU offset and horizontal scatter about it;
3. a scan of the reference time shift (-20..+20 s): a time-tag error would show as an offset
   along the walking direction that collapses at the right shift;
4. the offset in the west/east and south/north halves of the walk (10 m apart): multipath or
   non-line-of-sight reception from nearby buildings depends on where the antenna is;
5. per-satellite pseudorange residuals at the reference position (per-system clock removed)
   next to -u.offset, the residual a rigid shift of the reference would cause, and how much
   they vary while the antenna moves (dual and single frequency);
6. the NAD83(2011) - ITRF2020 difference at the site (a datum mix-up in the base coordinates);
7. if RTKLIB's ``convbin`` and ``rnx2rtkp`` are on PATH (e.g. Debian package ``rtklib``, a
   measuring instrument only, not a project dependency): RTKLIB's own decoding and SPP of the
   GPS satellites against the project's, epoch by epoch.

Usage:  .venv/bin/python bench/bench_spp_walk_reference.py [--data DIR]
"""
import argparse
import datetime as dt
import math
import shutil
import subprocess
import tempfile
from pathlib import Path

import numpy as np
import pymap3d

from ins_gnss_ros.gnss.atmosphere import tropo_delay
from ins_gnss_ros.gnss.constants import C_LIGHT
from ins_gnss_ros.gnss.ephemeris import elevation_azimuth, satellite_at_reception
from ins_gnss_ros.gnss.nav_decode import NavDataAssembler
from ins_gnss_ros.gnss.observations import PvtFix, RawEpoch
from ins_gnss_ros.gnss.spp import SppConfig, select_measurements, solve_position
from ins_gnss_ros.gnss.stream import decode_file
from ins_gnss_ros.gnss.time import GPS_EPOCH
from ins_gnss_ros.nav.earth import ecef_to_enu_matrix
from ins_gnss_ros.trial.rtklib import read_pos

REPO = Path(__file__).resolve().parents[1]
DEFAULT_DATA = REPO.parent / "shared" / "data" / "walk_0827"
VARIANTS = (("GPS+Galileo dual-freq. (default)", SppConfig(), "GE"),
            ("GPS only dual-freq.", SppConfig(), "G"),
            ("Galileo only dual-freq.", SppConfig(), "E"),
            ("GPS+Galileo+BeiDou single freq.", SppConfig(iono_free=False), "GEC"))
#: EPSG:10334 ITRF2020 -> NAD83(2011) (coordinate frame rotation) at epoch 2010.0 and rates:
#: translations [m], rotations [mas], scale [ppb].
NAD83 = dict(t=(1.0039, -1.90961, -0.54117), dt=(0.79e-3, -0.70e-3, -1.24e-3),
             r=(26.78138, -0.42027, 10.93206), dr=(0.06667, -0.75744, -0.05133),
             s=-0.05109, ds=-0.07201)


def load(folder):
    """RawEpochs, NAV-PVT fixes, ephemerides and the .pos reference of the walk."""
    records, _ = decode_file(folder / "gnss_1730.ubx")
    epochs = [r for r in records if isinstance(r, RawEpoch)]
    pvts = [r for r in records if isinstance(r, PvtFix)]
    return epochs, pvts, NavDataAssembler().add_records(records), \
        read_pos(folder / "gnss_1730_sf.pos")


def spp_errors(epochs, pvts, ephemerides, config, systems):
    """SPP minus NAV-PVT (ENU at the reference, m) of every epoch that solves, and the indices."""
    ephs = {k: v for k, v in ephemerides.items() if k[0] in systems}
    errors, index, x0 = [], [], None
    for i, (epoch, pvt) in enumerate(zip(epochs, pvts)):
        sol = solve_position(epoch, ephs, config, x0)
        if sol is None:
            continue
        x0 = sol.xyz
        errors.append(pymap3d.ecef2enu(*sol.xyz, pvt.lat, pvt.lon, pvt.h, deg=False))
        index.append(i)
    return np.array(errors), np.array(index)


def scatter(errors):
    """Horizontal RMS about the mean offset [m]."""
    centred = errors[:, :2] - errors[:, :2].mean(axis=0)
    return float(np.sqrt(np.mean(np.sum(centred ** 2, axis=1))))


def reference_check(pvts, pos):
    t_pvt = np.array([p.t_gps for p in pvts])
    lat = np.array([p.lat for p in pvts])
    lon = np.array([p.lon for p in pvts])
    h_msl = np.array([p.h_msl for p in pvts])
    carr = np.bincount([p.carr_soln for p in pvts], minlength=3)
    print("1. reference = receiver NAV-PVT?")
    print(f"   epochs {len(pvts)} / {len(pos.time)}; |t_pos - iTOW| max "
          f"{np.abs(pos.time - t_pvt).max() * 1e3:.1f} ms; |lat|,|lon| max "
          f"{np.degrees(np.abs(pos.lat - lat).max()):.1e}, "
          f"{np.degrees(np.abs(pos.lon - lon).max()):.1e} deg (file rounds to 1e-7); "
          f"|height - hMSL| max {np.abs(pos.height - h_msl).max():.3f} m")
    print(f"   NAV-PVT carrSoln none/float/fixed: {carr[0]}/{carr[1]}/{carr[2]} "
          "(real-time RTK against a base that the recording does not identify)")


def variants(epochs, pvts, ephemerides):
    print("2. SPP - reference, mean ENU offset and horizontal scatter about it [m]")
    out = {}
    for label, config, systems in VARIANTS:
        errors, index = spp_errors(epochs, pvts, ephemerides, config, systems)
        out[systems] = errors, index
        h_rms = np.sqrt(np.mean(np.sum(errors[:, :2] ** 2, axis=1)))
        print(f"   {label:34s} n {len(errors):3d}  H RMS {h_rms:5.2f}  mean "
              f"{np.array2string(errors.mean(axis=0), precision=2)}  scatter {scatter(errors):.2f}")
    return out


def time_shift_scan(errors, index, pvts):
    """Re-reference the SPP to the NAV-PVT track shifted in time by s seconds."""
    lat0, lon0, h0 = pvts[0].lat, pvts[0].lon, pvts[0].h
    track = np.array([pymap3d.geodetic2enu(p.lat, p.lon, p.h, lat0, lon0, h0, deg=False)
                      for p in pvts])
    t = np.array([p.t_gps for p in pvts])
    spp = track[index] + errors  # local ENU is the same frame over 20 m to < 1 mm
    print("3. reference time shift s [s] -> H RMS, scatter about the mean [m]")
    line = []
    for shift in (-20, -10, -5, -2, -1, -0.5, -0.25, 0, 0.25, 0.5, 1, 2, 5, 10, 20):
        inside = (t[index] + shift >= t[0]) & (t[index] + shift <= t[-1])
        ref = np.array([np.interp(t[index][inside] + shift, t, track[:, k]) for k in range(3)]).T
        err = spp[inside] - ref
        h_rms = np.sqrt(np.mean(np.sum(err[:, :2] ** 2, axis=1)))
        line.append(f"{shift:+g}: {h_rms:.2f}/{scatter(err):.2f}")
    print("   " + ", ".join(line))
    return track


def halves(errors, index, track):
    print("4. offset where the antenna is (halves of the walk split at the median) [m]")
    where = track[index]
    for axis, names in ((0, ("west", "east")), (1, ("south", "north"))):
        low = where[:, axis] < np.median(where[:, axis])
        for name, mask in zip(names, (low, ~low)):
            print(f"   {name:5s} half (antenna at E {where[mask, 0].mean():5.1f}, "
                  f"N {where[mask, 1].mean():5.1f}): mean offset "
                  f"{np.array2string(errors[mask].mean(axis=0), precision=2)}")


def residuals_at_reference(epochs, pvts, ephemerides, offset, config):
    """Per-satellite pseudorange residuals at the reference position, beside those a reference
    displaced by -offset from the truth would cause (-u.offset); both with their per-system,
    per-epoch mean removed (the receiver clock takes it). Single-frequency residuals include
    the ionosphere: their standard deviation over the walk is the point."""
    rows_by_sat = {}
    for epoch, pvt in zip(epochs, pvts):
        ref = np.array(pymap3d.geodetic2ecef(pvt.lat, pvt.lon, pvt.h, deg=False))
        rot = ecef_to_enu_matrix(pvt.lat, pvt.lon)
        by_system = {}
        for m in select_measurements(epoch, ephemerides, config):
            sat, clock, _, _ = satellite_at_reception(m.eph, epoch.t_gps, m.pseudorange, ref)
            elevation, azimuth = elevation_azimuth(ref, sat)
            if elevation < config.elevation_mask:
                continue
            predicted = (np.linalg.norm(sat - ref) - C_LIGHT * (clock - m.group_delay_s)
                         + tropo_delay(pvt.lat, pvt.h, elevation))
            unit = rot @ (sat - ref) / np.linalg.norm(sat - ref)
            by_system.setdefault(m.system, []).append(
                (m.sat_id, m.pseudorange - predicted, -unit @ offset, elevation, azimuth,
                 m.obs.cn0_dbhz))
        for rows in by_system.values():
            if len(rows) < 2:
                continue
            res_mean = np.mean([r[1] for r in rows])
            shift_mean = np.mean([r[2] for r in rows])
            for sat_id, res, shift, *rest in rows:
                rows_by_sat.setdefault(sat_id, []).append((res - res_mean, shift - shift_mean,
                                                           *rest))
    kind = "dual-freq." if config.iono_free else "single-freq."
    print(f"5. {kind} residual at the reference vs -u.offset, per-system mean removed [m]")
    print("   sat  epochs  mean   std  -u.offset  elev  azim  C/N0")
    for sat_id in sorted(rows_by_sat):
        rows = np.array(rows_by_sat[sat_id])
        res, shift = rows[:, 0], rows[:, 1]
        elevation, azimuth, cn0 = rows[len(rows) // 2, 2:]
        print(f"   {sat_id}  {len(res):4d}  {res.mean():5.2f} {res.std():5.2f}  {shift.mean():6.2f}"
              f"    {math.degrees(elevation):5.1f} {math.degrees(azimuth):5.1f}  {cn0:4.0f}")


def nad83_minus_itrf(lat, lon, h, year):
    """ENU position of a point's ITRF2020 coordinates minus its NAD83(2011) ones [m]."""
    mas = math.radians(1.0 / 3.6e6)
    years = year - 2010.0
    t = np.add(NAD83["t"], years * np.array(NAD83["dt"]))
    rx, ry, rz = (np.add(NAD83["r"], years * np.array(NAD83["dr"]))) * mas
    scale = (NAD83["s"] + years * NAD83["ds"]) * 1e-9
    rotation = np.array([[1.0, rz, -ry], [-rz, 1.0, rx], [ry, -rx, 1.0]])
    itrf = np.array(pymap3d.geodetic2ecef(lat, lon, h, deg=False))
    nad83 = t + (1.0 + scale) * rotation @ itrf
    return np.array(pymap3d.ecef2enu(*itrf, lat, lon, h, deg=False)) - \
        np.array(pymap3d.ecef2enu(*nad83, lat, lon, h, deg=False))


def rtklib_check(folder, epochs, pvts, ephemerides):
    """RTKLIB's GPS SPP (own UBX and SFRBX decoding) against the project's, epoch by epoch."""
    if not (shutil.which("convbin") and shutil.which("rnx2rtkp")):
        print("7. RTKLIB convbin/rnx2rtkp not on PATH: cross-check skipped")
        return
    t_pvt = np.array([p.t_gps for p in pvts])
    print("7. RTKLIB SPP (GPS; its decoder keeps no Galileo I/NAV or BeiDou B3I here) vs ours:")
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        subprocess.run(["convbin", "-r", "ubx", "-v", "3.04", str(folder / "gnss_1730.ubx"),
                        "-o", str(tmp / "w.obs"), "-n", str(tmp / "w.nav")],
                       check=True, capture_output=True)
        for label, freq, iono, config in (("L1+L2 iono-free", "l1+l2", "dual-freq", SppConfig()),
                                          ("L1 only, no iono", "l1", "off",
                                           SppConfig(iono_free=False))):
            (tmp / "spp.conf").write_text(
                f"pos1-posmode=single\npos1-frequency={freq}\npos1-elmask=10\n"
                f"pos1-ionoopt={iono}\npos1-tropopt=saas\npos1-navsys=1\n"
                "out-solformat=llh\nout-height=ellipsoidal\nout-timesys=gpst\n")
            subprocess.run(["rnx2rtkp", "-k", str(tmp / "spp.conf"), "-o", str(tmp / "w.pos"),
                            str(tmp / "w.obs"), str(tmp / "w.nav")], check=True,
                           capture_output=True)
            theirs = read_pos(tmp / "w.pos")
            ours, _ = spp_errors(epochs, pvts, ephemerides, config, "G")
            rows = [np.argmin(np.abs(t_pvt - t)) for t in theirs.time]
            ref = [pvts[i] for i in rows]
            rtk = np.array([pymap3d.geodetic2enu(la, lo, h, p.lat, p.lon, p.h, deg=False)
                            for la, lo, h, p in zip(theirs.lat, theirs.lon, theirs.height,
                                                    ref)])
            if len(rtk) != len(ours):
                print(f"   {label}: RTKLIB solved {len(rtk)} epochs, ours {len(ours)}")
                continue
            diff = ours - rtk
            print(f"   {label}: RTKLIB mean offset {np.array2string(rtk.mean(axis=0), precision=2)}"
                  f"; ours - RTKLIB max |E|,|N|,|U| "
                  f"{np.array2string(np.abs(diff).max(axis=0), precision=3)} m")


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--data", type=Path, default=DEFAULT_DATA)
    args = parser.parse_args()
    epochs, pvts, ephemerides, pos = load(args.data)
    reference_check(pvts, pos)
    solutions = variants(epochs, pvts, ephemerides)
    errors, index = solutions["GE"]
    track = time_shift_scan(errors, index, pvts)
    halves(errors, index, track)
    for config in (SppConfig(), SppConfig(iono_free=False)):
        residuals_at_reference(epochs, pvts, ephemerides, errors.mean(axis=0), config)
    utc = GPS_EPOCH + dt.timedelta(seconds=pvts[0].t_gps)
    year = utc.year + (utc - dt.datetime(utc.year, 1, 1)).days / 365.25
    shift = nad83_minus_itrf(pvts[0].lat, pvts[0].lon, pvts[0].h, year)
    print(f"6. ITRF2020 - NAD83(2011) at the site, epoch {year:.2f}: ENU "
          f"{np.array2string(shift, precision=2)} m")
    rtklib_check(args.data, epochs, pvts, ephemerides)


if __name__ == "__main__":
    main()
