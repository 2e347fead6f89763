"""Simulated GNSS outages: the ``LEN:PERIOD[:FIRST]`` protocol of the trial CLI, and reduced
constellations in the same windows (``N:LEN:PERIOD[:FIRST]``, ``trial replay --satellites``).

Published INS benchmarks test dead reckoning by withholding GNSS periodically (e.g. the 15 s
outages every 45 s, the first 40 s into the run, of the rtklibexplorer GNSS_IMU car trial): the
filter is aided between outages and coasts on the IMU during them, and the position drift at the
end of each outage measures the inertial quality. A reduced constellation tests what tight
coupling keeps where a receiver has too few satellites for its own fix (seed 004 section 2.13:
the constellation ablation): the N highest satellites stay, the receiver's solution goes.
"""
from dataclasses import dataclass

import numpy as np

#: No outage starts within this many seconds of the last GNSS epoch, so that each outage is
#: followed by GNSS again and its end-of-outage drift is observed.
DEFAULT_END_MARGIN_S = 30.0
#: Topics withheld during an outage window (prefix, absolute names).
GNSS_PREFIX = "/gnss/"


@dataclass(frozen=True)
class OutageSpec:
    """Outage protocol: `length` s without GNSS every `period` s, the first `first` s in.

    Attributes
    ----------
    length : float
        Duration of each outage, s (> 0).
    period : float
        Time from the start of one outage to the start of the next, s (> length).
    first : float
        Start of the first outage after the first GNSS epoch, s (>= 0).
    """

    length: float
    period: float
    first: float

    def __str__(self):
        return f"{self.length:g}:{self.period:g}:{self.first:g}"


def parse_outage_spec(spec):
    """Parse ``"LEN:PERIOD[:FIRST]"`` (seconds) into an `OutageSpec`.

    FIRST defaults to PERIOD - LEN, so that every period ends with its outage and the run starts
    with PERIOD - LEN seconds of GNSS aiding for the filter to converge.

    Raises
    ------
    ValueError
        With the offending spec in the message, if it is not two or three numbers separated by
        ':' or if LEN <= 0, PERIOD <= LEN or FIRST < 0.
    """
    parts = str(spec).strip().split(":")
    if len(parts) not in (2, 3):
        raise ValueError(f"outage spec {spec!r}: expected LEN:PERIOD[:FIRST] in seconds, "
                         "e.g. '15:45:40'")
    try:
        values = [float(part) for part in parts]
    except ValueError:
        raise ValueError(f"outage spec {spec!r}: LEN, PERIOD and FIRST must be numbers") from None
    if not all(np.isfinite(values)):
        raise ValueError(f"outage spec {spec!r}: values must be finite")
    length, period = values[:2]
    first = values[2] if len(values) == 3 else period - length
    if length <= 0.0:
        raise ValueError(f"outage spec {spec!r}: LEN must be > 0 s")
    if period <= length:
        raise ValueError(f"outage spec {spec!r}: PERIOD must exceed LEN, or GNSS never returns")
    if first < 0.0:
        raise ValueError(f"outage spec {spec!r}: FIRST must be >= 0 s")
    return OutageSpec(length=length, period=period, first=first)


def outage_windows(spec, t_start, t_end, end_margin=DEFAULT_END_MARGIN_S):
    """Outage windows of a protocol over a run.

    Parameters
    ----------
    spec : OutageSpec or str
        The protocol (a string is parsed with `parse_outage_spec`).
    t_start, t_end : float
        Times of the first and last GNSS epochs, s (any time scale, e.g. GPS seconds).
    end_margin : float
        No outage starts later than `t_end - end_margin`, s.

    Returns
    -------
    ndarray, shape (k, 2)
        [start, end) of each outage, s, on the time scale of `t_start`; an end never exceeds
        `t_end`.
    """
    if isinstance(spec, str):
        spec = parse_outage_spec(spec)
    last_start = t_end - end_margin
    starts = t_start + spec.first + spec.period * np.arange(
        max(0, int(np.floor((last_start - t_start - spec.first) / spec.period)) + 1))
    starts = starts[starts <= last_start]
    return np.column_stack([starts, np.minimum(starts + spec.length, t_end)])


