"""Strapdown inertial mechanisation in the local-level ENU frame.

Frames and state
----------------
* n: ENU navigation frame at the current position (REP-103); b: body frame FLU.
* :class:`NavState`: geodetic position (lat, lon rad; h m ellipsoidal), velocity relative to the
  Earth resolved in ENU (m/s), attitude quaternion ``q_nb`` (Hamilton, [w, x, y, z], rotates FLU
  body vectors into ENU), time t (s).

Inputs
------
Navigation-rate increments over one interval [t(k-1), t(k)] of length dt (see
:mod:`ins_gnss_ros.nav.coning`):

* ``dtheta``: rotation vector of b(k) relative to b(k-1) (coning-compensated gyro increment), rad.
* ``dv``: specific-force velocity increment resolved in b(k-1), including the rotation term
  1/2 dtheta x dv and the sculling term, m/s.

Algorithm (Savage, "Strapdown Analytics", ch. 7; Groves, "Principles of GNSS, Inertial and
Multisensor Integrated Navigation", 2nd ed., section 5.4; seed 001 B2.6, seed 004 section 2.2)
----------------------------------------------------------------------------------------
1. Velocity: dv_n = (I - 1/2 [zeta x]) C_nb(k-1) dv, with zeta = omega_in dt the rotation of
   the navigation frame over the interval, and
   v(k) = v(k-1) + dv_n + (g_n - (2 omega_ie + omega_en) x v) dt, where g_n = [0, 0, -g] is normal
   gravity (TR8350.2) and the Earth rate omega_ie, transport rate omega_en, gravity and Coriolis
   velocity are evaluated at the midpoint of the interval (predictor-corrector: one pass with
   start values, one with the midpoint of start and predicted end).
2. Position: trapezoidal velocity, lat += vn dt / (rm + h), lon += ve dt / ((rn + h) cos lat),
   h += vu dt, with the radii at the midpoint latitude and height.
3. Attitude: q_nb(k) = q_{n(k)n(k-1)} ⊗ q_nb(k-1) ⊗ q(dtheta), q_{n(k)n(k-1)} = q(-zeta).
   Like every latitude/longitude mechanisation this is singular at the poles (tan lat,
   1 / cos lat).
4. Optional vertical damping (the free-inertial height diverges with time constant
   sqrt(R / 2g) ~ 9.5 min because of the positive gravity gradient): with an external height
   h_ref, dh = h - h_ref feeds back as dh/dt -= k1 dh and dvu/dt -= k2 dh (second-order loop,
   Groves ch. 5 / Savage ch. 4). The loop is stable when k2 > 2 g / R;
   :meth:`VerticalDamping.from_bandwidth` picks critical damping at a chosen natural frequency.

Error and correction convention (shared with error_model.py and the filter)
---------------------------------------------------------------------------
Errors are "computed minus true":

* dpos_enu = position error in local ENU metres (dE = (rn + h) cos lat dlon, dN = (rm + h) dlat,
  dU = dh), dv_enu = v_computed - v_true (m/s);
* phi (rad, ENU): attitude error of the computed navigation frame, the psi/phi-angle model of
  seed 001 B2.7 and seed 004 section 2.1:

      C_nb_computed = (I - [phi x]) C_nb_true      (to first order in phi)

  i.e. C_nb_true = exp([phi x]) C_nb_computed and q_nb_true = q(phi) ⊗ q_nb_computed exactly.
  With this convention f_n_computed = f_n_true - phi x f_n_true, so d(dv)/dt contains
  + f_n x phi (= [f_n x] phi), and d(phi)/dt = -omega_in x phi + d(omega_in) - C_nb d(omega_ib).

:func:`apply_correction` removes estimated errors with exactly this convention: it subtracts
dpos and dv and rotates the attitude by q(phi) ⊗ q_nb.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from . import _kernels
from .earth import WGS84, Ellipsoid, normal_gravity, radii
from .error_model import nav_error


@dataclass
class NavState:
    """Navigation state of the IMU (navigation centre).

    Attributes
    ----------
    lat, lon : float
        Geodetic latitude and longitude, rad.
    h : float
        Ellipsoidal height, m.
    v_enu : ndarray, shape (3,)
        Velocity relative to the Earth in ENU, m/s.
    q_nb : ndarray, shape (4,)
        Attitude quaternion ENU <- FLU, [w, x, y, z].
    t : float
        Time, s.
    """

    lat: float
    lon: float
    h: float
    v_enu: np.ndarray = field(default_factory=lambda: np.zeros(3))
    q_nb: np.ndarray = field(default_factory=lambda: np.array([1.0, 0.0, 0.0, 0.0]))
    t: float = 0.0

    def __post_init__(self):
        self.v_enu = np.array(self.v_enu, dtype=float)
        self.q_nb = np.array(self.q_nb, dtype=float)

    @classmethod
    def taking(cls, lat, lon, h, v_enu, q_nb, t):
        """A state that takes the float arrays v_enu (3,) and q_nb (4,), which nothing else
        holds, as they are: the filter makes several states a sample from arrays it has just
        filled, where the constructor's copies and checks cost more than the rest."""
        state = object.__new__(cls)
        state.lat, state.lon, state.h, state.v_enu, state.q_nb, state.t = \
            lat, lon, h, v_enu, q_nb, t
        return state


