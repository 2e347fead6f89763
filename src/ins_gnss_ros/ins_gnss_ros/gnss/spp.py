"""Single-point positioning (SPP) from raw pseudoranges, with RAIM fault detection and
exclusion, and the receiver velocity from Doppler.

Measurement model (code pseudorange of satellite i, system s; cf. seed 004 §2.4, Groves
"Principles of GNSS, Inertial and Multisensor Integrated Navigation" 2nd ed. §9.4.1):

    P_i = |r_i - r| + c dt_s - c (dt_i - gd_i) + T_i + I_i + e_i

with r_i the satellite position at transmission in the ECEF frame of reception (Sagnac),
dt_s one receiver clock offset per system (absorbs the inter-system time offsets the seed
asks for), dt_i the satellite clock with relativity, gd_i its group delay for the signal
used, T_i Saastamoinen troposphere, I_i Klobuchar ionosphere (or none for the
ionosphere-free combination).  Solved by iterated weighted least squares with weights
1 / sigma_i^2, sigma_i = sigma0 / sin(E_i).

The covariance is that of the weights (noise only) unless ``SppConfig.model_errors`` gives
what the broadcast models leave per satellite (ionosphere after Klobuchar, troposphere after
Saastamoinen, orbit and clock: :class:`ModelErrors`, the error budget receivers put into their
accuracy estimates; RTKLIB's manual, appendix E.6, uses the same terms): the position is still
the noise-weighted one, and its covariance the sandwich (H'WH)^-1 H'W R W H (H'WH)^-1 with R the
noise plus those variances, independent between satellites.

RAIM (Groves §17.4.1, Parkinson & Axelrad 1988): after convergence the weighted sum of
squared residuals is tested against the chi-square threshold for n - m degrees of freedom;
on failure the measurement with the largest normalised residual r_i / sqrt(C_r,ii),
C_r = C_z - H (H' W H)^-1 H', is excluded and the solution repeated, while redundancy
remains.
"""
import math
from dataclasses import dataclass, field

import numpy as np
from scipy.stats import chi2

from ..nav.earth import ecef_to_enu_matrix, ecef_to_geodetic
from .atmosphere import klobuchar_delay, tropo_delay
from .constants import BEIDOU, C_LIGHT, GALILEO, GLONASS, GPS
from .ephemeris import group_delay, satellite_at_reception

#: Signals used per system: (primary, second frequency for the ionosphere-free combination).
#: GPS L1 C/A + L2C (CL), Galileo E1-C + E5a-Q (the receivers of this project track E5a,
#: not E5b), BeiDou B3I (the D1 clock reference) + B1I, GLONASS G1 + G2 C/A.
DEFAULT_SIGNALS = {GPS: ("1C", "2L"), GALILEO: ("1C", "5Q"), BEIDOU: ("6I", "2I"),
                   GLONASS: ("1C", "2C")}


@dataclass(frozen=True)
class ModelErrors:
    """Range errors the broadcast models leave, per satellite (1 sigma).

    Attributes
    ----------
    iono_fraction : float
        Of the Klobuchar delay (single frequency; the ionosphere-free combination has none).
    tropo_zenith : float
        Zenith troposphere after Saastamoinen, m, mapped as the model maps its zenith delay.
    sisre : float
        Broadcast orbit and clock (signal-in-space range error), m.
    """

    iono_fraction: float
    tropo_zenith: float
    sisre: float

    def variance(self, klobuchar_delay: float, tropo_slant: float, tropo_zenith: float) -> float:
        """Their variance for one satellite, m^2 (no troposphere where the model has none:
        above it, or an iteration's position still far from the ground)."""
        tropo = self.tropo_zenith * tropo_slant / tropo_zenith if tropo_zenith > 0.0 else 0.0
        return (self.iono_fraction * klobuchar_delay) ** 2 + tropo ** 2 + self.sisre ** 2


