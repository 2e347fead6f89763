"""Heading, pitch (and roll) from carrier-phase differences between 2-4 antennas, epoch by epoch
(seed 004 §1.3b-c and §2.7, the ISON-1/ISON-2 interferometric attitude): the pipeline around
the phase-attitude core :class:`~.attitude.AttitudeSolver`.

Per GNSS epoch :class:`PhaseHeading`

1. groups the observations of all antennas by GNSS time (receiver week + time of week, within
   ``epoch_tolerance``): an epoch is solved once every antenna has reported, or skipped when a
   later epoch completes first or it is older than ``max_latency`` behind the newest
   observation; late and duplicated observations are dropped;
2. computes every satellite's line of sight (ENU) from the broadcast ephemeris
   (IS-GPS-200 Table 20-IV via :mod:`.ephemeris`) at the master antenna's position: the INS or
   a GNSS fix when fresh, else the single-point solution of the master antenna's own
   pseudoranges (:mod:`.spp`); a position error of 1 km tilts a line of sight by only 5e-5 rad,
   so any of them will do;
3. runs the core with the INS attitude as an a-priori baseline when the INS is recent and its
   heading known (seed 004's tightly-coupled phase processing: it shrinks the ambiguity
   search), or only its roll and pitch, as an a-priori up component of the baselines, while
   the INS heading is not known (the INS levelled but ALIGNING, the filter ALIGNING or its
   heading σ above the prior's, or the heading prior switched off): an INS levels itself from
   its accelerometers in seconds, and the up component removes the weak vertical of the GNSS
   geometry from the search, where wrong candidates from few double differences hide;
4. takes a FIXED attitude with pitch or roll beyond ``max_tilt`` as a wrong fix: the
   ambiguities are dropped and the epoch gives nothing usable.

Whatever makes an epoch unusable is said through the ``report`` callback (one short sentence
each, for diagnostics).
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, Callable

import numpy as np

from ..nav.earth import ecef_to_enu_matrix, ecef_to_geodetic, geodetic_to_ecef
from ..nav.rotations import quat_normalize, quat_to_dcm
from .attitude import AttitudeSolution, AttitudeSolver
from .constants import C_LIGHT, FIT_HALF_WIDTH_S, SECONDS_PER_WEEK
from .differences import AntennaEpoch
from .ephemeris import KeplerEphemeris, satellite_at_reception
from .observations import RawEpoch
from .spp import DEFAULT_SIGNALS, SppConfig, solve_position

#: Nominal signal travel time when the master antenna has no pseudorange for a satellite [s].
NOMINAL_TRAVEL_S = 0.075


@dataclass
class ParsedEpoch:
    """One antenna's observations of the used systems, as the core and the SPP take them."""

    antenna: AntennaEpoch
    raw: RawEpoch


def signal_id(sat_id: str, code: str) -> str:
    """Core signal id: the satellite id for the system's primary signal (the one the SPP uses),
    else satellite id + RINEX code ("G05", "G05_2L")."""
    return sat_id if code == DEFAULT_SIGNALS.get(sat_id[0], ("",))[0] else f"{sat_id}_{code}"


def parsed_epoch(raw: RawEpoch, loss_of_lock) -> ParsedEpoch:
    """The phase core's AntennaEpoch of a RawEpoch whose signals have the receiver's
    ``loss_of_lock`` flags (one per observation)."""
    obs = raw.obs
    ids = [signal_id(f"{o.system}{o.prn:02d}", o.signal) for o in obs]
    return ParsedEpoch(AntennaEpoch(
        ids, np.array([o.carrier_cycles for o in obs]), np.array([o.pseudorange_m for o in obs]),
        np.array([C_LIGHT / o.frequency_hz for o in obs]), np.array([o.doppler_hz for o in obs]),
        np.array(loss_of_lock, bool)), raw)


