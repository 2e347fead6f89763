"""Loss-of-lock indicators of raw observations, as ``GnssObservations.loss_of_lock`` reports them.

The indicator tells the phase processing that a cycle slip is possible since the signal's
previous epoch.  A receiver gives it only indirectly: u-blox RXM-RAWX reports each signal's lock
time and whether its half-cycle ambiguity is resolved (:class:`LockTracker`); the simulated
receiver flags slips itself but, like a real one, publishes a phase only once its half-cycle
ambiguity is resolved (:class:`HalfCycleTracker`).  ``GnssObservations`` has no half-cycle
flag, so in both cases the epoch a phase becomes usable is flagged: u-blox may subtract half a
cycle at that moment (RXM-RAWX trkStat).
"""
from __future__ import annotations

import math

from .observations import RawEpoch


class LockTracker:
    """Per-signal carrier-phase continuity from the receiver's lock time and half-cycle flag.

    A signal is flagged ``loss_of_lock`` when the receiver clock was reset, the signal was not
    tracked at the previous epoch, its lock time is shorter than the time since that epoch (the
    phase loop re-locked in between), or its phase became usable only now.
    """

    def __init__(self):
        self._prev: dict[tuple, tuple[float, bool]] = {}  # key -> (t_gps, phase usable)

    def update(self, raw: RawEpoch) -> list[bool]:
        """Loss-of-lock flags of ``raw.obs`` (and remember this epoch)."""
        flags, current = [], {}
        for o in raw.obs:
            key = (o.system, o.prn, o.signal)
            usable = math.isfinite(o.carrier_cycles) and o.half_cycle_valid
            prev = self._prev.get(key)
            if raw.clock_reset or prev is None:
                flags.append(True)
            else:
                elapsed_ms = (raw.t_gps - prev[0]) * 1000.0
                flags.append(o.lock_ms < elapsed_ms or (usable and not prev[1]))
            current[key] = (raw.t_gps, usable)
        self._prev = current
        return flags


class HalfCycleTracker:
    """Loss-of-lock flags of simulated epochs: the simulator's own slip flags, and the epoch at
    which a satellite's half-cycle ambiguity becomes resolved (its phase published from then on).

    Satellites are tracked per antenna; one that leaves an antenna's epoch is forgotten, so its
    phase becoming valid after it returns is flagged again.
    """

    def __init__(self):
        self._valid: dict[int, dict[str, bool]] = {}  # antenna -> sat_id -> half cycle valid

    def update(self, antenna: int, raw: RawEpoch, slipped) -> list[bool]:
        """Loss-of-lock flags of ``raw.obs`` of ``antenna`` given the simulator's ``slipped``
        flags (one per observation)."""
        previous, current, newly_valid = self._valid.get(antenna, {}), {}, []
        for o in raw.obs:
            was_valid = current.get(o.sat_id, previous.get(o.sat_id, False))
            newly_valid.append(o.half_cycle_valid and not was_valid)
            current[o.sat_id] = o.half_cycle_valid
        self._valid[antenna] = current
        return [bool(a or b) for a, b in zip(slipped, newly_valid)]


__all__ = ["HalfCycleTracker", "LockTracker"]