def in_outage(t, windows):
    """True where time(s) `t` fall inside any [start, end) window of `windows`.

    `windows` is (k, 2), sorted by start and not overlapping, as `outage_windows` and
    `gnss_windows` return. Integer times and windows (ns) are compared as integers: exactly.
    """
    shape = np.shape(t)
    t = np.atleast_1d(np.asarray(t)).ravel()
    windows = np.asarray(windows).reshape(-1, 2)
    # searchsorted finds the last window starting at or before t; windows do not overlap.
    index = np.searchsorted(windows[:, 0], t, side="right") - 1
    inside = index >= 0
    inside[inside] = t[inside] < windows[index[inside], 1]
    return inside.reshape(shape)


def gnss_mask(t, windows):
    """True for GNSS epochs `t` to keep (outside every outage window), the mask a replay applies."""
    return ~in_outage(t, windows)


def in_gnss_outage(topic, t_ns, windows) -> bool:
    """Whether a replay withholds the message on ``topic`` (absolute) stamped ``t_ns``: a GNSS
    topic inside one of the ``windows`` of :func:`gnss_windows`."""
    return topic.startswith(GNSS_PREFIX) and bool(in_outage(t_ns, windows))


def gnss_windows(messages, spec) -> np.ndarray:
    """Outage windows (ns, shape (k, 2)) of a ``LEN:PERIOD[:FIRST]`` spec over the GNSS span of
    ``messages`` (:class:`~ins_gnss_ros.io.BagMessage` list); empty without GNSS."""
    t = [m.t_ns for m in messages if m.topic.startswith(GNSS_PREFIX)]
    if spec is None or not t:
        return np.zeros((0, 2), np.int64)
    # Work relative to the first GNSS epoch: 1e9-scale seconds would lose sub-us resolution.
    t0 = t[0]
    windows = outage_windows(parse_outage_spec(spec), 0.0, (t[-1] - t0) * 1e-9)
    return t0 + np.round(windows * 1e9).astype(np.int64)



# ---------------------------------------------------------------------------------------------
# Reduced constellations: the N:LEN:PERIOD[:FIRST] protocol of trial replay --satellites
# ---------------------------------------------------------------------------------------------
#: Topics withheld in a satellite window: the receiver's own solution, which a receiver with
#: too few satellites does not have (the observations are thinned, the ephemerides flow on).
SOLUTION_TOPICS = ("/gnss/fix", "/gnss/vel")
OBSERVATIONS_TOPIC = "/gnss/observations"
#: Per-satellite arrays of ins_gnss_msgs/GnssObservations.
_OBSERVATION_ARRAYS = ("system", "prn", "frequency_slot", "signal", "pseudorange", "doppler",
                       "carrier_phase", "cn0", "lock_time", "loss_of_lock", "pseudorange_std",
                       "carrier_phase_std")


@dataclass(frozen=True)
class SatelliteSpec:
    """Reduced-constellation protocol: only the `count` highest satellites (at each window's
    start) stay in the observations during the windows of `windows`."""

    count: int
    windows: OutageSpec

    def __str__(self):
        return f"{self.count}:{self.windows}"


def parse_satellite_spec(spec):
    """Parse ``"N:LEN:PERIOD[:FIRST]"`` (N satellites, the windows as `parse_outage_spec`).

    Raises
    ------
    ValueError
        With the offending spec in the message.
    """
    count, _, windows = str(spec).strip().partition(":")
    try:
        n = int(count)
    except ValueError:
        raise ValueError(f"satellite spec {spec!r}: expected N:LEN:PERIOD[:FIRST], N a whole "
                         "number of satellites, e.g. '3:20:40:30'") from None
    if n < 0:
        raise ValueError(f"satellite spec {spec!r}: N must be >= 0")
    return SatelliteSpec(n, parse_outage_spec(windows))


