"""Inertial sensor error processes: budgets, a simulator, and the filter's state-space blocks.

Each triad (gyros or accelerometers) is three identical, mutually independent axes
(seed 001, Babich §5, assumption L516-L520) whose output error is

    δ = b_const + b_gm(t) + b_rw(t) + (S + N) u + η

* b_const : run-to-run (turn-on) bias, constant in a run, N(0, σ_b²).
* b_gm    : in-run bias as a first-order Gauss-Markov process, E[b(t)b(t+τ)] = σ² e^{-|τ|/T}
            (seed 001 eq. 5.2; seed 004 simulator model П1 "first-order Markov").
* b_rw    : bias random walk, db/dt = w, E[w w] = q_rw δ (rate / acceleration random walk).
* S, N    : scale-factor errors (diagonal) and non-orthogonality (off-diagonal, Babich's
            β = (β_XY, β_XZ, β_YX, β_YZ, β_ZX, β_ZY): axis-i sensitivity to axis j), constant.
* η       : white noise of density N_w (ARW for gyros, VRW for accelerometers).

Gyros also respond to specific force through a g-sensitivity matrix (seed 004 §2.3).

The simulator draws these exactly (exact discrete Gauss-Markov). The filter may model them
differently (seed 004 §2.3 deliberately uses Wiener processes in the filter):
:func:`filter_noise` offers the exact model ("gm": separate constant and Gauss-Markov states)
and Babich's reduced model ("rw": one random-walk bias state, the GM process approximated by
the integral of white noise of intensity 2σ²/T, Babich §5).
"""

from dataclasses import dataclass, field, replace

import numpy as np

DEG = np.pi / 180.0
DEG_PER_HOUR = DEG / 3600.0
MILLI_G = 9.80665e-3
MICRO_G = 9.80665e-6
PPM = 1e-6
ARCMIN = DEG / 60.0

#: Babich's order of the 6 non-orthogonality terms: (row, column) of the error matrix.
MISALIGN_INDEX = ((0, 1), (0, 2), (1, 0), (1, 2), (2, 0), (2, 1))


@dataclass(frozen=True)
class TriadErrors:
    """Error budget of one sensor triad; 1σ values, same for the three axes.

    Units are those of the sensed quantity u: rad/s for gyros, m/s² for accelerometers.

    Attributes
    ----------
    white_density : float
        White-noise density [u/√Hz] (gyro: angle random walk in rad/√s; accelerometer:
        velocity random walk in m/s/√s).
    bias_sigma : float
        Run-to-run constant bias [u].
    gm_sigma : float
        In-run Gauss-Markov bias standard deviation [u].
    gm_tau : float
        Its correlation time [s].
    rw_density : float
        Bias random-walk density [u/√s].
    scale_sigma : float
        Scale-factor error [-].
    misalign_sigma : float
        Axis non-orthogonality [rad].
    """

    white_density: float
    bias_sigma: float
    gm_sigma: float = 0.0
    gm_tau: float = np.inf
    rw_density: float = 0.0
    scale_sigma: float = 0.0
    misalign_sigma: float = 0.0


@dataclass(frozen=True)
class ImuGrade:
    """Error budget of an IMU.

    Attributes
    ----------
    name : str
    gyro : TriadErrors
        Units rad/s.
    accel : TriadErrors
        Units m/s².
    g_sensitivity_sigma : float
        Gyro g-sensitivity, each of the 9 matrix elements [rad/s per m/s²].
    """

    name: str
    gyro: TriadErrors
    accel: TriadErrors
    g_sensitivity_sigma: float = 0.0


#: MEMS, ADIS16405-like. Noise densities from seed 004 §3 (0.07 °/s/√Hz, 0.0002 m/s²/√Hz);
#: in-run stability from the ADIS16405 data sheet (0.007 °/s, 0.2 mg); residual turn-on bias
#: after factory calibration, scale factor and 3' non-orthogonality (seed 004 §3) assumed.
MEMS_ADIS16405 = ImuGrade(
    "mems_adis16405",
    gyro=TriadErrors(white_density=0.07 * DEG, bias_sigma=0.05 * DEG,
                     gm_sigma=0.007 * DEG, gm_tau=100.0, rw_density=0.0,
                     scale_sigma=1000 * PPM, misalign_sigma=3 * ARCMIN),
    accel=TriadErrors(white_density=2e-4, bias_sigma=5 * MILLI_G,
                      gm_sigma=0.2 * MILLI_G, gm_tau=100.0, rw_density=0.0,
                      scale_sigma=1000 * PPM, misalign_sigma=3 * ARCMIN),
    g_sensitivity_sigma=0.05 * DEG / 9.80665)

