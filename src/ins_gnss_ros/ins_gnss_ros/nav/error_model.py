"""Linear error-state model of the strapdown INS in the ENU navigation frame.

Error definitions (computed value minus true value; "~" marks computed):

* pos : δp = [(R_N+h) cos(lat) δlon, (R_M+h) δlat, δh]  -- curvilinear position error
  scaled to metres along East, North, Up [m].  Metres keep the covariance well conditioned
  (δlat in rad is 1e-7 for a metre) while staying exact for the lat/lon/h mechanisation.
* vel : δv = ṽ_enu - v_enu [m/s].
* att : φ, small rotation of the computed navigation frame [rad], with
  C̃_nb = (I - [φ×]) C_nb, i.e. q̃_nb = q(-φ) ⊗ q_nb (the psi-angle convention of Groves
  §14.2 / Savage; also seed 001 eq. 6.5 and seed 004 §2.1).  The strapdown module
  corrects with C_nb = (I + [φ×]) C̃_nb.
* sensor errors, measured minus true (Babich eq. 5.5):
  "bg" gyro bias [rad/s], "ba" accelerometer bias [m/s²], "gmg"/"gma" Gauss-Markov bias
  parts, "sg"/"sa" scale factors [-], "ng"/"na" non-orthogonality in Babich's order
  (XY, XZ, YX, YZ, ZX, ZY) [rad], "nz" the accelerometers' ZX and ZY terms alone (the z
  axis reading the horizontal accelerations) [rad], "gs" gyro g-sensitivity, row-major 3x3
  [rad/s / (m/s²)].
* "clock": receiver clock offset [m], drift [m/s] and drift rate [m/s²] (seed 004 §2.4).

Continuous model dx/dt = F x + G w, E[w w^T] = Qc δ.  Derivation (checked against the
non-linear mechanisation in test/nav/test_error_model.py):

    d δp/dt = δv + F_pp δp                      (curvilinear terms from the radii)
    d δv/dt = [f_n×] φ + C δf - [(2ω_ie + ω_en)×] δv + [v×] (2 δω_ie + δω_en) + δg
    d φ/dt  = -[ω_in×] φ + δω_in - C δω_ib

with C = C_nb, f_n = C f_b, and δω_ie, δω_en the changes of the Earth and transport rates
(Groves, Principles of GNSS, Inertial and Multisensor Integrated Navigation, §14.2, the
local-navigation-frame error equations rewritten for ENU; Savage, Strapdown Analytics ch. 12;
seed 001 eqs. 6.6-6.7, whose reconstructed signs these replace).  Gravity is [0, 0, -g] in
each local frame, so only the vertical gradient and the latitude variation of g enter δg (the
horizontal "-g/R" terms of a fixed-frame gradient are carried here by φ and ω_en).
"""

from dataclasses import dataclass
from functools import cached_property

import numpy as np

from . import _kernels
from .earth import WGS84, radii
from .rotations import quat_conj, quat_mul, quat_to_dcm, quat_to_rotvec
from .sensor_errors import MISALIGN_INDEX

#: Number of states of each block.
BLOCK_SIZES = {"pos": 3, "vel": 3, "att": 3, "bg": 3, "ba": 3, "gmg": 3, "gma": 3,
               "sg": 3, "sa": 3, "ng": 6, "na": 6, "nz": 2, "gs": 9, "clock": 3}

#: Named layouts.  "24" is seed 004's tightly-coupled vector (§2.5), reordered to the
#: project's pos, vel, att, ... order; "33" is Babich's model (seed 001 §6.9) with
#: non-orthogonality in place of his "misalignment" states; "21gm" adds the Gauss-Markov
#: bias parts of :data:`ins_gnss_ros.nav.sensor_errors` for exact covariance analysis; "17"
#: adds the cross-axis terms that read a horizontal acceleration as vertical ("nz"), which
#: an accelerometer triad nobody calibrated shows as a tilt in every manoeuvre (a consumer
#: part's 2 % is 1.1 deg): the default profile's. The accelerometers' other four terms are
#: left out: on gravity XZ and YZ are a bias ("ba" carries them), and with all six estimated
#: the real car drive lost 12 % per outage where these two cost it 2 %
#: (docs/results/product_path.md, "2026-12-07 (session 40)").
LAYOUTS = {
    "9": ("pos", "vel", "att"),
    "15": ("pos", "vel", "att", "bg", "ba"),
    "17": ("pos", "vel", "att", "bg", "ba", "nz"),
    "21": ("pos", "vel", "att", "bg", "ba", "sg", "sa"),
    "24": ("pos", "vel", "att", "bg", "ba", "sg", "sa", "clock"),
    "33": ("pos", "vel", "att", "bg", "ba", "sg", "sa", "ng", "na"),
    "21gm": ("pos", "vel", "att", "bg", "ba", "gmg", "gma", "sg", "sa"),
}


