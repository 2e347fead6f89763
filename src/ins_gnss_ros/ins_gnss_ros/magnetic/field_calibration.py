"""In-field hard/soft-iron calibration of a vehicle's magnetometer from the turns it drives.

A land vehicle or a ship turns about its vertical only, so its raw readings m = A b + c trace a
tilted ellipse, not an ellipsoid: the 3-D fit of :mod:`ins_gnss_ros.magnetic.ellipsoid_fit`
(which needs readings spread over all attitudes) is degenerate there. The geometric approach of
Vasconcelos et al. ("Geometric approach to strapdown magnetometer calibration in sensor frame",
IEEE TAES 2011) still applies once the field model supplies what the motion cannot: with the INS
roll and pitch, the calibrated field b = W (m - c) levelled into the heading-aligned frame L
(:func:`ins_gnss_ros.magnetic.compass.level_field`) must have the WMM horizontal intensity H as
its horizontal magnitude and the WMM vertical component as its vertical one (the two-step
"heading-invariant" constraints of Gebre-Egziabher et al., "Calibration of strapdown
magnetometers in magnetic field domain", J. Aerosp. Eng. 2006, with the magnitude split into
its horizontal and vertical parts). The product c_z + W_zz B_z stays inseparable from yaw
motion alone, so the soft-iron matrix W gets a Gaussian prior about the identity (a maximum
a-posteriori fit): what the turns do not show stays at the prior, and its uncertainty stays in
the result. W is general but for a rotation about the
vertical: the sensor's non-orthogonality makes the distortion unsymmetric, and a rotation of the
triad about a horizontal axis tilts the field, which the vertical constraint sees (a symmetric W
leaves that as a heading error of the tilt times the field's vertical over horizontal ratio).

The fit's covariance, propagated to the azimuth (:meth:`FieldCalibration.azimuth_variance`),
is the calibration's own heading error: at every heading the compass publishes it as part of the
variance, and the worst over a full circle decides when the calibration is good enough to
publish at all. A rotation of the triad about the vertical (mounting, the antisymmetric part of
the soft iron) looks like a constant heading offset and is left to the navigation filter's
magnetic-bias state.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.optimize import least_squares

from ins_gnss_ros.magnetic.ellipsoid_fit import HardSoftIron
from ins_gnss_ros.magnetic.compass import level_rotation, magnetic_azimuth

#: The elements of W the fit estimates, each a set of (row, column) sharing one value: all
#: but the antisymmetric part of the horizontal pair, a rotation about the vertical that no
#: field constraint sees (a heading offset: the navigation filter's magnetic-bias state).
_W_ELEMENTS = (((0, 0),), ((1, 1),), ((2, 2),), ((0, 1), (1, 0)), ((0, 2),), ((2, 0),),
               ((1, 2),), ((2, 1),))
_W_IDENTITY = np.array([1.0, 1.0, 1.0, 0.0, 0.0, 0.0, 0.0, 0.0])
_N_PARAMS = 3 + len(_W_ELEMENTS)


@dataclass(frozen=True)
class FieldCalibrationConfig:
    """Settings of :class:`FieldCalibration`.

    Attributes
    ----------
    spacing : float
        Smallest angle (rad, as a fraction of the horizontal field) between two kept readings:
        a vehicle standing or driving straight adds nothing new.
    max_samples : int
        Readings kept at most (the first well-spread ones).
    min_samples : int
        Readings before the first fit.
    soft_iron_sigma : float
        Prior sigma of each element of W about the identity, - (a car's soft iron and a MEMS
        sensor's scale and cross-axis errors are a few per cent).
    max_heading_sigma : float
        Largest worst-heading calibration error of a calibration that is used, rad.
    max_gap : float
        Largest gap between the calibrated azimuths of the kept readings of a calibration that
        is used, rad. From an arc of less than half a circle the fit is far from linear (the
        circle fitting's known bias on a short arc) and its covariance understates the error
        two- to three-fold (test/magnetic/test_field_calibration.py); from half a circle on
        the worst error stays within twice the worst sigma.
    refit_interval : float
        Shortest time between two fits, s.
    """

    spacing: float = np.radians(5.0)
    max_samples: int = 360
    min_samples: int = 12
    soft_iron_sigma: float = 0.05
    max_heading_sigma: float = np.radians(2.0)
    max_gap: float = np.pi
    refit_interval: float = 1.0


#: Readings beyond this ratio to the expected field (either way) are in other units than tesla.
UNIT_RATIO = 100.0
#: Units a driver may publish the field in, as readings over the field in tesla.
FIELD_UNITS = {"milligauss": 1e7, "gauss": 1e4, "microtesla": 1e6, "nanotesla": 1e9}


@dataclass(frozen=True)
class FitResult:
    """One fit: the correction, its parameter covariance and its worst heading error.

    Attributes
    ----------
    calibration : HardSoftIron
    covariance : ndarray, shape (11, 11)
        Of (c / B, the elements of W), the parametrisation of :func:`fit_level_constraints`.
    heading_sigma : float
        Largest azimuth error over a full circle at level, rad.
    residual_rms : float
        RMS of the field residuals, T.
    samples : int
    scale : float
        The field magnitude B the offset is normalised by, T.
    gap : float
        Largest gap between the calibrated azimuths of the readings, rad.
    """

    calibration: HardSoftIron
    covariance: np.ndarray
    heading_sigma: float
    residual_rms: float
    samples: int
    scale: float
    gap: float


def _unpack(theta: np.ndarray, scale: float) -> tuple[np.ndarray, np.ndarray]:
    w = np.zeros((3, 3))
    for value, cells in zip(theta[3:], _W_ELEMENTS):
        for j, k in cells:
            w[j, k] = value
    return theta[:3] * scale, w


def _pack(cal: HardSoftIron, scale: float) -> np.ndarray:
    return np.r_[cal.offset / scale, [cal.matrix[cells[0]] for cells in _W_ELEMENTS]]


def azimuth_gradient(cal: HardSoftIron, raw, roll, pitch, scale: float) -> np.ndarray:
    """d(magnetic azimuth)/d(c / scale, the elements of W) of readings ``raw`` (n, 3) at
    ``roll``, ``pitch`` (n,) (or one reading (3,) at one attitude), shape (n, 11).
    A = atan2(L_y, L_x) with L = C_Lb W (m - c)."""
    raw = np.atleast_2d(np.asarray(raw, float))
    d = raw - cal.offset
    c_lb = np.broadcast_to(level_rotation(roll, pitch), (len(raw), 3, 3))
    lev = np.einsum("nij,nj->ni", c_lb, d @ cal.matrix.T)
    h2 = lev[:, 0] ** 2 + lev[:, 1] ** 2
    g_l = np.column_stack([-lev[:, 1], lev[:, 0], np.zeros(len(lev))]) / h2[:, None]
    g_b = np.einsum("nij,ni->nj", c_lb, g_l)                    # dA/db
    g_c = -(g_b @ cal.matrix) * scale                            # b = W (m - c)
    g_w = [sum(g_b[:, j] * d[:, k] for j, k in cells) for cells in _W_ELEMENTS]  # g_b,j d_k
    return np.column_stack([g_c, *g_w])


def fit_level_constraints(raw, roll, pitch, horizontal: float, up: float, field_std: float,
                          soft_iron_sigma: float) -> tuple[HardSoftIron, np.ndarray, float]:
    """Hard/soft iron from readings of a vehicle that turns about its vertical.

    Parameters
    ----------
    raw : array_like, shape (n, 3)
        Raw readings, body FLU, T.
    roll, pitch : array_like, shape (n,)
        INS roll and pitch of each reading, rad.
    horizontal, up : float
        The field model's horizontal intensity H and upward component (minus the WMM Z), T.
    field_std : float
        Noise of one reading's levelled field per axis (sensor noise and the tilt error times
        the field), T.
    soft_iron_sigma : float
        Prior sigma of the elements of W about the identity.

    Returns
    -------
    calibration : HardSoftIron
    covariance : ndarray, shape (11, 11)
        Of (c / B, the elements of W), scaled up by the residuals' chi-square where they
        exceed ``field_std`` (a model or a disturbance the fit cannot explain).
    residual_rms : float
        T.
    """
    raw = np.asarray(raw, float)
    roll, pitch = np.asarray(roll, float), np.asarray(pitch, float)
    scale = float(np.hypot(horizontal, up))
    c_lb = level_rotation(roll, pitch)
    sigma = field_std / scale

    def residual(theta):
        c, w = _unpack(theta, scale)
        lev = np.einsum("nij,nj->ni", c_lb, (raw - c) @ w.T) / scale
        meas = np.r_[np.hypot(lev[:, 0], lev[:, 1]) - horizontal / scale, lev[:, 2] - up / scale]
        return np.r_[meas / sigma, (theta[3:] - _W_IDENTITY) / soft_iron_sigma]

    start = HardSoftIron(_circle_centre(raw, c_lb, up), np.eye(3))
    theta0 = _pack(start, scale)
    sol = least_squares(residual, theta0, method="lm")
    n = len(raw)
    meas = sol.fun[:2 * n] * sigma * scale
    rms = float(np.sqrt(np.mean(meas ** 2)))
    covariance = np.linalg.pinv(sol.jac.T @ sol.jac)
    dof = max(2 * n - _N_PARAMS, 1)
    chi2 = float(np.sum(sol.fun[:2 * n] ** 2)) / dof
    covariance *= max(chi2, 1.0)
    c, w = _unpack(sol.x, scale)
    return HardSoftIron(c, w), covariance, rms


def _circle_centre(raw: np.ndarray, c_lb: np.ndarray, up: float) -> np.ndarray:
    """Hard-iron start of the fit: the centre of the levelled readings' horizontal circle by
    the linear least squares of Kasa ("A circle fitting procedure and its error analysis",
    IEEE Trans. Instrum. Meas. 1976), x^2 + y^2 = 2 a x + 2 b y + k, and the mean vertical
    minus the model's (soft iron and the tilt of the offset neglected)."""
    lev = np.einsum("nij,nj->ni", c_lb, raw)
    design = np.column_stack([2.0 * lev[:, 0], 2.0 * lev[:, 1], np.ones(len(lev))])
    (a, b, _), *_ = np.linalg.lstsq(design, lev[:, 0] ** 2 + lev[:, 1] ** 2, rcond=None)
    return np.array([a, b, np.mean(lev[:, 2]) - up])


#: A new fit is adopted when its worst-heading error is below this fraction of the one in use.
ADOPT_RATIO = 0.8


class FieldCalibration:
    """Collects well-spread readings as the vehicle turns and fits the calibration from them.

    Parameters
    ----------
    config : FieldCalibrationConfig
    stored : HardSoftIron, optional
        A calibration from an earlier run, used until a fit is better.
    stored_heading_sigma : float
        Its worst-heading error, rad.
    """

    def __init__(self, config: FieldCalibrationConfig = FieldCalibrationConfig(),
                 stored: HardSoftIron | None = None, stored_heading_sigma: float = 0.0):
        self.config = config
        self._raw: list[np.ndarray] = []
        self._tilt: list[tuple[float, float]] = []
        self.fit: FitResult | None = None      # the latest fit, used or not
        self.current = None if stored is None else \
            FitResult(stored, np.zeros((_N_PARAMS, _N_PARAMS)), float(stored_heading_sigma),
                      np.nan, 0, 1.0, 0.0)
        self._stored = stored is not None
        self._new_samples = 0
        self._last_fit_t = -np.inf

    @property
    def samples(self) -> int:
        return len(self._raw)

    def add(self, raw, roll: float, pitch: float, horizontal: float) -> bool:
        """Keep a reading if it is at least ``spacing`` from every kept one; True if kept."""
        raw = np.asarray(raw, float)
        if len(self._raw) >= self.config.max_samples:
            return False
        if self._raw:
            dist = np.min(np.linalg.norm(np.asarray(self._raw) - raw, axis=1))
            if dist < self.config.spacing * horizontal:
                return False
        self._raw.append(raw)
        self._tilt.append((roll, pitch))
        self._new_samples += 1
        return True

    def update(self, t: float, raw, roll: float, pitch: float, horizontal: float, up: float,
               field_std: float) -> bool:
        """One reading at t (s): keep it if new (:meth:`add`) and fit at most every
        ``refit_interval`` (:meth:`refit`); True when the calibration in use changed."""
        self.add(raw, roll, pitch, horizontal)
        if t - self._last_fit_t < self.config.refit_interval:
            return False
        changed = self.refit(horizontal, up, field_std)
        if self.fit is not None:
            self._last_fit_t = t
        return changed

    def refit(self, horizontal: float, up: float, field_std: float) -> bool:
        """Fit the kept readings (when there are new ones) and adopt the fit if it is good
        enough and better than the calibration in use; True when the calibration changed."""
        if self._new_samples == 0 or len(self._raw) < self.config.min_samples:
            return False
        self._new_samples = 0
        roll, pitch = np.asarray(self._tilt).T
        try:  # each fit from the circle's centre: a poor earlier fit is no start
            cal, cov, rms = fit_level_constraints(self._raw, roll, pitch, horizontal, up,
                                                  field_std, self.config.soft_iron_sigma)
        except ValueError:  # no invertible correction: the readings do not determine one yet
            return False
        azimuth = np.sort(magnetic_azimuth(cal.apply(self._raw), roll, pitch))
        gap = float(np.max(np.diff(np.r_[azimuth, azimuth[0] + 2.0 * np.pi])))
        self.fit = FitResult(cal, cov, worst_heading_sigma(cal, cov, horizontal, up), rms,
                             len(self._raw), float(np.hypot(horizontal, up)), gap)
        if self.fit.heading_sigma > self.config.max_heading_sigma or \
                gap > self.config.max_gap:
            return False
        # A fit replaces the one in use only when clearly better: each change restarts the
        # disturbance detector's running averages.
        if self.current is not None and \
                self.fit.heading_sigma >= ADOPT_RATIO * self.current.heading_sigma:
            return False
        self.current, self._stored = self.fit, False
        return True

    @property
    def ready(self) -> bool:
        return self.current is not None

    def azimuth_variance(self, raw, roll: float, pitch: float) -> float:
        """The calibration's contribution to the variance of this reading's azimuth, rad^2."""
        cur = self.current
        g = azimuth_gradient(cur.calibration, raw, roll, pitch, cur.scale)[0]
        return float(g @ cur.covariance @ g)

    def state(self) -> str:
        """One line for /diagnostics: what the calibration waits for, or what it is."""
        cfg, cur, fit = self.config, self.current, self.fit
        limit = np.degrees(cfg.max_heading_sigma)
        if cur is not None:
            what = "stored calibration" if self._stored else f"fit of {cur.samples} readings"
            return f"calibrated: {what}, worst heading sigma {np.degrees(cur.heading_sigma):.2f} deg"
        if fit is None:
            return (f"collecting readings while the vehicle turns: {len(self._raw)} of "
                    f"{cfg.min_samples} for a first fit")
        # Readings orders of magnitude off the Earth's field are in other units (hard iron near
        # a motor stays within tens of times the field): say so rather than ask for more turns
        # (the simulated car's readings in gauss never calibrated).
        ratio = float(np.median(np.linalg.norm(self._raw, axis=1))) / fit.scale
        if not 1.0 / UNIT_RATIO < ratio < UNIT_RATIO:
            unit = min(FIELD_UNITS, key=lambda u: abs(np.log10(ratio / FIELD_UNITS[u])))
            return (f"not calibrated: the readings are {ratio:.3g} x the Earth's field here "
                    f"({1e6 * fit.scale:.0f} uT): imu/mag_raw in {unit}? sensor_msgs/"
                    "MagneticField is in tesla")
        return (f"not yet calibrated: worst heading sigma {np.degrees(fit.heading_sigma):.1f} deg "
                f"(limit {limit:.1f}), azimuths seen with a gap of {np.degrees(fit.gap):.0f} deg "
                f"(limit {np.degrees(cfg.max_gap):.0f}) in {fit.samples} readings: turn through "
                f"more headings")


def worst_heading_sigma(cal: HardSoftIron, covariance: np.ndarray, horizontal: float,
                        up: float, n: int = 72) -> float:
    """Largest azimuth sigma of a calibration (rad) over ``n`` headings at level."""
    az = np.arange(n) * (2.0 * np.pi / n)
    b_level = np.column_stack([horizontal * np.cos(az), horizontal * np.sin(az),
                               np.full(n, up)])
    raw = cal.distort(b_level)
    g = azimuth_gradient(cal, raw, np.zeros(n), np.zeros(n), float(np.hypot(horizontal, up)))
    return float(np.sqrt(np.max(np.einsum("ni,ij,nj->n", g, covariance, g))))