#: The ADIS16405 at its data-sheet turn-on biases (Analog Devices ADIS16405 data sheet, rev. B:
#: gyro initial bias error ±3 °/s, accelerometer ±50 mg, taken as 1σ): what an uncalibrated unit
#: starts with. In-run stability, noise and scale factors as :data:`MEMS_ADIS16405`.
MEMS_ADIS16405_DATASHEET = ImuGrade(
    "mems_adis16405_datasheet",
    gyro=replace(MEMS_ADIS16405.gyro, bias_sigma=3.0 * DEG),
    accel=replace(MEMS_ADIS16405.accel, bias_sigma=50 * MILLI_G),
    g_sensitivity_sigma=MEMS_ADIS16405.g_sensitivity_sigma)

#: Consumer MEMS (MPU-6050 / ICM-20948 class; TDK InvenSense ICM-20948 data sheet DS-000189
#: rev. 1.3): gyro initial zero-rate output ±5 °/s, rate noise 0.015 °/s/√Hz, sensitivity
#: tolerance ±1.5 %, cross-axis ±2 %; accelerometer initial zero-g output ±50 mg, noise
#: 230 µg/√Hz, sensitivity ±0.5 %. The data sheets give no in-run stability: 0.01 °/s and 1 mg
#: over 100 s, the Allan bias-instability floor such parts show, is assumed.
CONSUMER_MEMS = ImuGrade(
    "consumer_mems",
    gyro=TriadErrors(white_density=0.015 * DEG, bias_sigma=5.0 * DEG,
                     gm_sigma=0.01 * DEG, gm_tau=100.0, rw_density=0.0,
                     scale_sigma=15000 * PPM, misalign_sigma=0.02),
    accel=TriadErrors(white_density=230 * MICRO_G, bias_sigma=50 * MILLI_G,
                      gm_sigma=1.0 * MILLI_G, gm_tau=100.0, rw_density=0.0,
                      scale_sigma=5000 * PPM, misalign_sigma=0.02),
    g_sensitivity_sigma=0.1 * DEG / 9.80665)

#: The figures a data sheet gives: white noise, turn-on bias, scale factor, cross-axis.
DATA_SHEET_FIGURES = ("white_density", "bias_sigma", "scale_sigma", "misalign_sigma")


def _wider_data_sheet(a: TriadErrors, b: TriadErrors) -> TriadErrors:
    """Triad a with each of its :data:`DATA_SHEET_FIGURES` the wider of a's and b's."""
    return replace(a, **{name: max(getattr(a, name), getattr(b, name))
                         for name in DATA_SHEET_FIGURES})


#: A MEMS unit nobody calibrated, of any make (config/default.yaml): each data-sheet figure the
#: wider of the ADIS16405 data sheet's (:data:`MEMS_ADIS16405_DATASHEET`) and the consumer
#: parts' (:data:`CONSUMER_MEMS`): the consumer's gyro turn-on bias (5 deg/s), accelerometer
#: noise, scale-factor and cross-axis tolerances and g-sensitivity, the ADIS's gyro noise. The
#: in-run stability, which the consumer data sheets do not give, stays the ADIS's: the consumer
#: figure is this project's assumption, and taken instead it cost the real car drive 0.85 m of
#: per-outage RMS (product_path.md, "2026-12-06 (session 38)"). The filter takes the gyros'
#: scale and cross-axis errors into its attitude variance in turns (propagation.turn_noise).
MEMS_UNCALIBRATED = ImuGrade(
    "mems_uncalibrated",
    gyro=_wider_data_sheet(MEMS_ADIS16405_DATASHEET.gyro, CONSUMER_MEMS.gyro),
    accel=_wider_data_sheet(MEMS_ADIS16405_DATASHEET.accel, CONSUMER_MEMS.accel),
    g_sensitivity_sigma=max(MEMS_ADIS16405_DATASHEET.g_sensitivity_sigma,
                            CONSUMER_MEMS.g_sensitivity_sigma))

#: Tactical grade (ring-laser / good FOG, ~1 °/h class).
TACTICAL = ImuGrade(
    "tactical",
    gyro=TriadErrors(white_density=0.125 * DEG / 60.0, bias_sigma=1.0 * DEG_PER_HOUR,
                     gm_sigma=0.35 * DEG_PER_HOUR, gm_tau=300.0,
                     rw_density=0.0, scale_sigma=150 * PPM, misalign_sigma=0.1e-3),
    accel=TriadErrors(white_density=0.05 / 60.0, bias_sigma=1.0 * MILLI_G,
                      gm_sigma=0.05 * MILLI_G, gm_tau=300.0, rw_density=0.0,
                      scale_sigma=300 * PPM, misalign_sigma=0.1e-3))

