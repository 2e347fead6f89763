"""Error-state (indirect, feedback) Kalman filter closed around the strapdown mechanisation.

The filter estimates the errors of the navigation solution and of the inertial sensors, in the
state order of a :class:`~ins_gnss_ros.nav.error_model.StateLayout` followed by optional extra
blocks (:class:`ExtraState`: IMU-GNSS time offset, magnetic-heading bias, ...). Conventions are
those of :mod:`ins_gnss_ros.nav.strapdown` and :mod:`ins_gnss_ros.nav.error_model`:

* navigation errors (pos, vel, att) are "computed minus true"; they are removed from the
  strapdown with :func:`~ins_gnss_ros.nav.strapdown.apply_correction`;
* every other state (sensor errors, clock, extra blocks) is the residual "true minus current
  estimate" of a quantity whose running estimate lives outside the filter; feedback ADDS the
  state to that estimate (for the IMU errors "true" means the sensor's measured-minus-true error,
  error_model.py).

Generalised Kalman filter of seed 004 section 2.5 (eqs. 2.1.10-2.1.15): covariance prediction
P- = Phi P Phi^T + Q with Phi and Q from the Picard series of seed 001 (Babich, equal orders of
Phi and Q, :mod:`ins_gnss_ros.nav.discretize`), Joseph-form update (seed 004 eq. 2.1.13), and
the closed-loop estimation channel x = C Phi x + K z with C zeroing the fed-back states: here all
states are fed back after each update, so the prediction of x is always zero and the innovation
is z itself (seed 004 section 2.5, "the innovation equals z").
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from . import _kernels
from .discretize import DEFAULT_ORDER
from .earth import WGS84
from .error_model import DEFAULT_CLOCK_PSD, MISALIGN_COLUMNS, StateLayout, _vector, \
    constant_system_matrix, noise_input
from .gating import DEFAULT_GATE_PROB, UpdateResult, chi2_gate

#: Smallest variance kept on the diagonal after an update (state units squared); guards the
#: Joseph form against round-off driving a variance negative on perfectly observed states.
MIN_VARIANCE = 1e-18


@dataclass(frozen=True)
class ExtraState:
    """A block of states outside error_model.py: random constant, random walk or Gauss-Markov.

    Attributes
    ----------
    size : int
        Number of states.
    sigma0 : float or array_like of `size` floats
        Initial standard deviation (state unit), one for the block or one per state.
    psd : float
        Driving white-noise spectral density (unit^2 / s); 0 for a random constant.
    tau : float
        Gauss-Markov correlation time, s; inf for a random constant / walk.
    consider : bool
        A "consider" block (Schmidt-Kalman filter; Simon, "Optimal State Estimation", 2006,
        section 7.5): its uncertainty and its correlations enter every gain of the other
        states, but it is never estimated (its gain rows are zero, so its estimate stays at its
        configured value and its covariance is that of the configured value's error). For a
        parameter that is not known and should not be fitted, such as an antenna lever arm
        nobody measured, which a fit would trade against the time offset or the heading.
    """

    size: int = 1
    sigma0: float = 0.0
    psd: float = 0.0
    tau: float = np.inf
    consider: bool = False


#: Extra blocks the measurement models know: "td" IMU-to-measurement time offset (s, a measurement
#: stamped t refers to the navigation epoch t - td), "mag" magnetic-heading bias (rad), "nhc"
#: pitch and yaw of the vehicle axes relative to the IMU axes (or to the learned ones,
#: vehicle_constraint.py) for the non-holonomic constraint (2, rad), "log" water current E, N
#: (m/s) and speed-log scale error (3), "wheel" wheel-odometry scale error (1, -), "vd" latency
#: of the GNSS velocity alone (s, measurements.py gnss_velocity), "lever_x", "lever_y",
#: "lever_z" error of the configured antenna lever arm along each FLU axis (m; consider blocks,
#: one per axis so that an exact axis has none: a zero variance would make P singular).
LEVER_ARM_EXTRAS = ("lever_x", "lever_y", "lever_z")
KNOWN_EXTRAS = ("td", "mag", "ahrs", "nhc", "log", "wheel", "vd") + LEVER_ARM_EXTRAS


@dataclass(frozen=True)
class StateSpace:
    """Error-state vector: an error_model layout followed by extra blocks.

    The layout's blocks keep their indices; the extras follow in the order of ``extras``.
    ``space[name]`` is the slice of a block and ``name in space`` says whether it is there.

    Attributes
    ----------
    layout : StateLayout
    extras : dict of str to ExtraState
    """

    layout: StateLayout
    extras: dict = field(default_factory=dict)

    def __post_init__(self):
        unknown = [name for name in self.extras if name not in KNOWN_EXTRAS]
        if unknown:
            raise ValueError(f"extra blocks {unknown}: the measurement models know {KNOWN_EXTRAS}")
        slices = dict(self.layout.slices)
        n = self.layout.size
        for name, block in self.extras.items():
            slices[name] = slice(n, n + block.size)
            n += block.size
        object.__setattr__(self, "_slices", slices)
        object.__setattr__(self, "_size", n)
        consider = [i for name, block in self.extras.items() if block.consider
                    for i in range(n)[slices[name]]]
        object.__setattr__(self, "_consider", np.array(consider, np.int64))
        object.__setattr__(self, "_lever_arm", tuple(
            (axis, slices[name].start) for axis, name in enumerate(LEVER_ARM_EXTRAS)
            if name in slices))

    @property
    def slices(self):
        """dict block name -> slice into the state vector."""
        return self._slices

    @property
    def size(self):
        """Number of states."""
        return self._size

    @property
    def blocks(self):
        """Block names in state order."""
        return tuple(self.layout.blocks) + tuple(self.extras)

    @property
    def consider(self):
        """Indices of the states of consider blocks (never estimated: ExtraState.consider)."""
        return self._consider

    @property
    def lever_arm(self):
        """(FLU axis, state index) of each "lever_*" block there is (empty: the lever arm is
        exact)."""
        return self._lever_arm

    def __getitem__(self, name):
        return self._slices[name]

    def __contains__(self, name):
        return name in self._slices


def at_prior(P, rows, sigma0):
    """The covariance P (a copy) with the states ``rows`` (a slice) back at their prior, sigma0
    (one or per state), and uncorrelated with the rest: what they were estimated to is
    forgotten."""
    P = P.copy()
    P[rows, :] = 0.0
    P[:, rows] = 0.0
    P[rows, rows] = np.diag(np.broadcast_to(sigma0, (rows.stop - rows.start,)) ** 2)
    return P


def _kernel_array(a, ndim):
    """`a` as a C-contiguous float64 array of at least `ndim` dimensions, as the compiled
    update takes it: `a` itself when it is one already (the measurement models' arrays; the
    general conversion costs more than the check at every update)."""
    if type(a) is np.ndarray and a.dtype == np.float64 and a.ndim == ndim and \
            a.flags.c_contiguous:
        return a
    a = np.asarray(a, float)
    return np.ascontiguousarray(np.atleast_1d(a) if ndim == 1 else np.atleast_2d(a))


class ErrorStateEKF:
    """Covariance and error-state estimate of the closed-loop filter.

    Parameters
    ----------
    space : StateSpace
    noise : FilterNoise
        IMU noise model (:func:`ins_gnss_ros.nav.sensor_errors.filter_noise`).
    P0 : (n, n) array_like
        Initial covariance.
    clock_psd : sequence of 3 float
        Receiver clock noise densities (layouts with a "clock" block).
    order : int
        Picard order of the discretisation (order 2 gives a non-PSD Q; order 3 is not PSD for
        MEMS models at dt >= 0.1 s either: the default 5 is, see discretize.DEFAULT_ORDER).
    joseph : bool
        Joseph-form covariance update (default) or the standard (I - K H) P.
    """

    def __init__(self, space, noise, P0, clock_psd=DEFAULT_CLOCK_PSD, order=DEFAULT_ORDER,
                 joseph=True):
        self.space = space
        self.noise = noise
        self.clock_psd = clock_psd
        self.order = order
        if len(space.consider) and not joseph:
            raise ValueError("consider blocks need the Joseph form: (I - K H) P holds only for "
                             "the optimal gain")
        self.joseph = joseph
        self.P = np.array(P0, dtype=float)
        self.x = np.zeros(space.size)
        # The model's constant part (Gauss-Markov and clock terms, the extra blocks' dynamics)
        # does not depend on the navigation state: built once, copied for each new model.
        lay = space.layout
        n0 = lay.size
        self._F_constant = np.zeros((space.size,) * 2)
        self._F_constant[:n0, :n0] = constant_system_matrix(lay)
        self._Q_extra = np.zeros((space.size - n0,) * 2)
        i = 0
        for block in space.extras.values():
            s = slice(n0 + i, n0 + i + block.size)
            if np.isfinite(block.tau):
                self._F_constant[s, s] = -np.eye(block.size) / block.tau
            self._Q_extra[i:i + block.size, i:i + block.size] = block.psd * np.eye(block.size)
            i += block.size
        self._Q = None
        self.F_model = None

    def set_noise(self, noise):
        """Use the IMU noise model `noise` from the next step on (the densities measured at
        rest, rest_noise.py): F and Q are rebuilt then."""
        if noise is not self.noise:
            self.noise, self.F_model, self._Q = noise, None, None

    def model(self, nav_state, refresh):
        """The continuous model of the next step: (F, Q, rebuild), F to be filled at the step's
        state by :func:`_kernels.system_matrix` (rebuild True: a copy of the constant part, on
        `refresh` or without a model) or the last one's.

        Q = G Qc G^T of the whole state (error_model.py plus extras) does not depend on the
        navigation state (the white noises are the same on the three axes of a triad, so
        C Qc C^T = Qc for any attitude C, to round-off): it is computed once per noise model,
        at the state of that step.
        """
        if self._Q is None:
            lay = self.space.layout
            n0 = lay.size
            G, Qc = noise_input(lay, nav_state, self.noise, self.clock_psd)
            Q = np.zeros((self.space.size,) * 2)
            Q[:n0, :n0] = (G * np.diag(Qc)) @ G.T
            Q[n0:, n0:] = self._Q_extra
            self._Q = Q
        if refresh or self.F_model is None:
            return self._F_constant.copy(), self._Q, True
        return self.F_model, self._Q, False

    def predicted(self, F, phi, P):
        """Take the result of a step of the model F: its transition matrix and covariance."""
        self.F_model, self.P = F, P
        self.x = phi.dot(self.x)  # (the array's dot: the same BLAS product as @, cheaper)

    def predict(self, nav_state, f_b, w_ib_b, dt, refresh=True):
        """Propagate x and P over dt with the model frozen at the given state.

        Parameters
        ----------
        nav_state : NavState
        f_b, w_ib_b : array_like, shape (3,)
            Compensated specific force and angular rate, body FLU (m/s^2, rad/s).
        dt : float
            Step, s.
        refresh : bool
            Rebuild F from the arguments (True), or reuse the F of the last refresh (the caller
            decides how often the model changes enough to matter).

        Returns
        -------
        phi : (n, n) ndarray
            Transition matrix of the step (kept by the navigator for the RTS smoother).
        """
        F, Q, rebuild = self.model(nav_state, refresh)
        # The system matrix and both Picard series in one compiled call
        # (discretize.picard_transition, picard_predict).
        phi, P = _kernels.covariance_step(
            F, rebuild, float(nav_state.lat), float(nav_state.h), _vector(nav_state.v_enu),
            _vector(nav_state.q_nb), _vector(f_b), _vector(w_ib_b), WGS84.kernel_params,
            self.space.layout.sensor_plan, MISALIGN_COLUMNS, np.ascontiguousarray(self.P, float),
            Q, float(dt), int(self.order))
        self.predicted(F, phi, P)
        return phi

    def update(self, name, t, z, H, R, gate_prob=DEFAULT_GATE_PROB, force=False, held=None):
        """Measurement update with chi-square innovation gating.

        Parameters
        ----------
        name : str
            Measurement kind, for the report.
        t : float
            Epoch, s.
        z : array_like, shape (m,)
            Measurement residual "predicted minus measured" (the filter's z, seed 004 2.1.3).
        H : array_like, shape (m, n)
        R : array_like, shape (m, m)
            Measurement noise covariance.
        gate_prob : float or None
            Chi-square gate probability; None disables gating.
        force : bool
            Update even if the gate rejects (the navigator's recovery after long rejections).
        held : array_like of int, optional
            States this update leaves as they are, beside the consider blocks': states the
            data cannot tell from others at the moment (their gain rows zero, as a consider
            block's; Navigator._held).

        Returns
        -------
        UpdateResult
        """
        z, H, R = _kernel_array(z, 1), _kernel_array(H, 2), _kernel_array(R, 2)
        if held is not None and not self.joseph:
            raise ValueError("held states need the Joseph form: (I - K H) P holds only for the "
                             "optimal gain")
        m, n = len(z), len(self.x)
        gate = chi2_gate(m, gate_prob) if gate_prob is not None else np.inf
        # One compiled call for the whole update (innovation, S, NIS, gain, state, Joseph
        # form); the numpy version spent most of its time in the overhead of some twenty
        # small-array operations.
        nu, s_diag, x, P = np.empty(m), np.empty(m), np.empty(n), np.empty((n, n))
        nis, applied = _kernels.kalman_update(
            np.ascontiguousarray(self.P, dtype=float), self.x, H, R, z, gate, force,
            self.joseph, MIN_VARIANCE,
            self.space.consider if held is None else np.union1d(self.space.consider, held),
            nu, s_diag, x, P)
        if applied:
            self.x, self.P = x, P
        ok = nis <= gate
        return UpdateResult(name, float(t), nu, s_diag, nis, gate, ok or force,
                            "ok" if ok else ("forced" if force else "gated"))

    def take_correction(self):
        """Return the estimated error state and zero it (closed-loop reset).

        The caller feeds it back (navigation errors to the strapdown, the rest to the running
        estimates). The covariance is unchanged: the reset subtracts a known quantity.
        """
        dx = self.x
        self.x = np.zeros(self.space.size)
        return dx

