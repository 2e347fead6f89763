"""A small real broadcast ephemeris set, stored with the package so that the GNSS simulator and
its tests need no recorded data at run time.

Source: the u-blox stream ``walk_0827/gnss_1730.ubx`` of github.com/rtklibexplorer/GNSS_IMU
(BSD-3-Clause, see ``SOURCE.md`` next to this file), decoded once with the project's own
decoder (:mod:`ins_gnss_ros.gnss.stream` + :mod:`ins_gnss_ros.gnss.nav_decode`) by
:func:`extract`; regenerate with ``python -m ins_gnss_ros.gnss.ephemeris_data SRC.ubx OUT.json``.

The 134 s recording completes 4 GPS LNAV and 7 Galileo I/NAV ephemerides (E14 flagged
unhealthy), all seen from Colorado (40.1 deg N, 105.1 deg W) on 2025-08-28 at about 17:31 UTC.
No GPS subframe 4 page 18 is in the stream (it repeats every 12.5 min), so the Klobuchar
coefficients stored are a representative broadcast set (see ``klobuchar_source`` in the file).

Sky at another place: :func:`load` can rotate every orbit about the Earth's axis by the
longitude difference to the recording site (adding it to the broadcast Omega0, which rotates
the ECEF orbit rigidly, IS-GPS-200 Table 20-IV), so a scenario at any longitude sees the
constellation the receiver tracked (the latitude difference is not compensated). The rotated
set is a valid broadcast ephemeris in its own right: publish it, not the original, to the
consumers of simulated data.
"""
from __future__ import annotations

import dataclasses
import json
import sys
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..constants import FIT_HALF_WIDTH_S, GALILEO, GPS
from ..ephemeris import KeplerEphemeris

#: The stored set.
DATA_FILE = Path(__file__).with_name("walk_0827.json")


@dataclass(frozen=True)
class BroadcastSet:
    """Ephemerides with the ionosphere coefficients and where and when they were received.

    Attributes
    ----------
    ephemerides : dict
        sat_id -> KeplerEphemeris (unhealthy ones included: check ``health``).
    klobuchar : tuple
        (alpha, beta) of the GPS broadcast ionosphere model [s/semicircle^n].
    site : tuple
        Mean receiver position of the recording: lat, lon [rad], h [m].
    t_first, t_last : float
        First and last raw-measurement epoch of the recording [GPS s].
    """

    ephemerides: dict
    klobuchar: tuple
    site: tuple
    t_first: float
    t_last: float

    def validity(self):
        """Interval [GPS s] in which every healthy ephemerides' fit interval overlaps."""
        toes = [e.toe for e in self.ephemerides.values() if not e.health]
        return max(toes) - FIT_HALF_WIDTH_S, min(toes) + FIT_HALF_WIDTH_S


def rotate_about_earth_axis(eph: KeplerEphemeris, angle: float) -> KeplerEphemeris:
    """The same orbit rotated by ``angle`` [rad] about the ECEF z axis (eastwards)."""
    return dataclasses.replace(eph, omega0=eph.omega0 + angle)


def load(longitude: float | None = None, path: Path = DATA_FILE) -> BroadcastSet:
    """Read the stored set.

    Parameters
    ----------
    longitude : float, optional
        Longitude [rad] at which the recorded sky should appear: every orbit is rotated by
        ``longitude - site longitude``. None keeps the orbits as broadcast.
    path : Path
        JSON file written by :func:`extract`.

    Returns
    -------
    BroadcastSet
    """
    data = json.loads(Path(path).read_text())
    site = tuple(data["site"])
    shift = 0.0 if longitude is None else longitude - site[1]
    ephs = {}
    for fields in data["ephemerides"]:
        eph = rotate_about_earth_axis(KeplerEphemeris(**fields), shift)
        ephs[eph.sat_id] = eph
    kb = data["klobuchar"]
    return BroadcastSet(ephs, (tuple(kb["alpha"]), tuple(kb["beta"])), site,
                        data["t_first"], data["t_last"])


#: Klobuchar coefficients used when the stream has none: a representative broadcast set
#: (the values of the project's ionosphere tests, test/gnss/test_atmosphere.py).
REPRESENTATIVE_KLOBUCHAR = {"alpha": [1.1176e-8, 7.4506e-9, -5.9605e-8, -5.9605e-8],
                            "beta": [90112.0, 0.0, -196608.0, -65536.0]}


def extract(ubx_path) -> dict:
    """Decode a u-blox stream into the JSON-ready content of a data file.

    Every RXM-SFRBX unit is assembled with the time of the last RXM-RAWX epoch (resolves
    week numbers); the newest complete ephemeris of each satellite is kept.
    """
    from .. import observations as obs
    from ..nav_decode import NavDataAssembler
    from ..stream import decode_file

    records, _ = decode_file(ubx_path)
    assembler, t_gps, leap, epochs, fixes = NavDataAssembler(), None, 18, [], []
    for record in records:
        if isinstance(record, obs.RawEpoch):
            t_gps, leap = record.t_gps, record.leap_s
            epochs.append(t_gps)
        elif isinstance(record, obs.NavSubframe) and t_gps is not None:
            assembler.add(record, t_gps, leap)
        elif isinstance(record, obs.PvtFix) and record.gnss_fix_ok:
            fixes.append((record.lat, record.lon, record.h))
    # GPS and Galileo only: the systems the simulator produces (BeiDou needs its own time
    # scale and GEO orbit handling, GLONASS a state-vector model).
    kepler = [dataclasses.asdict(e) for _, e in sorted(assembler.ephemerides.items())
              if isinstance(e, KeplerEphemeris) and e.system in (GPS, GALILEO)]
    if assembler.klobuchar is not None:
        klobuchar = {"alpha": list(assembler.klobuchar[0]), "beta": list(assembler.klobuchar[1])}
        kb_source = "GPS LNAV subframe 4 page 18 of the stream"
    else:
        klobuchar, kb_source = REPRESENTATIVE_KLOBUCHAR, (
            "not in the stream (page 18 repeats every 12.5 min): representative broadcast set")
    return {
        "source": f"{Path(ubx_path).name}, github.com/rtklibexplorer/GNSS_IMU data/walk_0827, "
                  "BSD-3-Clause; decoded with ins_gnss_ros.gnss.stream + nav_decode",
        "site": [float(v) for v in np.mean(fixes, axis=0)],
        "t_first": epochs[0], "t_last": epochs[-1],
        "klobuchar": klobuchar, "klobuchar_source": kb_source,
        "ephemerides": kepler,
    }


def main(argv=None) -> int:
    """``python -m ins_gnss_ros.gnss.ephemeris_data SRC.ubx OUT.json``"""
    argv = sys.argv[1:] if argv is None else argv
    if len(argv) != 2:
        print(main.__doc__, file=sys.stderr)
        return 2
    Path(argv[1]).write_text(json.dumps(extract(argv[0]), indent=1) + "\n")
    return 0


__all__ = ["BroadcastSet", "DATA_FILE", "extract", "load", "rotate_about_earth_axis"]