def lines_of_sight(master: ParsedEpoch, ephemerides: dict, t_gps: float, rx_xyz) -> dict:
    """Unit line of sight (ENU at ``rx_xyz``, ECEF m) to the satellite of every master signal
    with an ephemeris, keyed by signal id. The satellite is taken at transmission, in the ECEF
    frame of reception (Sagnac, Groves eq. 8.36), from the master's pseudorange."""
    rx = np.asarray(rx_xyz, float)
    lat, lon, _ = ecef_to_geodetic(rx)
    rot = ecef_to_enu_matrix(lat, lon)
    out, per_sat = {}, {}
    for sid, pr in zip(master.antenna.signal_ids, master.antenna.pseudorange):
        sat = sid[:3]
        eph = ephemerides.get(sat)
        if eph is None:
            continue
        if sat not in per_sat:
            rng = pr if np.isfinite(pr) else NOMINAL_TRAVEL_S * C_LIGHT
            xyz = satellite_at_reception(eph, t_gps, rng, rx)[0]
            e = rot @ (xyz - rx)
            per_sat[sat] = e / np.linalg.norm(e)
        out[sid] = per_sat[sat]
    return out


@dataclass(frozen=True)
class AntennaObservations:
    """One antenna's observations at one epoch, as :meth:`PhaseHeading.add` takes them.

    Attributes
    ----------
    antenna_id : int
        Index of the antenna (0: the master).
    t_gnss : float
        Receiver time tag [GPS s] (week and time of week).
    t : float
        Stamp [s] (UTC POSIX, the axis of the INS and fix times).
    epoch : ParsedEpoch or None
        The observations; None when they could not be read (the epoch is then skipped).
    clock_reset : bool
        The receiver reset its clock (the phase is discontinuous).
    tag : Any
        The caller's stamp, handed back with the epoch.
    """

    antenna_id: int
    t_gnss: float
    t: float
    epoch: ParsedEpoch | None
    clock_reset: bool
    tag: Any = None


@dataclass
class Epoch:
    """The observations of one GNSS epoch (antenna id -> AntennaObservations)."""

    t_gnss: float
    antennas: dict

    @property
    def tag(self):
        """The master's tag (another antenna's when the master is missing)."""
        return (self.antennas.get(0) or next(iter(self.antennas.values()))).tag


@dataclass(frozen=True)
class PhaseHeadingConfig:
    """Settings of :class:`PhaseHeading` (times [s], angles [rad]).

    Attributes
    ----------
    epoch_tolerance : float
        Observations of different antennas within this of each other are one epoch.
    max_latency : float
        An epoch still missing an antenna this long after the newest observation is skipped.
    position_max_age : float
        An INS or fix position older than this is not used for the lines of sight.
    elevation_mask : float
        Of the single-point solution.
    max_tilt : float
        Largest pitch and roll the platform can have; a FIXED attitude beyond is a wrong fix.
    prior : bool
        Use the INS attitude as a prior of the ambiguity search.
    prior_sigma : float
        1-sigma attitude error assumed for the INS.
    prior_heading : bool
        Use the INS heading too when it is known (else roll and pitch only).
    prior_tilt_sigma : float
        1-sigma roll and pitch error assumed when only the tilt is used (a larger one from the
        filter is taken instead).
    prior_max_age : float
        Largest stamp difference between an epoch and the INS attitude used.
    """

    epoch_tolerance: float = 0.005
    max_latency: float = 0.5
    position_max_age: float = 30.0
    elevation_mask: float = math.radians(10.0)
    max_tilt: float = math.radians(40.0)
    prior: bool = True
    prior_sigma: float = math.radians(2.0)
    prior_heading: bool = True
    prior_tilt_sigma: float = math.radians(0.5)
    prior_max_age: float = 0.2


