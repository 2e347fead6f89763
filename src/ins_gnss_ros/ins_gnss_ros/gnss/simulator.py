"""GNSS raw-measurement simulator: pseudorange, Doppler, carrier phase, C/N0 and lock state of
every antenna of a vehicle moving along a truth trajectory, from real broadcast orbits.

Observation model of antenna a, satellite i, carrier wavelength λ (seed 004 §2.4; Groves,
"Principles of GNSS, Inertial and Multisensor Integrated Navigation", 2nd ed., §8.5 and ch. 9;
RINEX signs: phase grows with range, Doppler positive when the satellite approaches):

    P   = ρ + c δt_r - c (δt^i - T_GD,i) + I + T + m_P + ε_P                    [m]
    φ   = (ρ + c δt_r - c δt^i - I + T + m_φ + ε_φ) / λ + N + h                [cycles]
    D   = -(ρ̇ + c δṫ_r - c δṫ^i - İ + Ṫ) / λ + ε_D                            [Hz]

* ρ: geometric range from the satellite at transmission to the antenna at reception, with the
  light time solved exactly and the satellite expressed in the ECEF frame of reception (Sagnac,
  Groves eq. 8.36); ρ̇ its exact time derivative (module function :func:`range_rate`).
* δt^i, δṫ^i: broadcast satellite clock with relativity (IS-GPS-200 §20.3.3.3.3.1), T_GD,i the
  group delay of the signal (§20.3.3.3.3.2; Galileo BGD). The code carries the group delay,
  the phase does not.
* δt_r: receiver clock (:mod:`clock_model`, the seed's offset + drift random walk, steering
  disabled); antennas share it (one receiver) or have one each.
* I: Klobuchar ionosphere at the signal's frequency (IS-GPS-200 §20.3.3.5.2.5), a delay on the
  code and an advance on the phase; T: Saastamoinen troposphere (:mod:`atmosphere`); their
  rates in D by central differences over ±0.5 s of geometry.
* with ``SimulatorConfig.residuals`` the truth is not the broadcast models: the ionosphere and
  troposphere differ from Klobuchar and Saastamoinen and each satellite's range carries an
  orbit + clock error (SISRE) the broadcast ephemeris does not have, by the residuals real
  receivers see (:mod:`broadcast_residuals`); without it the receiver's models are exact.
* m: multipath (:mod:`multipath`); ε: white noise of σ² = a² + b²/sin²E
  (:func:`ins_gnss_ros.gnss.differences.elevation_sigma`), code, phase and Doppler.
* N: integer ambiguity per antenna and satellite, drawn at each (re)acquisition and changed by
  cycle slips; h: half a cycle until the half-cycle ambiguity is resolved, on data channels only
  (:data:`SIGNALS`).

The receiver tags an epoch with its own clock: time of week = true GPS time + δt_r, so
``RawEpoch.t_gps`` is what a real receiver reports and the SPP of the pseudoranges returns
c δt_r as its clock estimate. Signals: GPS L1 C/A and Galileo E1-C (RINEX "1C", same carrier).

Half-cycle ambiguity. A receiver tracking a channel that carries navigation data uses a Costas
loop, which is insensitive to the data bit sign and so locks on either of two carrier phases
half a cycle apart; the phase is reported valid once the sign is known from the polarity of the
message preamble. GPS L1 C/A carries the 50 bit/s LNAV message whose 6 s subframes each begin
with the 8-bit TLM preamble (IS-GPS-200, §20.3.2 and §20.3.3.1), so the half cycle is resolved
within one subframe of lock: ``SimulatorConfig.half_cycle_resolve_s`` (6 s) of lock time. A
pilot channel carries no data (only a known secondary code, acquired with the primary code), so
a pure PLL tracks it with no half-cycle ambiguity and the phase is valid from lock: Galileo E1
is tracked on its pilot E1-C (Galileo OS SIS ICD, Issue 2.0, §2.3 and §3.4: E1-C is the
data-free component with the 25-chip secondary code CS25_1), as are GPS L1C-P, L2C CL and L5-Q
and BeiDou B1C and B2a pilots; u-blox receivers set the RXM-RAWX trkStat halfCyc bit at once
for pilot-tracked signals.

Masking: elevation mask, outage windows (nothing tracked) and shading windows that keep at
most ``max_satellites`` of the receiver's satellites: the highest ones at the window's first
epoch, kept while they stay above the mask (the seeds' constellation ablation, seed 004 §2.13).
A satellite lost and regained is reacquired: new ambiguity, lock time from zero, loss-of-lock
flag set, multipath restarted.

Seeded: the same configuration, seed and trajectory give identical output.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from ..nav.earth import ecef_to_enu_matrix, geodetic_to_ecef
from ..nav.lever_arm import lever_arm_position, lever_arm_velocity
from .atmosphere import klobuchar_delay, tropo_delay
from .broadcast_residuals import BroadcastResiduals, ResidualDraw
from .clock_model import TCXO, OscillatorSpec, ReceiverClock
from .constants import C_LIGHT, FREQ_E1, FREQ_L1, GALILEO, GPS, OMEGA_E
from .differences import NoiseModel, elevation_sigma
from .ephemeris import earth_rotation_correction, elevation_azimuth, group_delay, sat_position
from .ephemeris_data import BroadcastSet
from .multipath import MultipathModel, MultipathProcess
from .observations import RawEpoch, SatObs
from .spp import SppConfig, solve_position, solve_velocity
from .time import leap_seconds, gps_to_utc, week_tow

#: Step of the central differences giving the ionosphere and troposphere rates [s].
_ATMOSPHERE_RATE_STEP = 0.5


@dataclass(frozen=True)
class SimSignal:
    """A simulated signal: RINEX 3 observation code, carrier [Hz] and whether the receiver
    tracks a data channel (half-cycle ambiguity until the preamble is found) or a pilot."""

    code: str
    frequency: float
    data_channel: bool


#: Simulated signal per system (module docstring: GPS L1 C/A is a data channel, Galileo E1-C
#: a pilot).
SIGNALS = {GPS: SimSignal("1C", FREQ_L1, data_channel=True),
           GALILEO: SimSignal("1C", FREQ_E1, data_channel=False)}


@dataclass(frozen=True)
class SlipEvent:
    """A cycle slip injected between the epoch before ``t`` and the epoch at or after it.

    Attributes
    ----------
    t : float
        Time on the trajectory's axis [s].
    sat_id : str
        e.g. "G10".
    cycles : int
        Integer jump of the ambiguity.
    antenna : int or None
        Antenna index; None slips every antenna.
    """

    t: float
    sat_id: str
    cycles: int
    antenna: int | None = None


@dataclass(frozen=True)
class SimulatorConfig:
    """Settings of :class:`GnssSimulator` (SI units, angles in rad, lever arms base_link FLU).

    Attributes
    ----------
    lever_arms : tuple of (3,) tuples
        Antenna phase centres relative to the trajectory's reference point [m], 1 to 4.
    shared_clock : bool
        True: all antennas on one receiver (one clock); False: one receiver per antenna.
    systems : tuple of str
        Simulated systems ("G", "E").
    elevation_mask : float
    noise : NoiseModel
        White code and phase noise, σ² = a² + b²/sin²E [m].
    doppler_sigma : (float, float)
        Doppler white noise (a, b) of the same elevation form [Hz].
    multipath : MultipathModel or None
    ionosphere, troposphere : bool
        Apply the delays (for closed-loop checks).
    residuals : BroadcastResiduals or None
        How far the truth is from the broadcast models the receiver uses (None: not at all).
    oscillator : OscillatorSpec
    cn0_zenith, cn0_horizon : float
        C/N0 at 90 and 0 deg elevation [dB-Hz], linear in sin E in between.
    slips : tuple of SlipEvent
    slip_rate : float
        Random cycle slips per satellite-antenna per second (jump 1..5 cycles, random sign).
    half_cycle_resolve_s : float
        Lock time after which the half-cycle ambiguity of a data-channel signal (GPS L1 C/A)
        is resolved [s] (0: never present). Pilot-channel signals (Galileo E1-C) have none.
    shading : tuple of ShadingWindow
        (:class:`ins_gnss_ros.sim.scenarios.ShadingWindow`; times on the trajectory's axis).
    outages : tuple of (float, float)
        Windows without any signal [s].
    seed : int
    """

    lever_arms: tuple = ((0.0, 0.0, 0.0),)
    shared_clock: bool = True
    systems: tuple = (GPS, GALILEO)
    elevation_mask: float = math.radians(10.0)
    noise: NoiseModel = NoiseModel()
    doppler_sigma: tuple = (0.02, 0.02)
    multipath: MultipathModel | None = MultipathModel()
    ionosphere: bool = True
    troposphere: bool = True
    residuals: BroadcastResiduals | None = None
    oscillator: OscillatorSpec = TCXO
    cn0_zenith: float = 48.0
    cn0_horizon: float = 34.0
    slips: tuple = ()
    slip_rate: float = 0.0
    half_cycle_resolve_s: float = 6.0
    shading: tuple = ()
    outages: tuple = ()
    seed: int = 0


@dataclass
class AntennaTruth:
    """Position and velocity of one antenna at one epoch (ECEF, geodetic)."""

    xyz: np.ndarray
    vel: np.ndarray
    lat: float
    lon: float
    h: float


@dataclass
class SignalTruth:
    """The terms of every simulated signal of one epoch, aligned with ``RawEpoch.obs``.

    All arrays shape (n,): range (ρ incl. Sagnac) [m], range_rate [m/s], sat_clock (c δt^i, the
    true one: minus the orbit + clock residual of ``SimulatorConfig.residuals``) [m],
    group_delay (c T_GD) [m], iono, tropo [m] (at the signal's frequency), multipath_code,
    multipath_phase, noise_code, noise_phase [m], ambiguity (N + h) [cycles], elevation,
    azimuth [rad], los_enu (n, 3) unit line of sight antenna -> satellite.
    """

    range: np.ndarray
    range_rate: np.ndarray
    sat_clock: np.ndarray
    group_delay: np.ndarray
    iono: np.ndarray
    tropo: np.ndarray
    multipath_code: np.ndarray
    multipath_phase: np.ndarray
    noise_code: np.ndarray
    noise_phase: np.ndarray
    ambiguity: np.ndarray
    elevation: np.ndarray
    azimuth: np.ndarray
    los_enu: np.ndarray


@dataclass
class SimEpoch:
    """Everything one antenna's receiver reports at one epoch, with the truth behind it.

    Attributes
    ----------
    t : float
        Epoch on the trajectory's time axis [s].
    t_gps : float
        True GPS time of the epoch [s].
    antenna : int
    raw : RawEpoch
        Receiver-time-tagged observations (what a receiver outputs).
    loss_of_lock : ndarray of bool
        Per observation: the ambiguity may differ from the previous epoch's (slip, reacquisition).
    clock : ndarray, shape (3,)
        Receiver clock offset [m], drift [m/s], drift rate [m/s²].
    antenna_truth : AntennaTruth
    truth : SignalTruth
    """

    t: float
    t_gps: float
    antenna: int
    raw: RawEpoch
    loss_of_lock: np.ndarray
    clock: np.ndarray
    antenna_truth: AntennaTruth
    truth: SignalTruth


@dataclass
class _Channel:
    """Tracking state of one (antenna, satellite)."""

    ambiguity: int
    half: float
    acquired_t: float
    lock_t: float
    slipped: bool = True


def light_time(eph, t_rx: float, rx_xyz: np.ndarray, tau0: float = 0.075, iterations: int = 4):
    """Satellite state at transmission for a signal received at true GPS time ``t_rx``.

    Solves c τ = |R(ω_e τ) r^i(t_rx - τ) - r_rx| by fixed-point iteration (each step gains the
    factor |v^i|/c ≈ 1e-5: four steps from 75 ms, two from a nearby antenna's τ, reach 1e-15 s).

    Returns
    -------
    xyz, vel : ndarray (3,)
        Satellite position and velocity in the ECEF frame of reception [m, m/s].
    tau : float
        Signal travel time [s] (c τ = geometric range).
    clock, clock_drift : float
        Satellite clock offset [s] and drift [s/s] at transmission.
    """
    tau = tau0
    for _ in range(iterations):
        pos, clock, vel, drift = sat_position(eph, t_rx - tau)
        xyz, vel_rx = earth_rotation_correction(pos, vel, tau)
        tau = float(np.linalg.norm(xyz - rx_xyz)) / C_LIGHT
    return xyz, vel_rx, tau, clock, drift


def range_rate(sat_xyz, sat_vel, rx_xyz, rx_vel) -> float:
    """Exact time derivative of the light-time range ρ(t) = |R(ω_e τ) r^i(t - τ) - r_rx(t)|.

    With g = R r^i - r_rx, u = g/ρ and τ̇ = ρ̇/c:
    ġ = R v^i (1 - τ̇) + ω_e τ̇ (dR/dθ) r^i - v_rx, so ρ̇ = u·ġ solves to

        ρ̇ = u·(R v^i - v_rx) / (1 + u·(R v^i - ω_e R' r^i)/c),

    R' r^i = [y, -x, 0] of the rotated position (dR/dθ R^T = [[0, 1, 0], [-1, 0, 0], 0]).
    The denominator changes ρ̇ by up to 1 cm/s, more than Doppler noise.
    """
    g = np.asarray(sat_xyz) - np.asarray(rx_xyz)
    u = g / np.linalg.norm(g)
    rotated_derivative = np.array([sat_xyz[1], -sat_xyz[0], 0.0])
    numerator = u @ (np.asarray(sat_vel) - np.asarray(rx_vel))
    return float(numerator / (1.0 + u @ (np.asarray(sat_vel) - OMEGA_E * rotated_derivative)
                              / C_LIGHT))


def antenna_truth(lat, lon, h, v_enu, q_nb, omega_ib_b, lever_arm) -> AntennaTruth:
    """Position and Earth-relative velocity of an antenna at ``lever_arm`` (FLU) [m]
    (:mod:`ins_gnss_ros.nav.lever_arm`), in ECEF and geodetic coordinates."""
    lever = np.asarray(lever_arm, float)
    a_lat, a_lon, a_h = lever_arm_position(lat, lon, h, q_nb, lever)
    v = lever_arm_velocity(v_enu, q_nb, omega_ib_b, lever, lat)
    rot = ecef_to_enu_matrix(a_lat, a_lon)
    return AntennaTruth(geodetic_to_ecef(a_lat, a_lon, a_h), rot.T @ v, float(a_lat),
                        float(a_lon), float(a_h))


class GnssSimulator:
    """Stateful simulator: call :meth:`epoch` with the truth at ascending times.

    Parameters
    ----------
    broadcast : BroadcastSet
        Orbits and ionosphere coefficients (``ephemeris_data.load(longitude)``); its
        ephemerides are both the truth and what the receiver broadcasts.
    config : SimulatorConfig
    start_gps : float
        GPS time [s] of trajectory time ``t0``.
    t0 : float
        Trajectory time [s] that maps onto ``start_gps``.
    """

    def __init__(self, broadcast: BroadcastSet, config: SimulatorConfig = SimulatorConfig(),
                 start_gps: float | None = None, t0: float = 0.0):
        if not 1 <= len(config.lever_arms) <= 4:
            raise ValueError("1 to 4 antennas are supported")
        self.broadcast = broadcast
        self.config = config
        self.ephemerides = {k: e for k, e in broadcast.ephemerides.items()
                            if not e.health and e.system in config.systems}
        self.start_gps = default_start(broadcast) if start_gps is None else start_gps
        self.t0 = t0
        seeds = np.random.SeedSequence(config.seed).spawn(5)  # the first 4 as with spawn(4)
        n_clocks = 1 if config.shared_clock else len(config.lever_arms)
        self.clocks = [ReceiverClock(config.oscillator, np.random.default_rng(s))
                       for s in seeds[0].spawn(n_clocks)]
        self.rng = np.random.default_rng(seeds[1])          # noise, slips
        self.rng_ambiguity = np.random.default_rng(seeds[2])
        self.multipath = (MultipathProcess(config.multipath, np.random.default_rng(seeds[3]))
                          if config.multipath is not None else None)
        self.residuals = (ResidualDraw(config.residuals, np.random.default_rng(seeds[4]))
                          if config.residuals is not None else None)
        self.channels: dict = {}
        self._shade = {}       # index of the shading window -> kept sat_ids
        self.t_prev = None

    # -- time --------------------------------------------------------------------------------
    def gps_time(self, t: float) -> float:
        """True GPS time [s] of trajectory time ``t``."""
        return self.start_gps + (t - self.t0)

    # -- visibility --------------------------------------------------------------------------
    def _tracked(self, t, elevations) -> set:
        """Satellites tracked at ``t`` given their elevations (sat_id -> rad) at antenna 0."""
        if any(a <= t < b for a, b in self.config.outages):
            return set()
        visible = {s for s, el in elevations.items() if el >= self.config.elevation_mask}
        for k, window in enumerate(self.config.shading):
            if window.t_start <= t < window.t_end:
                if k not in self._shade:
                    ranked = sorted(visible, key=lambda s: -elevations[s])
                    self._shade[k] = set(ranked[:window.max_satellites])
                visible &= self._shade[k]
        return visible

    # -- one epoch ---------------------------------------------------------------------------
    def epoch(self, t, lat, lon, h, v_enu, q_nb, omega_ib_b=(0.0, 0.0, 0.0)) -> list:
        """Observations of every antenna at trajectory time ``t``.

        Parameters
        ----------
        t : float
            Epoch [s], after the previous call's.
        lat, lon, h : float
            Reference point (IMU) geodetic position [rad, rad, m].
        v_enu : array_like (3,)
            Its velocity [m/s].
        q_nb : array_like (4,)
            Attitude ENU <- FLU.
        omega_ib_b : array_like (3,)
            Body rate [rad/s] (moves the antennas through the lever arms).

        Returns
        -------
        list of SimEpoch, one per antenna.
        """
        cfg = self.config
        if self.t_prev is not None and t <= self.t_prev:
            raise ValueError(f"epoch {t} is not after the previous one {self.t_prev}")
        t_gps = self.gps_time(t)
        antennas = [antenna_truth(lat, lon, h, np.asarray(v_enu, float), np.asarray(q_nb, float),
                                  np.asarray(omega_ib_b, float), arm) for arm in cfg.lever_arms]
        clocks = [c.advance(t).copy() for c in self.clocks]

        # Satellite states at antenna 0 decide visibility (one receiver tracks one set).
        ref = {s: light_time(e, t_gps, antennas[0].xyz) for s, e in self.ephemerides.items()}
        elevations = {s: elevation_azimuth(antennas[0].xyz, r[0])[0] for s, r in ref.items()}
        tracked = self._tracked(t, elevations)
        self._drop_lost(tracked)
        out = [self._antenna_epoch(t, t_gps, a, ant, clocks[0 if cfg.shared_clock else a],
                                   sorted(tracked), ref)
               for a, ant in enumerate(antennas)]
        self.t_prev = t
        return out

    def _drop_lost(self, tracked):
        for key in [k for k in self.channels if k[1] not in tracked]:
            del self.channels[key]
            if self.multipath is not None:
                self.multipath.reset(key)

    def _half_cycle_resolve_s(self, signal: SimSignal) -> float:
        """Lock time until the half-cycle ambiguity of ``signal`` is resolved [s], 0 if it has
        none (a pilot channel, module docstring)."""
        return self.config.half_cycle_resolve_s if signal.data_channel else 0.0

    def _channel(self, key, t, signal: SimSignal) -> _Channel:
        """The tracking state of (antenna, sat), acquiring it if new; applies the slips."""
        cfg = self.config
        ch = self.channels.get(key)
        if ch is None:
            half = (0.5 * self.rng_ambiguity.integers(0, 2)
                    if self._half_cycle_resolve_s(signal) > 0 else 0.0)
            ch = _Channel(int(self.rng_ambiguity.integers(-10 ** 6, 10 ** 6)), half, t, t)
            self.channels[key] = ch
            return ch
        ch.slipped = False
        antenna, sat_id = key
        jump = sum(ev.cycles for ev in cfg.slips
                   if ev.sat_id == sat_id and ev.antenna in (None, antenna)
                   and self.t_prev < ev.t <= t)
        # Poisson slips: probability 1 - exp(-rate dt) of one in the interval.
        p_slip = -math.expm1(-cfg.slip_rate * (t - self.t_prev))
        if cfg.slip_rate > 0.0 and self.rng.uniform() < p_slip:
            jump += int(self.rng.integers(1, 6)) * int(self.rng.choice([-1, 1]))
        if jump:
            ch.ambiguity += jump
            ch.lock_t = t
            ch.slipped = True
        return ch

    def _atmosphere(self, t_gps, ant: AntennaTruth, sat_id, sat_xyz, freq):
        """(ionosphere, troposphere) delays [m] for satellite ``sat_id`` at ``sat_xyz``."""
        el, az = elevation_azimuth(ant.xyz, sat_xyz)
        iono = (klobuchar_delay(t_gps, ant.lat, ant.lon, el, az, *self.broadcast.klobuchar, freq)
                if self.config.ionosphere else 0.0)
        tropo = tropo_delay(ant.lat, ant.h, el) if self.config.troposphere else 0.0
        if self.residuals is not None:
            iono = self.residuals.ionosphere(sat_id, iono)
            # (a disabled troposphere stays 0: the residual scales the model's delay)
            tropo = self.residuals.troposphere(tropo, tropo_delay(ant.lat, ant.h, math.pi / 2))
        return iono, tropo

    def _antenna_epoch(self, t, t_gps, a, ant, clock, sat_ids, ref) -> SimEpoch:
        cfg = self.config
        rot = ecef_to_enu_matrix(ant.lat, ant.lon)
        obs, lol, rows = [], [], []
        for sat_id in sat_ids:
            eph = self.ephemerides[sat_id]
            signal = SIGNALS[eph.system]
            freq = signal.frequency
            lam = C_LIGHT / freq
            sat, sat_vel, tau, sat_clock, sat_drift = light_time(eph, t_gps, ant.xyz,
                                                                 tau0=ref[sat_id][2], iterations=2)
            rho = C_LIGHT * tau
            rho_dot = range_rate(sat, sat_vel, ant.xyz, ant.vel)
            el, az = elevation_azimuth(ant.xyz, sat)
            iono, tropo = self._atmosphere(t_gps, ant, sat_id, sat, freq)
            step = _ATMOSPHERE_RATE_STEP
            after = self._atmosphere(t_gps + step, ant, sat_id, sat + sat_vel * step, freq)
            before = self._atmosphere(t_gps - step, ant, sat_id, sat - sat_vel * step, freq)
            iono_rate, tropo_rate = (np.subtract(after, before) / (2 * step)).tolist()
            gd = C_LIGHT * group_delay(eph, freq)
            key = (a, sat_id)
            ch = self._channel(key, t, signal)
            mp_code, mp_phase = (self.multipath.step(key, t, el) if self.multipath is not None
                                 else (0.0, 0.0))
            sig_code = float(elevation_sigma(el, cfg.noise.code_a, cfg.noise.code_b))
            sig_phase = float(elevation_sigma(el, cfg.noise.phase_a, cfg.noise.phase_b))
            sig_dop = float(elevation_sigma(el, *cfg.doppler_sigma))
            e_code, e_phase, e_dop = self.rng.standard_normal(3) * (sig_code, sig_phase, sig_dop)

            lock = t - ch.lock_t
            resolved = t - ch.acquired_t >= self._half_cycle_resolve_s(signal)
            ambiguity = ch.ambiguity + (0.0 if resolved else ch.half)
            # what the broadcast orbit and clock miss, as a true satellite clock (the same on
            # code and phase)
            orbit, orbit_rate = (self.residuals.orbit_clock(sat_id, t_gps)
                                 if self.residuals is not None else (0.0, 0.0))
            sat_clock_m = C_LIGHT * sat_clock - orbit
            sat_drift_mps = C_LIGHT * sat_drift - orbit_rate
            common = rho + clock[0] - sat_clock_m + tropo
            pseudorange = common + gd + iono + mp_code + e_code
            phase = (common - iono + mp_phase + e_phase) / lam + ambiguity
            doppler = (-(rho_dot + clock[1] - sat_drift_mps - iono_rate + tropo_rate) / lam
                       + e_dop)
            mp_sigma = (cfg.multipath.sigma(el) if cfg.multipath is not None else (0.0, 0.0))
            cn0 = cfg.cn0_horizon + (cfg.cn0_zenith - cfg.cn0_horizon) * max(math.sin(el), 0.0)
            obs.append(SatObs(
                eph.system, eph.prn, 0, signal.code, freq, pseudorange, doppler, phase, cn0,
                lock * 1000.0, math.hypot(sig_code, mp_sigma[0]),
                math.hypot(sig_phase, mp_sigma[1]) / lam, sig_dop,
                half_cycle_valid=resolved,
                half_cycle_subtracted=bool(resolved and ch.half)))
            lol.append(ch.slipped)
            los = rot @ (sat - ant.xyz)
            rows.append((rho, rho_dot, sat_clock_m, gd, iono, tropo, mp_code, mp_phase,
                         e_code, e_phase, ambiguity, el, az, *(los / np.linalg.norm(los))))
        cols = np.array(rows, float).reshape(len(rows), 16).T
        truth = SignalTruth(*cols[:13], los_enu=cols[13:].T.copy())
        week, tow = week_tow(t_gps + clock[0] / C_LIGHT)
        leap = leap_seconds(gps_to_utc(t_gps, 18))
        raw = RawEpoch(week, tow, leap, True, False, obs)
        return SimEpoch(t, t_gps, a, raw, np.array(lol, bool), clock, ant, truth)

    # -- whole trajectories ------------------------------------------------------------------
    def run(self, traj, rate: float) -> list:
        """Simulate a :class:`ins_gnss_ros.sim.trajectory.Trajectory` at ``rate`` Hz (a divisor
        of the trajectory's rate). Returns a list (per epoch) of lists (per antenna) of SimEpoch.
        """
        factor = int(round(1.0 / (traj.dt * rate)))
        if factor < 1 or abs(factor * traj.dt * rate - 1.0) > 1e-9:
            raise ValueError(f"{rate} Hz does not divide the trajectory rate {1.0 / traj.dt:g} Hz")
        return [self.epoch(traj.t[k], traj.lat[k], traj.lon[k], traj.h[k], traj.v_enu[k],
                           traj.q_nb[k], traj.omega_ib_b[k])
                for k in range(0, len(traj), factor)]


def default_start(broadcast: BroadcastSet) -> float:
    """Default GPS time of the trajectory's start: one hour before the recording, on a whole
    minute. With the orbits rotated to the scenario's longitude (`ephemeris_data.load`) 8-10 of
    the 10 healthy satellites stand above 10 deg at 60 deg N for the following 1.5 h; the
    broadcast fit intervals (± 2 h around toe) hold until ``broadcast.validity()[1]``. Later
    epochs use the Keplerian model beyond its fit interval: still a consistent orbit for the
    simulation (the receiver is given the same ephemerides), only less like the real satellite's.
    """
    return math.floor(broadcast.t_first / 60.0) * 60.0 - 3600.0


@dataclass
class Fix:
    """Receiver position-velocity solution of one epoch (SPP of the simulated pseudoranges).

    Attributes
    ----------
    t : float
        Epoch on the trajectory's axis [s].
    lat, lon, h : float
        [rad, rad, m] of the antenna.
    xyz : ndarray (3,)
        The same position in ECEF [m].
    covariance_enu : ndarray (3, 3)
        [m²] (weights σ0/sin E, σ0 the configured zenith code σ; with
        ``SimulatorConfig.residuals`` their budget added: spp.ModelErrors).
    vel_enu : ndarray (3,)
        [m/s] from the Doppler; NaN when not solved.
    vel_covariance_enu : ndarray (3, 3)
    n_used : int
    pdop : float
    clock_m : dict
        Per-system receiver clock estimate [m].
    """

    t: float
    lat: float
    lon: float
    h: float
    xyz: np.ndarray
    covariance_enu: np.ndarray
    vel_enu: np.ndarray
    vel_covariance_enu: np.ndarray
    n_used: int
    pdop: float
    clock_m: dict = field(default_factory=dict)


def solve_fix(sim_epoch: SimEpoch, simulator: GnssSimulator, x0=None) -> Fix | None:
    """Single-point position and Doppler velocity from one antenna's simulated epoch, with the
    project's SPP (:mod:`spp`, Klobuchar and Saastamoinen corrections as simulated); ``x0`` an
    initial ECEF position [m] (e.g. the previous fix), the Earth's centre when None.

    Returns None when fewer satellites than unknowns are tracked (shading, outages).
    """
    cfg = simulator.config
    sigma0 = math.hypot(cfg.noise.code_a, cfg.noise.code_b)
    doppler0 = math.hypot(*cfg.doppler_sigma)
    # With residuals the receiver's covariance carries their budget, as a real receiver's
    # accuracy estimate does (without, 0.55 m was reported for 2.3 m of error).
    spp = SppConfig(elevation_mask=cfg.elevation_mask, iono_free=False,
                    klobuchar=simulator.broadcast.klobuchar if cfg.ionosphere else None,
                    sigma0=sigma0, model_errors=cfg.residuals.model_errors()
                    if cfg.residuals is not None else None)
    sol = solve_position(sim_epoch.raw, simulator.ephemerides, spp, x0)
    if sol is None:
        return None
    vel = solve_velocity(sim_epoch.raw, simulator.ephemerides, sol, spp, doppler0)
    vel_enu, vel_cov = (vel[0], vel[2]) if vel is not None else (np.full(3, np.nan),
                                                                  np.full((3, 3), np.nan))
    return Fix(sim_epoch.t, sol.lat, sol.lon, sol.h, sol.xyz, sol.covariance_enu, vel_enu, vel_cov,
               len(sol.used), sol.dop["pdop"], sol.clock_m)


def time_reference(sim_epoch: SimEpoch, sigma_s: float, rng: np.random.Generator):
    """PPS time reference of an epoch: (trajectory time [s], GPS time of the pulse [s]).

    The receiver aligns its pulse to GNSS time through its own time solution: the pulse
    carries white noise of ``sigma_s`` [s] (seed 004 quotes 20 ns static, 50 ns moving).
    """
    return sim_epoch.t, sim_epoch.t_gps + sigma_s * rng.standard_normal()


__all__ = ["AntennaTruth", "Fix", "GnssSimulator", "SIGNALS", "SignalTruth", "SimEpoch",
           "SimSignal", "SimulatorConfig", "SlipEvent", "antenna_truth", "default_start",
           "light_time", "range_rate", "solve_fix", "time_reference"]