@dataclass
class SppConfig:
    """Settings of `solve_position`.

    Attributes
    ----------
    elevation_mask : float
        Satellites below it are not used [rad].
    iono_free : bool
        Use the dual-frequency ionosphere-free combination (needs both signals); otherwise
        the primary signal with the Klobuchar model (when coefficients are given).
    klobuchar : tuple or None
        (alpha, beta) for single-frequency use; None applies no ionosphere correction.
    sigma0 : float
        Zenith pseudorange noise [m] (multiplied by 3 for the ionosphere-free combination
        through its noise amplification, automatically).
    p_false_alarm : float
        RAIM false-alarm probability of the chi-square test.
    max_exclusions : int
    signals : dict
        System -> (primary, secondary) signal codes.
    model_errors : ModelErrors or None
        What the broadcast models leave, in the solution's covariance (not its weights); None:
        the covariance of the noise alone.
    """

    elevation_mask: float = math.radians(10.0)
    iono_free: bool = True
    klobuchar: tuple = None
    sigma0: float = 1.0
    p_false_alarm: float = 1e-3
    max_exclusions: int = 3
    signals: dict = field(default_factory=lambda: dict(DEFAULT_SIGNALS))
    model_errors: ModelErrors | None = None


@dataclass
class SppSolution:
    """Result of `solve_position`.

    Attributes
    ----------
    t_gps : float  receiver time tag [GPS s] (clock error not removed)
    xyz : ndarray (3,)  ECEF position [m]
    lat, lon, h : float  geodetic position [rad, rad, m]
    clock_m : dict  system -> receiver clock offset [m]
    covariance : ndarray  (3 + n_sys) square covariance of [x, y, z, clocks] [m^2]
    covariance_enu : ndarray (3, 3)  position covariance in ENU [m^2]
    dop : dict  gdop, pdop, hdop, vdop, tdop
    residuals : dict  sat_id -> post-fit residual [m]
    used, excluded : list of sat_id
    chi2, chi2_threshold : float  RAIM test statistic and threshold (NaN without redundancy)
    valid : bool  converged and passed (or had no redundancy for) the RAIM test
    """

    t_gps: float
    xyz: np.ndarray
    lat: float
    lon: float
    h: float
    clock_m: dict
    covariance: np.ndarray
    covariance_enu: np.ndarray
    dop: dict
    residuals: dict
    used: list
    excluded: list
    chi2: float
    chi2_threshold: float
    valid: bool


@dataclass
class _Meas:
    sat_id: str
    system: str
    eph: object
    pseudorange: float
    obs: object  # SatObs of the primary signal (Doppler, frequency)
    group_delay_s: float
    noise_factor: float


def _elevation_azimuth(los_enu):
    """Elevation and azimuth (clockwise from north) of a line of sight given in ENU [rad]."""
    east, north, up = los_enu
    return math.atan2(up, math.hypot(east, north)), math.atan2(east, north) % (2 * math.pi)


def select_measurements(epoch, ephemerides, config):
    """Pick one (possibly ionosphere-free) pseudorange per satellite with a usable
    ephemeris.

    Returns
    -------
    list of _Meas
    """
    by_sat = {}
    for ob in epoch.obs:
        by_sat.setdefault(ob.sat_id, {})[ob.signal] = ob
    out = []
    for sat_id, signals in by_sat.items():
        eph = ephemerides.get(sat_id)
        system = sat_id[0]
        if eph is None or system not in config.signals or getattr(eph, "health", 0):
            continue
        first, second = config.signals[system]
        ob1 = signals.get(first)
        if ob1 is None or not math.isfinite(ob1.pseudorange_m):
            continue
        gd1 = group_delay(eph, ob1.frequency_hz) if system != GLONASS else 0.0
        if config.iono_free:
            ob2 = signals.get(second)
            if ob2 is None or not math.isfinite(ob2.pseudorange_m):
                continue
            gd2 = group_delay(eph, ob2.frequency_hz) if system != GLONASS else 0.0
            gamma = (ob1.frequency_hz / ob2.frequency_hz) ** 2
            pr = (gamma * ob1.pseudorange_m - ob2.pseudorange_m) / (gamma - 1.0)
            gd = (gamma * gd1 - gd2) / (gamma - 1.0)
            noise = math.hypot(gamma, 1.0) / (gamma - 1.0)
        else:
            pr, gd, noise = ob1.pseudorange_m, gd1, 1.0
        if math.isfinite(gd):
            out.append(_Meas(sat_id, system, eph, pr, ob1, gd, noise))
    return out