def highest_satellites(messages, windows_ns, count):
    """The `count` highest satellites at the start of each window: of those in the first
    observation epoch at or after the start, of the systems tight coupling ranges by default
    (:class:`~ins_gnss_ros.gnss.ranges.RangeConfig`: GPS and Galileo, one receiver clock), with
    a valid broadcast ephemeris by then; by elevation at the receiver's last ``gnss/fix``
    before the start (its first when none is before).

    Returns
    -------
    list of list of (system, prn)
        u-blox gnssId numbering, highest first, one list per window; empty (the window keeps
        no satellite) when the messages have no observation epoch after its start or no fix.
    """
    from ins_gnss_ros.gnss.constants import UBX_GNSS_ID
    from ins_gnss_ros.gnss.ephemeris import elevation_azimuth, sat_position
    from ins_gnss_ros.gnss.ranges import RangeConfig, ephemeris_valid
    from ins_gnss_ros.nav.earth import geodetic_to_ecef
    from ins_gnss_ros.nodes.gnss_messages import kepler_from_msg

    systems = set(RangeConfig().signals)
    fixes = [m for m in messages if m.topic == "/gnss/fix" and m.msg.status.status >= 0]
    chosen = []
    for start, _ in windows_ns:
        epoch = next((m.msg for m in messages
                      if m.topic == OBSERVATIONS_TOPIC and m.t_ns >= start), None)
        if epoch is None or not fixes:
            chosen.append([])
            continue
        fix = max((m for m in fixes if m.t_ns <= start), key=lambda m: m.t_ns,
                  default=fixes[0]).msg
        rx = geodetic_to_ecef(np.radians(fix.latitude), np.radians(fix.longitude), fix.altitude)
        t_gps = epoch.gps_week * 604800.0 + epoch.time_of_week
        ephemerides = {(m.msg.system, m.msg.prn): m.msg for m in messages
                       if m.topic == "/gnss/ephemeris" and m.t_ns <= start}
        elevation = {}
        for sat in set(zip(epoch.system, epoch.prn)):
            if sat not in ephemerides or UBX_GNSS_ID.get(sat[0]) not in systems:
                continue
            eph = kepler_from_msg(ephemerides[sat], t_gps)
            if ephemeris_valid(eph, t_gps):
                elevation[sat] = elevation_azimuth(rx, sat_position(eph, t_gps)[0])[0]
        chosen.append(sorted(elevation, key=elevation.get, reverse=True)[:count])
    return chosen


def thin_observations(msg, keep):
    """A copy of a GnssObservations message with only the satellites in `keep` ((system, prn))."""
    import copy

    out = copy.copy(msg)
    mask = [(s, p) in keep for s, p in zip(msg.system, msg.prn)]
    for name in _OBSERVATION_ARRAYS:
        values = getattr(msg, name)
        setattr(out, name, [v for v, m in zip(values, mask) if m])
    return out


def reduce_constellation(messages, windows_ns, chosen):
    """The messages a replay plays with satellite windows: in window k, ``gnss/observations``
    thinned to ``chosen[k]`` and ``gnss/fix`` / ``gnss/vel`` left out; the rest unchanged.

    Returns
    -------
    played : list of BagMessage
    withheld : collections.Counter
        Messages left out, by topic.
    """
    from collections import Counter

    from ins_gnss_ros.io import BagMessage

    played, withheld = [], Counter()
    window = np.searchsorted(np.asarray(windows_ns)[:, 0], [m.t_ns for m in messages],
                             side="right") - 1 if len(windows_ns) else np.full(len(messages), -1)
    for m, k in zip(messages, window):
        inside = k >= 0 and m.t_ns < windows_ns[k][1]
        if inside and m.topic in SOLUTION_TOPICS:
            withheld[m.topic] += 1
        elif inside and m.topic == OBSERVATIONS_TOPIC:
            played.append(BagMessage(m.topic, m.t_ns, thin_observations(m.msg, set(chosen[k]))))
        else:
            played.append(m)
    return played, withheld
