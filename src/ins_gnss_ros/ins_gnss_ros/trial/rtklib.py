"""Readers for RTKLIB output files: ``.pos`` solutions and ``.tag`` time-tag files.

Time is returned as GPS seconds, the project's time scale (:mod:`ins_gnss_ros.gnss.time`):
seconds since the GPS epoch 1980-01-06 00:00:00, float64. GPS time has no leap seconds, so a GPST
calendar label converts by plain calendar arithmetic; UTC labels go through the leap-second table.

The ``.pos`` layout is RTKLIB's ``outsol`` text format (RTKLIB manual, appendix B "Output file
formats"): '%' comment lines, the last of which names the columns, then one epoch per line.
"""
from dataclasses import dataclass, replace
from datetime import datetime
from pathlib import Path

import numpy as np

from ins_gnss_ros.gnss.time import GPS_EPOCH, gps_seconds, utc_to_gps

#: Seconds from 1970-01-01 to the GPS epoch (315964800); the ``.tag`` file counts whole GPST
#: seconds "like Unix time", i.e. from 1970-01-01 on the GPS time scale (RTKLIB ``gpst0``).
GPS_EPOCH_UNIX_S = (GPS_EPOCH - datetime(1970, 1, 1)).total_seconds()

# Solution quality flags Q of RTKLIB (SOLQ_* in rtklib.h).
Q_FIX = 1
Q_FLOAT = 2
Q_SBAS = 3
Q_DGPS = 4
Q_SINGLE = 5
Q_PPP = 6

# Header names (units stripped) -> attribute; vn/ve/vu and their sigmas are optional columns.
_POSITION_COLUMNS = ("latitude", "longitude", "height")
_REQUIRED_COLUMNS = _POSITION_COLUMNS + ("Q", "ns")
_SIGMA_COLUMNS = ("sdn", "sde", "sdu", "sdne", "sdeu", "sdun")
_VELOCITY_COLUMNS = ("vn", "ve", "vu")
_VELOCITY_SIGMA_COLUMNS = ("sdvn", "sdve", "sdvu", "sdvne", "sdveu", "sdvun")


@dataclass(frozen=True)
class PosSolution:
    """An RTKLIB position solution, one row per epoch.

    Attributes
    ----------
    time : ndarray, shape (n,)
        GPS seconds (since 1980-01-06 GPST).
    lat, lon : ndarray, shape (n,)
        Geodetic latitude and longitude, rad.
    height : ndarray, shape (n,)
        Ellipsoidal height, m.
    quality : ndarray of int, shape (n,)
        RTKLIB Q flag (`Q_FIX`, `Q_FLOAT`, ... `Q_PPP`).
    num_sats : ndarray of int, shape (n,)
        Number of satellites used.
    pos_cov_enu : ndarray, shape (n, 3, 3) or None
        Position covariance in the local ENU frame, m^2 (None if the file has no sigma columns).
    age : ndarray, shape (n,) or None
        Age of differential corrections, s.
    ratio : ndarray, shape (n,) or None
        Ambiguity ratio-test value.
    vel_enu : ndarray, shape (n, 3) or None
        Velocity east/north/up, m/s (None if the file has no velocity columns).
    vel_cov_enu : ndarray, shape (n, 3, 3) or None
        Velocity covariance in ENU, (m/s)^2.
    """

    time: np.ndarray
    lat: np.ndarray
    lon: np.ndarray
    height: np.ndarray
    quality: np.ndarray
    num_sats: np.ndarray
    pos_cov_enu: np.ndarray | None
    age: np.ndarray | None
    ratio: np.ndarray | None
    vel_enu: np.ndarray | None
    vel_cov_enu: np.ndarray | None

    def __len__(self):
        return len(self.time)

    def select(self, mask):
        """Return the epochs where boolean `mask` is true, as a new `PosSolution`."""
        return PosSolution(**{name: None if value is None else value[mask]
                              for name, value in vars(self).items()})