def _solve_wls(t_rx, meas, config, x0):
    """Iterated weighted least squares over the given measurements.

    Returns (state, systems, H, W, post-fit residuals, measurements used, model error
    variances: ``config.model_errors`` per measurement, zeros without) once the position step
    is below 0.1 mm, None when too few measurements remain or it does not converge.
    """
    systems = sorted({m.system for m in meas})
    n_state = 3 + len(systems)
    state = np.zeros(n_state)
    state[:3] = x0
    for _ in range(12):
        rx = state[:3]
        near_earth = np.linalg.norm(rx) > 6.0e6   # corrections only once near the surface
        if near_earth:
            lat, lon, h = ecef_to_geodetic(rx)
            rot = ecef_to_enu_matrix(lat, lon)
        rows, z, weights, sats, model_var = [], [], [], [], []
        for m in meas:
            sat, clock, _, _ = satellite_at_reception(
                m.eph, t_rx, m.pseudorange, rx if near_earth else None)
            los = sat - rx
            rng = np.linalg.norm(los)
            elevation, azimuth = math.pi / 2, 0.0
            if near_earth:
                elevation, azimuth = _elevation_azimuth(rot @ los)
                if elevation < config.elevation_mask:
                    continue
            predicted = rng - C_LIGHT * (clock - m.group_delay_s)
            iono = 0.0
            if near_earth:
                tropo = tropo_delay(lat, h, elevation)
                predicted += tropo
                if not config.iono_free and config.klobuchar is not None:
                    iono = klobuchar_delay(t_rx, lat, lon, elevation, azimuth,
                                           *config.klobuchar, m.obs.frequency_hz)
                    predicted += iono
                if config.model_errors is not None:
                    model_var.append(config.model_errors.variance(
                        iono, tropo, tropo_delay(lat, h, math.pi / 2)))
            row = np.zeros(n_state)
            row[:3] = -los / rng
            row[3 + systems.index(m.system)] = 1.0
            predicted += state[3 + systems.index(m.system)]
            rows.append(row)
            z.append(m.pseudorange - predicted)
            sigma = config.sigma0 * m.noise_factor / max(math.sin(elevation), 0.1)
            weights.append(1.0 / sigma ** 2)
            sats.append(m)
        if len(rows) < n_state:
            return None
        H, z, W = np.array(rows), np.array(z), np.array(weights)
        # Systems that lost all their satellites to the mask leave a zero column.
        if np.any(np.abs(H[:, 3:]).sum(axis=0) == 0):
            return None
        normal = H.T @ (W[:, None] * H)
        dx = np.linalg.solve(normal, H.T @ (W * z))
        state += dx
        if np.linalg.norm(dx[:3]) < 1e-4 and near_earth:
            return state, systems, H, W, z - H @ dx, sats, \
                np.array(model_var) if model_var else np.zeros(len(sats))
    return None