@dataclass(frozen=True)
class VerticalDamping:
    """Gains of the second-order vertical-channel damping loop.

    Attributes
    ----------
    k1 : float
        Height-error feedback into the height rate, 1/s.
    k2 : float
        Height-error feedback into the vertical acceleration, 1/s^2.
    """

    k1: float
    k2: float

    @classmethod
    def from_bandwidth(cls, omega0: float, lat: float = 0.0, h: float = 0.0,
                       ell: Ellipsoid = WGS84) -> "VerticalDamping":
        """Critically damped loop with natural frequency omega0 (rad/s).

        The error obeys dh'' + k1 dh' + (k2 - 2g/R) dh = 0, so k1 = 2 omega0 and
        k2 = omega0^2 + 2g/R cancel the gravity-gradient instability.
        """
        rm, rn = radii(lat, ell)
        grad = 2.0 * normal_gravity(lat, h, ell) / (np.sqrt(rm * rn) + h)
        return cls(2.0 * omega0, omega0 ** 2 + grad)


def strapdown_step(state: NavState, dtheta, dv, dt: float, ell: Ellipsoid = WGS84,
                   h_ref: float = np.nan,
                   damping: VerticalDamping | None = None) -> NavState:
    """Advance the navigation state by one interval of increments.

    Parameters
    ----------
    state : NavState
        State at t(k-1).
    dtheta : array_like, shape (3,)
        Coning-compensated rotation vector b(k-1) -> b(k), rad, FLU.
    dv : array_like, shape (3,)
        Compensated specific-force velocity increment resolved in b(k-1), m/s, FLU.
    dt : float
        Interval length, s.
    ell : Ellipsoid
    h_ref : float
        External ellipsoidal height for vertical damping, m; NaN (default) or ``damping=None``
        leaves the vertical channel free.
    damping : VerticalDamping or None

    Returns
    -------
    NavState
        State at t(k) = t(k-1) + dt.
    """
    k1, k2 = (damping.k1, damping.k2) if damping is not None else (0.0, 0.0)
    href = h_ref if damping is not None else np.nan
    v = np.empty(3)
    q = np.empty(4)
    lat, lon, h = _kernels.mech_step(
        float(state.lat), float(state.lon), float(state.h), state.v_enu, state.q_nb,
        np.asarray(dtheta, float), np.asarray(dv, float), float(dt), ell.kernel_params,
        float(href), k1, k2, v, q)
    return NavState.taking(lat, lon, h, v, q, state.t + dt)


def run(state0: NavState, dthetas, dvs, dt: float, ell: Ellipsoid = WGS84, h_ref=None,
        damping: VerticalDamping | None = None) -> dict:
    """Mechanise a whole sequence of increments (compiled loop).

    Parameters
    ----------
    state0 : NavState
        Initial state.
    dthetas, dvs : array_like, shape (N, 3)
        Increments as in :func:`strapdown_step`.
    dt : float
        Interval length, s.
    h_ref : None, float or array_like, shape (N,)
        External height per step for vertical damping (used only with ``damping``).
    damping : VerticalDamping or None

    Returns
    -------
    dict
        ``t`` (N+1,), ``lat``, ``lon``, ``h`` (N+1,), ``v_enu`` (N+1, 3), ``q_nb`` (N+1, 4);
        row 0 is the initial state.
    """
    dthetas = np.ascontiguousarray(dthetas, dtype=float)
    dvs = np.ascontiguousarray(dvs, dtype=float)
    n = len(dthetas)
    if damping is None or h_ref is None:
        href = np.full(n, np.nan)
        k1 = k2 = 0.0
    else:
        href = np.broadcast_to(np.asarray(h_ref, float), (n,)).copy()
        k1, k2 = damping.k1, damping.k2
    lla, vel, quat = _kernels.mech_run(
        float(state0.lat), float(state0.lon), float(state0.h), state0.v_enu, state0.q_nb,
        dthetas, dvs, float(dt), ell.kernel_params, href, k1, k2)
    return {"t": state0.t + dt * np.arange(n + 1), "lat": lla[:, 0], "lon": lla[:, 1],
            "h": lla[:, 2], "v_enu": vel, "q_nb": quat}