class PhaseHeading:
    """Phase-difference attitude of 2-4 antennas from their observations, the broadcast
    ephemerides and, when available, the INS, a GNSS fix and the filter's attitude accuracy.

    Parameters
    ----------
    solver : AttitudeSolver
        The core, set up with the antennas in base_link.
    n_antennas : int
        Antennas whose observations make an epoch.
    config : PhaseHeadingConfig
    report : callable, optional
        ``report(what)`` for every observation dropped and epoch skipped, and why.
    """

    def __init__(self, solver: AttitudeSolver, n_antennas: int,
                 config: PhaseHeadingConfig = PhaseHeadingConfig(),
                 report: Callable[[str], None] = lambda what: None):
        self.solver = solver
        self.n_antennas = n_antennas
        self.config = config
        self.report = report
        self.spp = SppConfig(elevation_mask=config.elevation_mask, iono_free=False)
        self.pending: dict[float, dict] = {}     # epoch GNSS time -> {antenna_id: observations}
        self.last_epoch = -math.inf               # GNSS time of the last epoch handed out
        self.newest = -math.inf
        self.broadcast: dict[str, Callable[[float], KeplerEphemeris]] = {}
        self.eph_cache: dict[str, KeplerEphemeris] = {}
        self.position = None        # (stamp s, ECEF xyz m) of the latest position
        self.spp_x0 = None
        self.ins = None             # (stamp s, C_nb, heading known) of the latest INS attitude
        self.filter = None          # (heading known, tilt 1-sigma rad) from the filter
        self.last_solution: AttitudeSolution | None = None

    # -- inputs ---------------------------------------------------------------------------------
    def add_ephemeris(self, sat_id: str, resolve: Callable[[float], KeplerEphemeris]) -> None:
        """A new broadcast ephemeris of ``sat_id``: ``resolve(t_gps)`` gives it with toe and toc
        taken within half a week of ``t_gps`` (broadcast times carry the seconds of week only).
        It is resolved at the first epoch that uses it and again beyond half a week."""
        self.broadcast[sat_id] = resolve
        self.eph_cache.pop(sat_id, None)

    def fix(self, t: float, lat: float, lon: float, h: float) -> None:
        """A GNSS fix of the master antenna (stamp [s], geodetic rad, rad, m); a non-finite one is
        ignored."""
        if all(math.isfinite(v) for v in (lat, lon, h)):
            self.position = (t, geodetic_to_ecef(lat, lon, h))

    def ins_state(self, t: float, lat: float, lon: float, h: float, q_nb, levelled: bool,
                  heading_known: bool) -> bool:
        """The INS solution at stamp ``t`` [s]: position (geodetic rad, rad, m) and attitude
        ``q_nb`` (ENU to FLU body, [w, x, y, z]); its attitude is used when ``levelled``, its
        heading too when ``heading_known``. False (nothing taken) if it is not finite or ``q_nb``
        is far from a unit quaternion."""
        q = np.asarray(q_nb, float)
        if not all(math.isfinite(v) for v in (lat, lon, h, *q)) or np.linalg.norm(q) < 0.5:
            return False
        self.position = (t, geodetic_to_ecef(lat, lon, h))
        if levelled:
            self.ins = (t, quat_to_dcm(quat_normalize(q)), heading_known)
        return True

    def filter_status(self, aligning: bool, att_std) -> None:
        """The filter's view of the INS attitude: whether it is still ALIGNING (as ``ins/state``
        says; either suffices) and its attitude σ (ENU error angles [rad], NaN: unknown)."""
        tilt = max(att_std[0], att_std[1]) if all(math.isfinite(a) for a in att_std[:2]) else 0.0
        # A heading σ larger than the full prior assumes makes that prior overconfident (no σ
        # reported, NaN: trust the mode).
        too_wide = att_std[2] > self.config.prior_sigma
        self.filter = (not aligning and not too_wide, tilt)

    def add(self, obs: AntennaObservations) -> list[Epoch]:
        """Take one antenna's observations; return the epochs now ready to :meth:`solve`, oldest
        first (complete ones, and incomplete ones given up)."""
        tolerance = self.config.epoch_tolerance
        t = obs.t_gnss
        if not math.isfinite(t) or obs.antenna_id >= self.n_antennas:
            self.report("observations with an unknown antenna_id or time dropped")
            return []
        if t <= self.last_epoch + tolerance:
            self.report("late observations (epoch already handled) dropped")
            return []
        key = next((k for k in self.pending if abs(k - t) <= tolerance), t)
        group = self.pending.setdefault(key, {})
        if obs.antenna_id in group:
            self.report("duplicate observations of an antenna in one epoch dropped")
            return []
        group[obs.antenna_id] = obs
        self.newest = max(self.newest, t)
        complete = [k for k, g in self.pending.items() if len(g) == self.n_antennas]
        horizon = max(max(complete, default=-math.inf), self.newest - self.config.max_latency)
        ready = [Epoch(k, self.pending.pop(k)) for k in sorted(k for k in self.pending
                                                               if k <= horizon)]
        if ready:
            self.last_epoch = ready[-1].t_gnss
        return ready

    # -- one epoch ------------------------------------------------------------------------------
    def solve(self, epoch: Epoch) -> AttitudeSolution:
        """The attitude of one epoch from :meth:`add` (status NONE when it is unusable)."""
        sol = self._solve(epoch.t_gnss, epoch.antennas)
        self.last_solution = sol if sol is not None else AttitudeSolution("NONE")
        return self.last_solution

    def _solve(self, t_gps: float, group: dict) -> AttitudeSolution | None:
        if len(group) < self.n_antennas:
            self.report("epoch without every antenna skipped")
            return None
        parsed = [group[a].epoch for a in range(self.n_antennas)]
        if any(p is None for p in parsed):
            self.report("observations with arrays of unequal length: epoch skipped")
            return None
        if any(group[a].clock_reset for a in group):
            self.report("receiver clock reset: ambiguities dropped")
            self.solver.reset()
        ephemerides = self._ephemerides(t_gps)
        if not ephemerides:
            self.report("no ephemeris yet: epoch skipped")
            return None
        t = group[0].t
        rx = self._receiver_position(t, parsed[0], ephemerides)
        if rx is None:
            self.report("no receiver position for the lines of sight: epoch skipped")
            return None
        los = lines_of_sight(parsed[0], ephemerides, t_gps, rx)
        try:
            sol = self.solver.process([p.antenna for p in parsed], los, t_gps, **self._priors(t))
        except (ValueError, np.linalg.LinAlgError, FloatingPointError) as err:
            # A degenerate geometry the core could not handle: start the ambiguities afresh.
            self.report(f"attitude solver failed: {type(err).__name__}")
            self.solver.reset()
            return None
        tilt = np.nanmax(np.abs([sol.pitch, sol.roll])) if sol.status == "FIXED" else 0.0
        if tilt > self.config.max_tilt:
            # With few double differences a wrong integer set can pass the ratio, residual and
            # length tests and rotate the baseline out of the plane the platform can reach.
            self.report("FIXED attitude beyond max_tilt_deg: wrong fix, ambiguities dropped")
            self.solver.reset()
            return AttitudeSolution("NONE", satellites=sol.satellites, slipped=sol.slipped)
        return sol

    def _ephemerides(self, t_gps: float) -> dict:
        """Healthy ephemerides within their fit interval at ``t_gps``, by satellite id."""
        out = {}
        for sat, resolve in self.broadcast.items():
            eph = self.eph_cache.get(sat)
            if eph is None or abs(eph.toe - t_gps) > SECONDS_PER_WEEK / 2:
                eph = self.eph_cache[sat] = resolve(t_gps)
            if not eph.health and abs(t_gps - eph.toe) <= FIT_HALF_WIDTH_S:
                out[sat] = eph
        return out

    def _receiver_position(self, t: float, master: ParsedEpoch, ephemerides: dict):
        """ECEF position of the master antenna (m), or None."""
        if self.position is not None and abs(t - self.position[0]) <= self.config.position_max_age:
            return self.position[1]
        sol = solve_position(master.raw, ephemerides, self.spp, self.spp_x0)
        if sol is None:
            return None
        self.spp_x0 = sol.xyz
        self.position = (t, sol.xyz)
        return sol.xyz

    def _priors(self, t: float) -> dict:
        """Keyword arguments of the core's ``process``: ``attitude_prior`` when the INS heading
        is known and wanted, else ``tilt_prior``; none without a recent INS attitude."""
        c = self.config
        if not c.prior or self.ins is None or abs(t - self.ins[0]) > c.prior_max_age:
            return {}
        _, C_nb, heading_known = self.ins
        filter_known, filter_tilt = self.filter or (True, 0.0)
        if c.prior_heading and heading_known and filter_known:
            return {"attitude_prior": (C_nb, np.eye(3) * c.prior_sigma ** 2)}
        return {"tilt_prior": (C_nb, max(c.prior_tilt_sigma, filter_tilt))}


__all__ = ["AntennaObservations", "Epoch", "ParsedEpoch", "PhaseHeading", "PhaseHeadingConfig",
           "lines_of_sight", "parsed_epoch", "signal_id"]
