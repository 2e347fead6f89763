"""When a message of a periodic stream will arrive, from its stamp.

A node that needs only some messages of a high-rate stream at once (the imu_preprocessor: the
sample that completes an increment) may let the others wait and take them together, if it
knows when the one it needs will come. The delay from a message's stamp to its arrival is a
transport and scheduling delay that is never shorter than some least value; the least delay
seen lately, added to a stamp, is the earliest the message of that stamp can be expected.
No ROS here: stamps and arrivals are integer ns given by the caller.
"""
from __future__ import annotations

from .stamps import NS

__all__ = ["ArrivalForecast"]


class ArrivalForecast:
    """The earliest arrival of a message by its stamp, from the least stamp-to-arrival delay of
    the messages of the last one to two windows.

    The minimum is taken over windows (the current one and the one before it) rather than
    over all time, so that a drift or a step between the stamping clock and the arrival
    clock is forgotten after two windows.

    Parameters
    ----------
    window_ns : int
        Length of a window, ns.
    """

    def __init__(self, window_ns: int = NS):
        self.window_ns = int(window_ns)
        self._least: int | None = None      # least delay of the current window
        self._previous: int | None = None   # ... and of the window before it
        self._window_end: int | None = None

    def add(self, stamp_ns: int, arrival_ns: int) -> None:
        """A message stamped ``stamp_ns`` arrived (or was seen first) at ``arrival_ns``."""
        delay = arrival_ns - stamp_ns
        if self._window_end is None or arrival_ns >= self._window_end:
            self._previous, self._least = self._least, delay
            self._window_end = arrival_ns + self.window_ns
        elif delay < self._least:
            self._least = delay

    def arrival(self, stamp_ns: int) -> int | None:
        """The earliest expected arrival of the message stamped ``stamp_ns``, ns; None before
        the first message."""
        if self._least is None:
            return None
        least = self._least if self._previous is None else min(self._least, self._previous)
        return stamp_ns + least