@dataclass(frozen=True)
class StateLayout:
    """Ordered blocks of the error state with named index slices.

    Attributes
    ----------
    blocks : tuple of str
        Block names in state order (keys of :data:`BLOCK_SIZES`).
    tau : dict
        Correlation time [s] of sensor blocks modelled as first-order Gauss-Markov
        processes; blocks not listed are random constants or random walks.
    """

    blocks: tuple
    tau: dict

    def __post_init__(self):
        unknown = [b for b in self.blocks if b not in BLOCK_SIZES]
        if unknown or len(set(self.blocks)) != len(self.blocks):
            raise ValueError(f"bad block list {self.blocks}")
        if self.blocks[:3] != ("pos", "vel", "att"):
            raise ValueError("a layout starts with pos, vel, att")

    @cached_property  # read at every filter epoch: built once (the layout is immutable)
    def slices(self):
        """dict block name -> slice into the state vector."""
        out, i = {}, 0
        for b in self.blocks:
            out[b] = slice(i, i + BLOCK_SIZES[b])
            i += BLOCK_SIZES[b]
        return out

    @cached_property
    def size(self):
        """Number of states."""
        return sum(BLOCK_SIZES[b] for b in self.blocks)

    @cached_property
    def sensor_plan(self):
        """(k, 3) int64 rows (column kind, first column, 1 for a gyro block) of the sensor-error
        blocks, as :func:`_kernels.system_matrix` takes them."""
        rows = []
        for b in self.blocks:
            if b in _SENSOR_COLUMNS:
                kind, gyro = _SENSOR_COLUMNS[b]
                rows.append((kind, self.slices[b].start, gyro))
        return np.array(rows, dtype=np.int64).reshape(-1, 3)

    def __getitem__(self, name):
        return self.slices[name]

    def __contains__(self, name):
        return name in self.blocks


def make_layout(spec, noise=None):
    """Build a :class:`StateLayout` from a preset name or a list of block names.

    Parameters
    ----------
    spec : str or sequence of str
        Key of :data:`LAYOUTS` or block names.
    noise : FilterNoise, optional
        Supplies the correlation times of Gauss-Markov blocks.
    """
    blocks = tuple(LAYOUTS[spec]) if isinstance(spec, str) else tuple(spec)
    tau = {}
    if noise is not None:
        tau = {b: bn.tau for b, bn in noise.blocks.items() if b in blocks and np.isfinite(bn.tau)}
    return StateLayout(blocks, tau)


#: Sensor-error blocks: (column kind of _kernels.system_matrix, True for a gyro block). Gyro
#: errors enter the attitude rows, accelerometer errors the velocity rows.
_SENSOR_COLUMNS = {"bg": (_kernels.BIAS, True), "gmg": (_kernels.BIAS, True),
                   "sg": (_kernels.SCALE, True), "ng": (_kernels.NONORTHOGONALITY, True),
                   "gs": (_kernels.G_SENSITIVITY, True),
                   "ba": (_kernels.BIAS, False), "gma": (_kernels.BIAS, False),
                   "sa": (_kernels.SCALE, False), "na": (_kernels.NONORTHOGONALITY, False),
                   "nz": (_kernels.VERTICAL_CROSS_AXIS, False)}
#: sensor_errors.MISALIGN_INDEX as :func:`_kernels.system_matrix` takes it.
MISALIGN_COLUMNS = np.array(MISALIGN_INDEX, dtype=np.int64)


def _vector(a):
    """A float64 C-contiguous array, the one layout the kernels are compiled for."""
    return np.ascontiguousarray(a, dtype=float)


def system_matrix(layout, nav_state, f_b, w_ib_b, ell=WGS84):
    """Continuous system matrix F of the error state.

    The navigation and sensor-error rows are filled by the compiled :func:`_kernels.system_matrix`
    (the equations of the module docstring; F is rebuilt at every covariance epoch, where some
    sixty small numpy operations took ~0.3 ms), the Gauss-Markov and clock terms are those of
    :func:`constant_system_matrix`.

    Parameters
    ----------
    layout : StateLayout
    nav_state : NavState
        Navigation solution (lat, lon [rad], h [m], v_enu [m/s], q_nb).
    f_b : array_like, shape (3,)
        Specific force in body (FLU) axes [m/s²].
    w_ib_b : array_like, shape (3,)
        Angular rate of body w.r.t. inertial space in body axes [rad/s].
    ell : Ellipsoid

    Returns
    -------
    (n, n) ndarray [1/s]
    """
    F = constant_system_matrix(layout)
    _kernels.system_matrix(F, float(nav_state.lat), float(nav_state.h), _vector(nav_state.v_enu),
                           _vector(nav_state.q_nb), _vector(f_b), _vector(w_ib_b),
                           ell.kernel_params, layout.sensor_plan, MISALIGN_COLUMNS)
    return F