#: Navigation grade FOG (0.01 °/h class, like the seed 004 reference IMU-120).
NAVIGATION = ImuGrade(
    "navigation",
    gyro=TriadErrors(white_density=0.002 * DEG / 60.0, bias_sigma=0.01 * DEG_PER_HOUR,
                     gm_sigma=0.003 * DEG_PER_HOUR, gm_tau=3600.0,
                     rw_density=0.0, scale_sigma=20 * PPM, misalign_sigma=10e-6),
    accel=TriadErrors(white_density=20 * MICRO_G, bias_sigma=50 * MICRO_G,
                      gm_sigma=10 * MICRO_G, gm_tau=3600.0, rw_density=0.0,
                      scale_sigma=50 * PPM, misalign_sigma=10e-6))

GRADES = {g.name: g for g in (MEMS_ADIS16405, MEMS_ADIS16405_DATASHEET, CONSUMER_MEMS,
                              MEMS_UNCALIBRATED, TACTICAL, NAVIGATION)}


def error_matrix(scale, misalign):
    """Scale-factor + non-orthogonality error matrix S + N, shape (..., 3, 3).

    Parameters
    ----------
    scale : array_like, shape (..., 3)
        Scale-factor errors k [-].
    misalign : array_like, shape (..., 6)
        Non-orthogonality β in Babich's order (XY, XZ, YX, YZ, ZX, ZY) [rad].
    """
    scale = np.asarray(scale, float)
    misalign = np.asarray(misalign, float)
    M = np.zeros(scale.shape[:-1] + (3, 3))
    M[..., [0, 1, 2], [0, 1, 2]] = scale
    for k, (i, j) in enumerate(MISALIGN_INDEX):
        M[..., i, j] = misalign[..., k]
    return M


def misalign_jacobian(u):
    """Babich's Γ(u) (eq. 5.4): Γ β = N u for the off-diagonal error matrix N, shape (3, 6)."""
    u = np.asarray(u, float)
    gamma = np.zeros((3, 6))
    for k, (i, j) in enumerate(MISALIGN_INDEX):
        gamma[i, k] = u[j]
    return gamma


@dataclass
class _TriadState:
    """Drawn constants and current in-run processes of one triad for R runs."""

    bias: np.ndarray       # (R, 3) constant bias
    gm: np.ndarray         # (R, 3) Gauss-Markov bias, current value
    rw: np.ndarray         # (R, 3) random-walk bias, current value
    matrix: np.ndarray     # (R, 3, 3) scale + non-orthogonality
    scale: np.ndarray      # (R, 3)
    misalign: np.ndarray   # (R, 6)


class ImuErrorSimulator:
    """Draws the error processes of an IMU grade and corrupts ideal increments.

    Vectorised over R independent runs (Monte Carlo) and over time: arrays are (R, N, 3).
    Successive calls continue the same in-run processes.

    Parameters
    ----------
    grade : ImuGrade
    dt : float
        Sample interval of the increments [s].
    rng : numpy.random.Generator
    n_runs : int
        Number of independent realisations R.
    """

    def __init__(self, grade, dt, rng, n_runs=1):
        self.grade = grade
        self.dt = float(dt)
        self.rng = rng
        self.n_runs = int(n_runs)
        self.gyro = self._draw(grade.gyro)
        self.accel = self._draw(grade.accel)
        self.g_sensitivity = grade.g_sensitivity_sigma * rng.standard_normal(
            (self.n_runs, 3, 3))

    def _draw(self, t):
        n, rng = self.n_runs, self.rng
        scale = t.scale_sigma * rng.standard_normal((n, 3))
        misalign = t.misalign_sigma * rng.standard_normal((n, 6))
        # The Gauss-Markov process starts from its stationary distribution.
        return _TriadState(bias=t.bias_sigma * rng.standard_normal((n, 3)),
                           gm=t.gm_sigma * rng.standard_normal((n, 3)),
                           rw=np.zeros((n, 3)),
                           matrix=error_matrix(scale, misalign),
                           scale=scale, misalign=misalign)

    def _bias_sequence(self, t, s, n):
        """In-run bias at the start of each of n steps, (R, n, 3); advances the state."""
        dt, rng, shape = self.dt, self.rng, (self.n_runs, n, 3)
        gm = np.broadcast_to(s.gm[:, None, :], shape)
        if np.isfinite(t.gm_tau) and t.gm_sigma > 0.0:
            # Exact discrete first-order Gauss-Markov: x_{k+1} = a x_k + w_k,
            # var(w) = σ² (1 - a²) keeps the variance stationary (Babich B4.10).
            # scipy.signal takes 2 s to import: only the simulators get here, not the nodes
            from scipy.signal import lfilter

            a = np.exp(-dt / t.gm_tau)
            w = t.gm_sigma * np.sqrt(1.0 - a * a) * rng.standard_normal(shape)
            nxt, _ = lfilter([1.0], [1.0, -a], w, axis=1, zi=a * s.gm[:, None, :])
            gm = np.concatenate([s.gm[:, None, :], nxt[:, :-1]], axis=1)
            s.gm = nxt[:, -1]
        rw = np.broadcast_to(s.rw[:, None, :], shape)
        if t.rw_density > 0.0:
            steps = t.rw_density * np.sqrt(dt) * rng.standard_normal(shape)
            walk = s.rw[:, None, :] + np.cumsum(steps, axis=1)
            rw = np.concatenate([s.rw[:, None, :], walk[:, :-1]], axis=1)
            s.rw = walk[:, -1]
        return s.bias[:, None, :] + gm + rw

    def _corrupt(self, t, s, x):
        """x: ideal increments (N, 3) or (R, N, 3) -> measured increments (R, N, 3)."""
        x = np.broadcast_to(x, (self.n_runs,) + np.shape(x)[-2:])
        n = x.shape[1]
        # Integrated white noise of density N_w over dt has standard deviation N_w √dt.
        noise = t.white_density * np.sqrt(self.dt) * self.rng.standard_normal(x.shape)
        return x + np.einsum("rij,rnj->rni", s.matrix, x) \
            + self._bias_sequence(t, s, n) * self.dt + noise

    def corrupt(self, dtheta, dv):
        """Measured increments of a sequence of ideal increments.

        Parameters
        ----------
        dtheta : array_like, shape (N, 3) or (R, N, 3)
            Ideal angle increments in body axes [rad].
        dv : array_like, shape (N, 3) or (R, N, 3)
            Ideal velocity increments in body axes [m/s].

        Returns
        -------
        dtheta_m, dv_m : ndarray, shape (R, N, 3)
        """
        dv_b = np.broadcast_to(dv, (self.n_runs,) + np.shape(dv)[-2:])
        dtheta_m = self._corrupt(self.grade.gyro, self.gyro, dtheta) \
            + np.einsum("rij,rnj->rni", self.g_sensitivity, dv_b)
        dv_m = self._corrupt(self.grade.accel, self.accel, dv)
        return dtheta_m, dv_m