@dataclass(frozen=True)
class TimeTag:
    """Contents of an RTKLIB stream time-tag file (``<stream>.tag``, RTKLIB ``strsvr``/``str2str``).

    Attributes
    ----------
    start_time : float
        GPS seconds at which the logged stream started (``time_time + time_sec``).
    tick_f : int
        Receiver-host millisecond tick counter at the start of the log.
    ticks_ms : ndarray of uint32, shape (m,)
        Milliseconds since the start of the log at which each block of bytes was written.
    offsets : ndarray of uint32, shape (m,)
        File offsets, bytes, of the stream at each tick.
    header : str
        The 60-byte text header (e.g. ``"TIMETAG RTKLIB demo5"``), NUL padding stripped.
    """

    start_time: float
    tick_f: int
    ticks_ms: np.ndarray
    offsets: np.ndarray
    header: str

    @property
    def end_time(self):
        """GPS seconds of the last tag: start time plus the last tick."""
        return self.start_time + (float(self.ticks_ms[-1]) / 1000.0 if len(self.ticks_ms) else 0.0)


def gps_seconds_from_calendar(label, time_system="GPST"):
    """Convert a calendar label ``"YYYY/MM/DD HH:MM:SS[.sss]"`` to GPS seconds.

    Parameters
    ----------
    label : str
        Date and clock time as RTKLIB writes them.
    time_system : {"GPST", "UTC"}
        Time scale of the label; UTC adds the leap seconds GPST - UTC.

    Raises
    ------
    ValueError
        If `label` is not in that format.
    """
    stamp = datetime.strptime(label.strip(), "%Y/%m/%d %H:%M:%S.%f" if "." in label
                              else "%Y/%m/%d %H:%M:%S")
    if time_system == "UTC":
        return utc_to_gps(stamp)
    return (stamp - GPS_EPOCH).total_seconds()


def read_pos(path, geoid_separation=0.0):
    """Read an RTKLIB ``.pos`` solution file with geodetic (deg) positions and GPST time.

    The columns are taken from the last '%' header line, so files with or without velocity
    columns parse alike. Both time forms RTKLIB writes are accepted: calendar
    ``YYYY/MM/DD HH:MM:SS.sss`` and ``week tow``.

    Parameters
    ----------
    path : str or Path
        The ``.pos`` file.
    geoid_separation : float
        Geoid height N, m, added to the file's heights when they are above the geoid (RTKLIB's
        "geodetic" height option, or a converter that wrote u-blox hMSL): the returned
        heights are then ellipsoidal (h = H + N).

    Returns
    -------
    PosSolution

    Raises
    ------
    ValueError
        On an unsupported header (ECEF/ENU output, JST time, deg-min-sec angles) or on a
        malformed data line; the message names the file and line number.
    """
    path = Path(path)
    header = None
    rows = []
    with path.open("r", encoding="ascii", errors="replace") as stream:
        for number, line in enumerate(stream, start=1):
            text = line.strip()
            if not text:
                continue
            if text.startswith("%"):
                # The column header is the comment line whose first word is a time system;
                # other comment lines (e.g. "% obs start : ... GPST") are skipped.
                if text.lstrip("%").split()[:1] in (["GPST"], ["UTC"], ["JST"]):
                    time_system, header = _parse_header(text, path, number)
                continue
            if header is None:
                raise ValueError(f"{path}:{number}: data line before the '%' column header line")
            rows.append(_parse_line(text, time_system, len(header), path, number))
    if header is None:
        raise ValueError(f"{path}: no '%  GPST ...' column header line found")
    solution = _solution_from_rows(np.array(rows, dtype=float).reshape(-1, len(header)), header)
    return replace(solution, height=solution.height + geoid_separation)


def read_time_tag(path):
    """Read an RTKLIB time-tag file.

    Layout (RTKLIB ``stream.c``, ``TIMETAGH_LEN`` = 64): a 60-byte text header, then
    little-endian uint32 ``tick_f``, uint32 ``time_time`` (whole GPST seconds counted from
    1970-01-01 like Unix time) and float64 ``time_sec`` (fraction of a second); then 8-byte
    blocks of uint32 tick (ms since the start) and uint32 file offset.

    Raises
    ------
    ValueError
        If the file is shorter than its fixed header or has a partial trailing block.
    """
    path = Path(path)
    data = path.read_bytes()
    fixed = 60 + 4 + 4 + 8
    if len(data) < fixed:
        raise ValueError(f"{path}: {len(data)} bytes, shorter than the {fixed}-byte "
                         "time-tag header")
    if (len(data) - fixed) % 8:
        raise ValueError(f"{path}: {len(data) - fixed} bytes after the header, not whole "
                         "8-byte blocks")
    tick_f, time_time = np.frombuffer(data, "<u4", count=2, offset=60)
    time_sec = np.frombuffer(data, "<f8", count=1, offset=68)[0]
    blocks = np.frombuffer(data, "<u4", offset=fixed).reshape(-1, 2)
    return TimeTag(start_time=float(time_time) - GPS_EPOCH_UNIX_S + float(time_sec),
                   tick_f=int(tick_f),
                   ticks_ms=blocks[:, 0].copy(),
                   offsets=blocks[:, 1].copy(),
                   header=data[:60].split(b"\0", 1)[0].decode("ascii", errors="replace").strip())