def constant_system_matrix(layout):
    """The part of the system matrix that does not depend on the navigation state, (n, n): the
    Gauss-Markov and clock terms, zeros elsewhere. :func:`_kernels.system_matrix` fills the rest
    (the navigation rows, which these terms never touch) by assignment."""
    F = np.zeros((layout.size, layout.size))
    S = layout.slices
    for name, tau in layout.tau.items():
        F[S[name], S[name]] = -np.eye(BLOCK_SIZES[name]) / tau
    if "clock" in layout:
        k = S["clock"].start
        F[k, k + 1] = 1.0
        F[k + 1, k + 2] = 1.0
    return F


#: Default receiver-clock noise densities [m²/s, m²/s³, m²/s⁵] for offset, drift and drift
#: rate: a TCXO (order of magnitude of Groves ch. 9: S_cφ = 0.01 m²/s, S_cf = 0.04 m²/s³);
#: the drift-rate Wiener process of seed 004 §2.4 is kept small.
DEFAULT_CLOCK_PSD = (0.01, 0.04, 1e-6)


def noise_input(layout, nav_state, noise, clock_psd=DEFAULT_CLOCK_PSD):
    """Noise input matrix G and spectral density Qc of the error model.

    The noise vector is [gyro white (3), accelerometer white (3), then the driving noise of
    every sensor block with non-zero PSD, then the clock noises].

    Parameters
    ----------
    layout : StateLayout
    nav_state : NavState
        Supplies q_nb.
    noise : FilterNoise
        From :func:`ins_gnss_ros.nav.sensor_errors.filter_noise`.
    clock_psd : sequence of 3 float
        Clock offset, drift and drift-rate noise densities.

    Returns
    -------
    G : (n, m) ndarray
    Qc : (m, m) ndarray, diagonal
    """
    C = quat_to_dcm(nav_state.q_nb)
    S = layout.slices
    cols, psd = [], []

    def add(rows, block, q):
        g = np.zeros((layout.size, block.shape[1]))
        g[rows] = block
        cols.append(g)
        psd.extend([q] * block.shape[1])

    add(S["att"], -C, noise.gyro_psd)
    add(S["vel"], C, noise.accel_psd)
    for name, bn in noise.blocks.items():
        if name in layout and bn.psd > 0.0:
            add(S[name], np.eye(BLOCK_SIZES[name]), bn.psd)
    if "clock" in layout:
        for i, q in enumerate(clock_psd):
            e = np.zeros((3, 1))
            e[i] = 1.0
            add(S["clock"], e, q)
    return np.hstack(cols), np.diag(psd)


def initial_covariance(layout, noise, sigma_pos, sigma_vel, sigma_att,
                       sigma_clock=(30.0, 1.0, 0.01)):
    """Diagonal initial covariance P0.

    Parameters
    ----------
    layout : StateLayout
    noise : FilterNoise
        Supplies the sensor-block initial standard deviations.
    sigma_pos, sigma_vel, sigma_att : float or array_like (3,)
        ENU position [m], velocity [m/s] and attitude-error [rad] standard deviations.
    sigma_clock : sequence of 3 float
        Clock offset [m], drift [m/s], drift rate [m/s²].
    """
    sig = np.zeros(layout.size)
    S = layout.slices
    sig[S["pos"]] = sigma_pos
    sig[S["vel"]] = sigma_vel
    sig[S["att"]] = sigma_att
    for name in layout.blocks[3:]:
        sig[S[name]] = sigma_clock if name == "clock" else noise.blocks[name].sigma0
    return np.diag(sig ** 2)


def nav_error(est, true, ell=WGS84):
    """Error (est - true) of a navigation solution in the model's definitions.

    Parameters
    ----------
    est, true : NavState

    Returns
    -------
    dp : (3,) ndarray
        ENU position error [m] (curvilinear, scaled at the true position).
    dv : (3,) ndarray
        ENU velocity error [m/s].
    phi : (3,) ndarray
        Attitude error [rad], C̃ = (I - [φ×]) C.
    """
    rm, rn = radii(true.lat, ell)
    dlon = (est.lon - true.lon + np.pi) % (2 * np.pi) - np.pi
    dp = np.array([(rn + true.h) * np.cos(true.lat) * dlon,
                   (rm + true.h) * (est.lat - true.lat),
                   est.h - true.h])
    dv = np.asarray(est.v_enu, float) - np.asarray(true.v_enu, float)
    # C̃ C^T = I - [φ×]  =>  q̃ ⊗ q* is the rotation -φ.
    phi = -quat_to_rotvec(quat_mul(est.q_nb, quat_conj(true.q_nb)))
    return dp, dv, phi