@dataclass(frozen=True)
class BlockNoise:
    """Filter model of one block of sensor-error states (per state, all states alike).

    Attributes
    ----------
    sigma0 : float
        Initial standard deviation.
    tau : float
        Correlation time [s]; inf for a random constant / random walk.
    psd : float
        Spectral density of the driving white noise [unit²/s].
    """

    sigma0: float
    tau: float = np.inf
    psd: float = 0.0


@dataclass(frozen=True)
class FilterNoise:
    """Noise description consumed by :mod:`ins_gnss_ros.nav.error_model`.

    Attributes
    ----------
    gyro_psd : float
        Gyro white-noise spectral density [rad²/s] (= ARW²).
    accel_psd : float
        Accelerometer white-noise spectral density [m²/s³] (= VRW²).
    blocks : dict[str, BlockNoise]
        Sensor-error blocks by layout name ("bg", "ba", "gmg", "gma", "sg", "sa", "ng",
        "na", "nz", "gs").
    """

    gyro_psd: float
    accel_psd: float
    blocks: dict = field(default_factory=dict)


def filter_noise(grade, bias_model="gm"):
    """Filter noise model of an IMU grade.

    Parameters
    ----------
    grade : ImuGrade
    bias_model : {"gm", "rw"}
        "gm": exact model, constant + random-walk bias states "bg"/"ba" plus Gauss-Markov
        states "gmg"/"gma". "rw": Babich's reduced model, one random-walk bias state whose
        intensity adds 2σ²/T of the Gauss-Markov part and whose initial variance adds σ².

    Returns
    -------
    FilterNoise
    """
    g, a = grade.gyro, grade.accel
    blocks = {
        "sg": BlockNoise(g.scale_sigma), "sa": BlockNoise(a.scale_sigma),
        "ng": BlockNoise(g.misalign_sigma), "na": BlockNoise(a.misalign_sigma),
        "nz": BlockNoise(a.misalign_sigma),
        "gs": BlockNoise(grade.g_sensitivity_sigma),
    }
    for name, t in (("g", g), ("a", a)):
        if bias_model == "gm":
            blocks["b" + name] = BlockNoise(t.bias_sigma, psd=t.rw_density ** 2)
            blocks["gm" + name] = BlockNoise(t.gm_sigma, t.gm_tau, 2 * t.gm_sigma ** 2 / t.gm_tau)
        elif bias_model == "rw":
            blocks["b" + name] = BlockNoise(np.hypot(t.bias_sigma, t.gm_sigma),
                                            psd=t.rw_density ** 2 + 2 * t.gm_sigma ** 2 / t.gm_tau)
        else:
            raise ValueError(f"unknown bias model {bias_model!r}")
    return FilterNoise(g.white_density ** 2, a.white_density ** 2, blocks)
