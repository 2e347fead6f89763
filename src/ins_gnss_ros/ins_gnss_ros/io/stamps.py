"""Message stamps: conversions between ``builtin_interfaces/Time``, integer ns and float s.

Every time on the ROS time axis here is sensor time as UTC (POSIX; CONTRACT.md "Stamps").
Names say what goes in and what comes out: ``stamp`` is a ``builtin_interfaces/Time``, ``ns`` an
integer count of nanoseconds, ``sec`` a float of seconds. Integer ns are exact; a float of POSIX
seconds resolves only about 0.2 µs, so code that differences stamps (the IMU increments, bag log
times) works in ns and converts to seconds last.

The ``set_stamp_*`` functions write into the stamp a message already has: a generated message's
constructor is a few microseconds of Python, and the nodes stamp several messages per IMU
sample.
"""
from __future__ import annotations

import math

import numpy as np
from builtin_interfaces.msg import Time

#: Nanoseconds per second.
NS = 1_000_000_000


def stamp_to_ns(stamp: Time) -> int:
    """Integer ns of a stamp (exact)."""
    return stamp.sec * NS + stamp.nanosec


def stamp_or_arrival(stamp_ns: int, arrival_ns: int, topic: str) -> tuple[int, str | None]:
    """A message's stamp, or its arrival time where the driver left the stamp unset (0: no
    clock reads it; such a stream was refused sample by sample, or never measured a rate, with
    every node saying "ok"), and then what /diagnostics counts."""
    if stamp_ns:
        return stamp_ns, None
    return arrival_ns, f"{topic} stamp unset (0): its arrival time used"


def stamp_to_sec(stamp: Time) -> float:
    """Seconds (float) of a stamp."""
    return stamp.sec + stamp.nanosec * 1e-9


def ns_to_sec(t_ns: int) -> float:
    """Seconds (float) of integer ns, as :func:`stamp_to_sec` gives them for the stamp of those
    ns: ``t_ns * 1e-9`` differs from it in the last bit for many stamps, and a path that timed
    its IMU increments one way and its measurements the other (the offline replay did) applied
    a measurement stamped at a sample's own time one sample early."""
    sec, nanosec = divmod(int(t_ns), NS)
    return sec + nanosec * 1e-9


def msg_stamp_ns(msg) -> int:
    """Integer ns of a message's header stamp (``rosgraph_msgs/Clock``: of its clock field;
    ``tf2_msgs/TFMessage``: of its first transform)."""
    if hasattr(msg, "header"):
        return stamp_to_ns(msg.header.stamp)
    if hasattr(msg, "transforms"):
        return stamp_to_ns(msg.transforms[0].header.stamp)
    return stamp_to_ns(msg.clock)


def set_stamp_ns(stamp: Time, t_ns: int) -> None:
    """Write integer ns (a Python int) into an existing stamp."""
    stamp.sec, stamp.nanosec = divmod(t_ns, NS)


def sec_nanosec(t: float) -> tuple[int, int]:
    """The (sec, nanosec) of a stamp of ``t`` (s), rounded to the nearest ns."""
    sec = math.floor(t)
    nanosec = int(round((t - sec) * 1e9))
    if nanosec >= NS:  # rounding carried into the next second
        sec, nanosec = sec + 1, nanosec - NS
    return sec, nanosec


def set_stamp_sec(stamp: Time, t: float) -> None:
    """Write ``t`` (s) into an existing stamp, rounded to the nearest ns."""
    stamp.sec, stamp.nanosec = sec_nanosec(t)


def sec_to_stamp_ns(t) -> np.ndarray:
    """Integer ns (int64 array) of the stamps :func:`set_stamp_sec` writes for times ``t`` (s,
    array_like): whole seconds and the rounded fraction, which can differ by a few hundred ns
    from :func:`sec_to_ns`'s rounding of the whole time (for messages encoded in columns)."""
    t = np.asarray(t, float)
    sec = np.floor(t)
    return sec.astype(np.int64) * NS + np.round((t - sec) * 1e9).astype(np.int64)


def ns_to_stamp(t_ns: int) -> Time:
    """A new stamp of integer ns (any integer type, numpy's too)."""
    stamp = Time()
    set_stamp_ns(stamp, int(t_ns))
    return stamp


def sec_to_stamp(t: float) -> Time:
    """A new stamp of ``t`` (s), rounded to the nearest ns."""
    stamp = Time()
    set_stamp_sec(stamp, t)
    return stamp


def sec_to_ns(t, t0_ns: int = 0) -> np.ndarray:
    """Integer ns (int64 array) of times ``t`` (s, array_like) after ``t0_ns``; the same
    offset in s always gives the same ns (rounded, not truncated)."""
    return int(t0_ns) + np.round(np.asarray(t, float) * 1e9).astype(np.int64)