def solve_position(epoch, ephemerides, config=None, x0=None):
    """Single-point position, receiver clocks, DOPs and RAIM from one raw epoch.

    Parameters
    ----------
    epoch : observations.RawEpoch
    ephemerides : dict
        sat_id -> KeplerEphemeris / GlonassEphemeris (e.g. `NavDataAssembler.ephemerides`).
    config : SppConfig, optional
    x0 : array_like, shape (3,), optional
        Initial ECEF position [m] (the Earth's centre when omitted).

    Returns
    -------
    SppSolution or None
        None when fewer satellites than unknowns remain or the iteration diverges.
    """
    config = config or SppConfig()
    meas = select_measurements(epoch, ephemerides, config)
    x0 = np.zeros(3) if x0 is None else np.asarray(x0, dtype=float)
    excluded = []
    while True:
        result = _solve_wls(epoch.t_gps, meas, config, x0)
        if result is None:
            return None
        state, systems, H, W, residuals, sats, model_var = result
        dof = len(residuals) - H.shape[1]
        cov = np.linalg.inv(H.T @ (W[:, None] * H))  # of the noise the weights are
        test = float(np.sum(W * residuals ** 2))
        threshold = float(chi2.ppf(1.0 - config.p_false_alarm, dof)) if dof > 0 else math.nan
        passed = dof <= 0 or test <= threshold
        # Exclusion needs one redundant measurement left afterwards to re-test.
        if passed or dof < 2 or len(excluded) >= config.max_exclusions:
            break
        residual_cov = np.diag(1.0 / W) - H @ cov @ H.T
        normalised = np.abs(residuals) / np.sqrt(np.clip(np.diag(residual_cov), 1e-12, None))
        worst = sats[int(np.argmax(normalised))]
        excluded.append(worst.sat_id)
        meas = [m for m in meas if m is not worst]
        x0 = state[:3]
    if np.any(model_var > 0.0):  # the sandwich: the weights' estimate under R = noise + models
        gain = cov @ (H.T * W)
        cov = cov + (gain * model_var) @ gain.T
    xyz = state[:3]
    lat, lon, h = ecef_to_geodetic(xyz)
    rot = ecef_to_enu_matrix(lat, lon)
    dop_q = np.linalg.inv(H.T @ H)
    q_enu = rot @ dop_q[:3, :3] @ rot.T
    dop = {"gdop": math.sqrt(np.trace(dop_q)), "pdop": math.sqrt(np.trace(q_enu)),
           "hdop": math.sqrt(q_enu[0, 0] + q_enu[1, 1]), "vdop": math.sqrt(q_enu[2, 2]),
           "tdop": math.sqrt(dop_q[3, 3])}
    return SppSolution(
        t_gps=epoch.t_gps, xyz=xyz.copy(), lat=float(lat), lon=float(lon), h=float(h),
        clock_m={s: float(state[3 + i]) for i, s in enumerate(systems)},
        covariance=cov, covariance_enu=rot @ cov[:3, :3] @ rot.T, dop=dop,
        residuals={m.sat_id: float(r) for m, r in zip(sats, residuals)},
        used=[m.sat_id for m in sats], excluded=excluded, chi2=test,
        chi2_threshold=threshold, valid=passed)


def solve_velocity(epoch, ephemerides, solution, config=None, sigma_hz=0.1):
    """Receiver velocity and clock drift from the Doppler of the primary signals.

    Range-rate model: -lambda D_i = u_i . (v_i - v) + c (d_rx - d_i), u_i the unit vector
    receiver -> satellite, d the clock drifts (one receiver drift: all systems share the
    oscillator).  The Doppler sign is the receiver's (positive when approaching).

    Parameters
    ----------
    epoch : observations.RawEpoch
    ephemerides : dict
    solution : SppSolution
        Position solution of the same epoch (gives geometry and used satellites).
    sigma_hz : float
        Doppler noise for the weights [Hz] (relative weights only matter for the estimate).

    Returns
    -------
    vel_enu : ndarray (3,)  [m/s]
    clock_drift : float  receiver clock drift [m/s]
    covariance_enu : ndarray (3, 3)  [m^2/s^2]
    """
    config = config or SppConfig()
    meas = {m.sat_id: m for m in select_measurements(epoch, ephemerides, config)}
    rx = solution.xyz
    rot = ecef_to_enu_matrix(solution.lat, solution.lon)
    rows, z, weights = [], [], []
    for sat_id in solution.used:
        m = meas.get(sat_id)
        if m is None or not math.isfinite(m.obs.doppler_hz):
            continue
        sat, _, sat_vel, sat_drift = satellite_at_reception(m.eph, epoch.t_gps, m.pseudorange, rx)
        los = sat - rx
        unit = los / np.linalg.norm(los)
        wavelength = C_LIGHT / m.obs.frequency_hz
        range_rate = -wavelength * m.obs.doppler_hz
        rows.append(np.concatenate([-unit, [1.0]]))
        z.append(range_rate - unit @ sat_vel + C_LIGHT * sat_drift)
        elevation, _ = _elevation_azimuth(rot @ los)
        weights.append((math.sin(elevation) / (sigma_hz * wavelength)) ** 2)
    if len(rows) < 4:
        return None
    H, z, W = np.array(rows), np.array(z), np.array(weights)
    cov = np.linalg.inv(H.T @ (W[:, None] * H))
    x = cov @ H.T @ (W * z)
    return rot @ x[:3], float(x[3]), rot @ cov[:3, :3] @ rot.T
