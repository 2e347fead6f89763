"""Deterministic IMU calibration: the "passport" of a gyro and an accelerometer triad.

Seed 004 §2.3 lists what the prototype and ISON-1 compensate before the navigation algorithms see
the data: bias and scale factor with their temperature drift (compensated to 0.01 °/s/°C for the
gyros and 0.0003 m/s²/°C for the accelerometers), axis non-orthogonality, gyro g-sensitivity,
the mounting ("привязка") matrix C_o,b of the sensor block, and on top of that, at every filter
step, the biases and scale factors estimated by the Kalman filter (feedback).

Per triad (Groves, "Principles of GNSS, Inertial and Multisensor Integrated Navigation", 2nd ed.,
§4.4.5, written in its inverse, "correction" form):

    x_s = M(T) (x_raw - b(T))          M(T) = I + diag(s(T)) + N

with b(T) and s(T) polynomials in (T - T_ref), N the non-orthogonality (zero diagonal) and x_s the
calibrated reading in the orthogonalised sensor frame. The gyro also sees the specific force:
ω_raw contains G f_s (g-sensitivity, rad/s per m/s²). The mounting rotation C_bs takes sensor-frame
vectors to base_link (FLU). The filter's running estimates of the errors left after that
(:class:`~ins_gnss_ros.nav.increments.SensorErrors`, resolved in base_link) are modelled as
x_cal = (1 + δs) x + δb (element-wise), so the output is x = (x_cal - δb) / (1 + δs).

Temperatures are in °C (sensor_msgs/Temperature); angular rate rad/s, specific force m/s².
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ins_gnss_ros.nav.increments import SensorErrors
from ins_gnss_ros.params_io import load_yaml_file
from ins_gnss_ros.nav.rotations import dcm_from_euler


def _array(value, name: str, shape=None) -> np.ndarray:
    """Float array named ``name``, checked for shape and finiteness (ValueError names the field)."""
    try:
        a = np.array(value, dtype=float)
    except (TypeError, ValueError) as exc:
        raise ValueError(f"{name}: not numeric ({exc})") from None
    if shape is not None and a.shape != shape:
        raise ValueError(f"{name}: shape {a.shape}, expected {shape}")
    if not np.all(np.isfinite(a)):
        raise ValueError(f"{name}: contains NaN or inf")
    return a


def _poly(value, name: str) -> np.ndarray:
    """Temperature polynomial coefficients as shape (K, 3); a bare 3-vector means K = 1."""
    a = _array(value, name)
    if a.ndim == 1:
        a = a[None, :]
    if a.ndim != 2 or a.shape[1] != 3 or a.shape[0] < 1:
        raise ValueError(f"{name}: shape {a.shape}, expected (3,) or (K, 3)")
    return a


def _rows(a: np.ndarray) -> tuple:
    """A 3x3 array as a tuple of row tuples of Python floats."""
    return tuple(map(tuple, a.tolist()))


def _matvec(rows: tuple, x) -> tuple:
    """rows @ x for a 3x3 matrix given as row tuples and a 3-vector, in Python floats."""
    (a, b, c), (d, e, f), (g, h, i) = rows
    x0, x1, x2 = x
    return a * x0 + b * x1 + c * x2, d * x0 + e * x1 + f * x2, g * x0 + h * x1 + i * x2


def _minus(x, y) -> tuple:
    """x - y for 3-vectors, in Python floats."""
    return x[0] - y[0], x[1] - y[1], x[2] - y[2]


def _polyval(coeffs: np.ndarray, dt) -> np.ndarray:
    """sum_k c_k dt^k for every axis; dt scalar or (N,), result (3,) or (N, 3)."""
    dt = np.asarray(dt, float)
    powers = dt[..., None] ** np.arange(coeffs.shape[0])
    return powers @ coeffs


@dataclass
class TriadCalibration:
    """Bias, scale factor (both temperature polynomials) and non-orthogonality of one triad.

    Attributes
    ----------
    bias : ndarray, shape (K, 3)
        Coefficients of b(T) = sum_k bias[k] (T - t_ref)^k, sensor units (rad/s or m/s²) per °C^k.
    scale : ndarray, shape (K, 3)
        Coefficients of the scale-factor error s(T), dimensionless per °C^k.
    nonorthogonality : ndarray, shape (3, 3)
        N: off-diagonal coupling (rad); the diagonal must be zero (it belongs to ``scale``).
    """

    bias: np.ndarray = field(default_factory=lambda: np.zeros((1, 3)))
    scale: np.ndarray = field(default_factory=lambda: np.zeros((1, 3)))
    nonorthogonality: np.ndarray = field(default_factory=lambda: np.zeros((3, 3)))
    label: str = field(default="triad", repr=False, compare=False)

    def __post_init__(self):
        # Normalise and check the arrays; a ValueError names the field as ``label.field``.
        prefix = self.label
        self.bias = _poly(self.bias, f"{prefix}.bias")
        self.scale = _poly(self.scale, f"{prefix}.scale")
        self.nonorthogonality = _array(self.nonorthogonality, f"{prefix}.nonorthogonality", (3, 3))
        if np.any(np.diag(self.nonorthogonality) != 0.0):
            raise ValueError(f"{prefix}.nonorthogonality: diagonal must be zero "
                             "(scale-factor errors belong in scale)")

    def matrix(self, dtemp) -> np.ndarray:
        """M(T) = I + diag(s(T)) + N, shape (3, 3) or (N, 3, 3) for (N,) temperatures."""
        s = _polyval(self.scale, dtemp)
        return np.eye(3) + s[..., None] * np.eye(3) + self.nonorthogonality

    def bias_at(self, dtemp) -> np.ndarray:
        """b(T), shape (3,) or (N, 3)."""
        return _polyval(self.bias, dtemp)

    def correct(self, raw, dtemp) -> np.ndarray:
        """x_s = M (x_raw - b): calibrated sensor-frame reading, raw shape (3,) or (N, 3)."""
        m = self.matrix(dtemp)
        return np.einsum("...ij,...j->...i", m, np.asarray(raw, float) - self.bias_at(dtemp))

    def distort(self, true, dtemp) -> np.ndarray:
        """Forward model x_raw = M^-1 x_s + b (the exact inverse of :meth:`correct`)."""
        m = np.broadcast_to(self.matrix(dtemp), np.shape(true) + (3,))
        return np.linalg.solve(m, np.asarray(true, float)[..., None])[..., 0] + self.bias_at(dtemp)

    def to_dict(self) -> dict:
        return {"bias": self.bias.tolist(), "scale": self.scale.tolist(),
                "nonorthogonality": self.nonorthogonality.tolist()}


@dataclass
class ImuCalibration:
    """Complete calibration of a six-axis IMU, from raw sensor readings to base_link.

    Attributes
    ----------
    gyro, accel : TriadCalibration
        Per-triad bias/scale/non-orthogonality (rad/s and m/s²).
    gyro_g_sensitivity : ndarray, shape (3, 3)
        G, rad/s per m/s²: the gyro reads G f_s in addition to the rate (f_s sensor-frame specific
        force).
    mounting_rpy : ndarray, shape (3,)
        Roll, pitch, yaw (rad, ROS convention) of C_bs, the rotation taking sensor-frame vectors
        into base_link (FLU).
    temperature_ref : float
        T_ref of the temperature polynomials, °C. Readings without a temperature use T_ref.

    The arrays are read-only after construction: C_bs, and for :meth:`correct_sample` the
    matrices as Python floats, are derived from them once.
    """

    gyro: TriadCalibration = field(default_factory=TriadCalibration)
    accel: TriadCalibration = field(default_factory=TriadCalibration)
    gyro_g_sensitivity: np.ndarray = field(default_factory=lambda: np.zeros((3, 3)))
    mounting_rpy: np.ndarray = field(default_factory=lambda: np.zeros(3))
    temperature_ref: float = 20.0

    def __post_init__(self):
        self.gyro_g_sensitivity = _array(self.gyro_g_sensitivity, "gyro_g_sensitivity", (3, 3))
        self.mounting_rpy = _array(self.mounting_rpy, "mounting_rpy", (3,))
        self.temperature_ref = float(_array(self.temperature_ref, "temperature_ref", ()))
        self.c_bs = dcm_from_euler(*self.mounting_rpy)
        # For correct_sample: C_bs and G as row tuples, and (temperature, [(M, b) of the
        # accelerometer, (M, b) of the gyro]) at the last temperature it saw.
        self._c_bs_rows, self._g_rows = _rows(self.c_bs), _rows(self.gyro_g_sensitivity)
        self._at = None

    def _dtemp(self, temperature):
        return 0.0 if temperature is None else np.asarray(temperature, float) - self.temperature_ref

    def correct(self, gyro_raw, accel_raw, temperature=None, errors: SensorErrors | None = None):
        """Raw readings to calibrated angular rate and specific force in base_link.

        Parameters
        ----------
        gyro_raw, accel_raw : array_like, shape (3,) or (N, 3)
            Raw sensor-frame readings, rad/s and m/s².
        temperature : float or array_like (N,), optional
            Sensor temperature, °C.
        errors : SensorErrors, optional
            The filter's estimates of the errors left after calibration, removed as well.

        Returns
        -------
        omega_b, f_b : ndarray, shape like the inputs
            Angular rate (rad/s) and specific force (m/s²) in base_link (FLU).
        """
        dt = self._dtemp(temperature)
        f_s = self.accel.correct(accel_raw, dt)
        # g-sensitivity is driven by the true specific force; the corrected accelerometer is the
        # best available estimate of it.
        w_raw = np.asarray(gyro_raw, float) - f_s @ self.gyro_g_sensitivity.T
        w_s = self.gyro.correct(w_raw, dt)
        w_b, f_b = w_s @ self.c_bs.T, f_s @ self.c_bs.T
        if errors is not None:
            # Rates are the increments over 1 s: (x - b 1.0) / (1 + s) is (x - b) / (1 + s)
            # bit for bit.
            w_b, f_b = errors.compensate(w_b, f_b, 1.0)
        return w_b, f_b

    def correct_sample(self, gyro_raw, accel_raw, temperature: float | None = None,
                       errors: SensorErrors | None = None) -> tuple[tuple, tuple]:
        """:meth:`correct` for one sample in Python floats: (ωx, ωy, ωz), (fx, fy, fz) tuples.

        The per-sample path of the imu_preprocessor, where numpy's per-call overhead on 3-vectors
        cost about ten times the arithmetic. Same formula, term for term; a 3x3 product may
        differ from numpy's in the last bit (numpy's einsum and BLAS kernels may fuse
        multiply-adds, depending on the CPU; Python rounds every operation, on any machine).
        M(T) and b(T) are kept until the temperature changes: the polynomials cost more than the
        correction, and a sensor's temperature changes far more slowly than it samples (or is
        not measured at all).
        """
        if self._at is None or self._at[0] != temperature:
            dt = self._dtemp(temperature)
            self._at = (temperature, [(_rows(t.matrix(dt)), tuple(t.bias_at(dt).tolist()))
                                      for t in (self.accel, self.gyro)])
        (m_accel, b_accel), (m_gyro, b_gyro) = self._at[1]
        f_s = _matvec(m_accel, _minus(accel_raw, b_accel))
        # g-sensitivity: see correct().
        w_raw = _minus(gyro_raw, _matvec(self._g_rows, f_s))
        w_s = _matvec(m_gyro, _minus(w_raw, b_gyro))
        w_b, f_b = _matvec(self._c_bs_rows, w_s), _matvec(self._c_bs_rows, f_s)
        if errors is not None:
            return errors.compensate_rates(w_b, f_b)
        return w_b, f_b

    def simulate_raw(self, omega_b, f_b, temperature=None, errors: SensorErrors | None = None):
        """Forward model: true base_link rate and specific force to raw readings.

        The exact inverse of :meth:`correct` (same arguments and shapes, reversed roles).
        """
        dt = self._dtemp(temperature)
        w_b, f_b = np.asarray(omega_b, float), np.asarray(f_b, float)
        if errors is not None:  # the SensorErrors model forwards: (1 + s) x + b
            w_b = (1.0 + errors.gyro_scale) * w_b + errors.gyro_bias
            f_b = (1.0 + errors.accel_scale) * f_b + errors.accel_bias
        w_s, f_s = w_b @ self.c_bs, f_b @ self.c_bs
        accel_raw = self.accel.distort(f_s, dt)
        gyro_raw = self.gyro.distort(w_s, dt) + f_s @ self.gyro_g_sensitivity.T
        return gyro_raw, accel_raw

    def to_dict(self) -> dict:
        """Plain dict of lists and floats (YAML-able); inverse of :meth:`from_dict`."""
        return {"gyro": self.gyro.to_dict(), "accel": self.accel.to_dict(),
                "gyro_g_sensitivity": self.gyro_g_sensitivity.tolist(),
                "mounting_rpy": self.mounting_rpy.tolist(),
                "temperature_ref": self.temperature_ref}

    @classmethod
    def from_dict(cls, d: dict) -> "ImuCalibration":
        """Build from a plain dict; missing entries default to the ideal sensor.

        Raises
        ------
        ValueError
            Unknown keys, or a field with a bad shape or non-finite values (the message names
            the field, e.g. ``gyro.bias``).
        """
        known = {"gyro", "accel", "gyro_g_sensitivity", "mounting_rpy", "temperature_ref"}
        unknown = set(d) - known
        if unknown:
            raise ValueError(f"unknown calibration fields: {sorted(unknown)}")
        triads = {}
        for name in ("gyro", "accel"):
            sub = d.get(name) or {}
            extra = set(sub) - {"bias", "scale", "nonorthogonality"}
            if extra:
                raise ValueError(f"{name}: unknown fields {sorted(extra)}")
            triads[name] = TriadCalibration(label=name, **sub)
        return cls(gyro=triads["gyro"], accel=triads["accel"],
                   gyro_g_sensitivity=d.get("gyro_g_sensitivity", np.zeros((3, 3))),
                   mounting_rpy=d.get("mounting_rpy", np.zeros(3)),
                   temperature_ref=d.get("temperature_ref", 20.0))



def read_calibration_file(path) -> dict:
    """The calibration dict of a YAML file: ``imu_calibrate``'s output (key ``imu_calibration``)
    or the bare :meth:`ImuCalibration.to_dict` dict (for :meth:`ImuCalibration.from_dict`).

    Raises
    ------
    ValueError
        The file cannot be read, is not safe YAML (:mod:`ins_gnss_ros.params_io`) or holds no
        dict.
    """
    d = load_yaml_file(path)
    if isinstance(d, dict) and "imu_calibration" in d:
        d = d["imu_calibration"]
    if not isinstance(d, dict):
        raise ValueError(f"{path} holds no calibration dict")
    return d