def _parse_header(text, path, number):
    """Time system and column names (units stripped) of the '%' column header line."""
    names = [token.split("(", 1)[0] for token in text.lstrip("%").split()]
    if names[0] not in ("GPST", "UTC"):
        raise ValueError(f"{path}:{number}: time system {names[0]!r} not supported (GPST or UTC)")
    missing = [name for name in _REQUIRED_COLUMNS if name not in names]
    if missing:
        raise ValueError(f"{path}:{number}: header lacks columns {missing} "
                         "(only latitude/longitude/height output in degrees is supported)")
    if "latitude(d'\")" in text:
        raise ValueError(f"{path}:{number}: deg-min-sec angles not supported (use degrees)")
    # The time takes two fields in both forms ("date clock" or "week tow"); _parse_line puts
    # GPS seconds in the first and 0 in the second.
    return names[0], ["time", "time_unused"] + names[1:]


def _parse_line(text, time_system, num_columns, path, number):
    """One data line as floats in header order, GPS seconds and 0 for the two time fields."""
    fields = text.split()
    if len(fields) != num_columns:
        raise ValueError(f"{path}:{number}: {len(fields)} fields, header has {num_columns}: "
                         f"{text!r}")
    try:
        if "/" in fields[0]:
            time = gps_seconds_from_calendar(f"{fields[0]} {fields[1]}", time_system)
        elif time_system == "GPST":
            time = gps_seconds(int(fields[0]), float(fields[1]))
        else:
            raise ValueError("week/tow time in UTC is not an RTKLIB format")
        return (time, 0.0) + tuple(float(value) for value in fields[2:])
    except ValueError as error:
        raise ValueError(f"{path}:{number}: cannot parse {text!r}: {error}") from None


def _signed_square(sigma):
    """RTKLIB writes off-diagonal covariances as sign(c) * sqrt(|c|) (``sqvar`` in solution.c)."""
    return np.sign(sigma) * sigma ** 2


def _covariance_enu(columns, names):
    """ENU covariance stack from RTKLIB's (n, e, u, ne, eu, un) sigma columns."""
    sn, se, su, sne, seu, sun = (columns[name] for name in names)
    cov = np.empty((len(sn), 3, 3))
    cov[:, 0, 0], cov[:, 1, 1], cov[:, 2, 2] = se ** 2, sn ** 2, su ** 2
    cov[:, 0, 1] = cov[:, 1, 0] = _signed_square(sne)
    cov[:, 0, 2] = cov[:, 2, 0] = _signed_square(seu)
    cov[:, 1, 2] = cov[:, 2, 1] = _signed_square(sun)
    return cov


def _solution_from_rows(table, header):
    columns = {name: table[:, index] for index, name in enumerate(header)}
    names = set(header)
    return PosSolution(
        time=columns["time"],
        lat=np.radians(columns["latitude"]),
        lon=np.radians(columns["longitude"]),
        height=columns["height"],
        quality=columns["Q"].astype(int),
        num_sats=columns["ns"].astype(int),
        pos_cov_enu=(_covariance_enu(columns, _SIGMA_COLUMNS)
                     if names >= set(_SIGMA_COLUMNS) else None),
        age=columns.get("age"),
        ratio=columns.get("ratio"),
        vel_enu=(np.column_stack([columns["ve"], columns["vn"], columns["vu"]])
                 if names >= set(_VELOCITY_COLUMNS) else None),
        vel_cov_enu=(_covariance_enu(columns, _VELOCITY_SIGMA_COLUMNS)
                     if names >= set(_VELOCITY_SIGMA_COLUMNS) else None),
    )