def apply_correction(state: NavState, dpos_enu_m, dv_enu, phi_enu,
                     ell: Ellipsoid = WGS84) -> NavState:
    """Remove estimated navigation errors (closed-loop feedback from the filter).

    Parameters
    ----------
    state : NavState
        Computed (erroneous) state.
    dpos_enu_m : array_like, shape (3,)
        Position error (computed - true) in local ENU, m.
    dv_enu : array_like, shape (3,)
        Velocity error (computed - true), m/s.
    phi_enu : array_like, shape (3,)
        Attitude error, rad, with C_nb_computed = (I - [phi x]) C_nb_true (module docstring).

    Returns
    -------
    NavState
        Corrected state: position and velocity minus their errors, q_nb = q(phi) ⊗ q_nb.
    """
    v = np.empty(3)
    q = np.empty(4)
    # Compiled: the filter corrects the state at every accepted update, where numpy's
    # per-call overhead on 3- and 4-vectors was most of the cost.
    lat, lon, h = _kernels.correct(
        float(state.lat), float(state.lon), float(state.h), state.v_enu, state.q_nb,
        _vector(dpos_enu_m), _vector(dv_enu), _vector(phi_enu), ell.a, ell.e2, v, q)
    return NavState.taking(lat, lon, h, v, q, state.t)


def apply_error_state(state: NavState, dx, pos: int, vel: int, att: int,
                      ell: Ellipsoid = WGS84) -> NavState:
    """:func:`apply_correction` with the errors of the error state dx (float array), whose
    position, velocity and attitude blocks start at `pos`, `vel`, `att` (the filter's
    feedback, twice a sample on a vessel with position and heading)."""
    v = np.empty(3)
    q = np.empty(4)
    lat, lon, h = _kernels.correct_by_state(float(state.lat), float(state.lon), float(state.h),
                                            state.v_enu, state.q_nb, dx, pos, vel, att, ell.a,
                                            ell.e2, v, q)
    return NavState.taking(lat, lon, h, v, q, state.t)


def correction_to(state: NavState, target: NavState, ell: Ellipsoid = WGS84):
    """The errors (dpos_enu_m, dv_enu, phi_enu) whose removal by :func:`apply_correction` puts
    ``state`` on ``target`` exactly, however far apart they are.

    The position error is scaled with the radii at ``state``, the ones apply_correction divides
    by; the error model's :func:`nav_error` scales it at the true position, which is the same to
    first order only. A strapdown started at its parameters' position, thousands of km from
    the first fix, thus lands on the filter's solution with the first correction instead of
    converging over several while its states are published.
    """
    rm, rn = radii(state.lat, ell)
    dlon = (state.lon - target.lon + np.pi) % (2 * np.pi) - np.pi
    dp = np.array([(rn + state.h) * np.cos(state.lat) * dlon,
                   (rm + state.h) * (state.lat - target.lat),
                   state.h - target.h])
    _, dv, phi = nav_error(state, target, ell)
    return dp, dv, phi


def _vector(x) -> np.ndarray:
    """A 3-vector as a contiguous float64 array (no copy if it is one): one compiled
    signature of the kernel."""
    return np.ascontiguousarray(x, dtype=float)


class Strapdown:
    """Stateful mechanisation for streaming use (the strapdown node).

    Parameters
    ----------
    state : NavState
        Initial state.
    ell : Ellipsoid
    damping : VerticalDamping or None
        Vertical-channel damping gains; used whenever :meth:`step` gets a finite ``h_ref``.
    """

    def __init__(self, state: NavState, ell: Ellipsoid = WGS84,
                 damping: VerticalDamping | None = None):
        self.state = state
        self.ell = ell
        self.damping = damping

    def step(self, dtheta, dv, dt: float, h_ref: float = np.nan) -> NavState:
        """Advance by one interval of increments (see :func:`strapdown_step`)."""
        self.state = strapdown_step(self.state, dtheta, dv, dt, self.ell, h_ref, self.damping)
        return self.state

    def step_compensated(self, dtheta: np.ndarray, dv: np.ndarray, dt: float,
                         errors) -> np.ndarray:
        """:meth:`step` with a free vertical channel of the increments (float arrays (3,))
        compensated for ``errors`` (increments.SensorErrors) as its ``compensate`` does, in
        one compiled call (the strapdown node runs this per increment). Returns the
        compensated increments, (2, 3): angle, velocity."""
        state = self.state
        v, q, comp = np.empty(3), np.empty(4), np.empty((2, 3))
        lat, lon, h = _kernels.mech_step_compensated(
            state.lat, state.lon, state.h, state.v_enu, state.q_nb, _vector(dtheta), _vector(dv),
            dt, errors.gyro_bias, errors.gyro_scale, errors.accel_bias, errors.accel_scale,
            self.ell.kernel_params, v, q, comp)
        self.state = NavState.taking(lat, lon, h, v, q, state.t + dt)
        return comp

    def correct(self, dpos_enu_m, dv_enu, phi_enu) -> NavState:
        """Apply filter feedback (see :func:`apply_correction`)."""
        self.state = apply_correction(self.state, dpos_enu_m, dv_enu, phi_enu, self.ell)
        return self.state
