"""Seven-state Kalman calibration of a magnetometer triad on a turntable (seed 004 §2.9, Lab 3).

My reading of seed 004 eqs. (2.3.4)-(2.3.6). The unit sits on a rotary-tilt table whose
heading K_et (reference, clockwise from north) is known; roll and pitch come from the unit's
own INS. The state is the seed's, all Wiener processes (F = 0):

    x = [A_E, A_N, A_U,  ΔF_x, ΔF_y, ΔF_z,  ΔK]

* A = errors of the a-priori field H_et in ENU (T), including the anomaly of the stand and the
  building (the seed's A_E, A_N, A_H with "H" up);
* ΔF = magnetometer zero offsets (hard iron), body FLU axes, T (the seed's ΔF_x,y,z are on its
  x-starboard/y-forward axes; converted by :mod:`ins_gnss_ros.nav.conventions` if needed);
* ΔK = systematic heading error of the compass, rad (the seed's ΔK_mk): the compass reads
  K_et + ΔK; physically the yaw misalignment of the triad to the base.

Measurement: the tilt-compensated field F_L = C_Lb F_b (the seed's C_{h_k,o} F_o, see
:mod:`ins_gnss_ros.magnetic.compass`) against the model

    h(x) = C_Ln(K_et + ΔK) (H_et + A) + C_Lb ΔF,      C_Ln(K) = Rz(K - π/2)

whose linearisation (∂h/∂A = C_Ln, ∂h/∂ΔF = C_Lb, ∂h/∂ΔK = [e_z×] C_Ln (H_et + A)) is the
seed's z1-z3 in FLU axes. The seed's fourth row, z4 = K_mk - K_et = ΔK + v4, is not used: K_mk is
computed from the same F_L, so to first order z4 = (F_Lx z2 - F_Ly z1) / H² carries no new
information and counting it as independent would overweight the heading.

Observability (checked by the tests): ΔF_x, ΔF_y are body-fixed while C_Ln A turns with the table,
so a full revolution separates them; ΔF_z and A_U enter the vertical row identically when level,
and a tilt (the procedure's 10°) separates them. ΔK and the anomaly component perpendicular to the
horizontal field, [e_z×] H, enter identically for every table motion: only their sum, the total
heading error, is observable, and the filter splits it according to the priors. The heading
correction therefore uses both (:meth:`TurntableCalibrationKF.heading_correction`).
"""
from __future__ import annotations

import numpy as np

from ins_gnss_ros.nav.conventions import wrap_2pi, wrap_pi
from ins_gnss_ros.nav.rotations import dcm_from_euler, skew

STATES = ("anomaly_e", "anomaly_n", "anomaly_u", "offset_x", "offset_y", "offset_z",
          "heading_bias")
ANOMALY, OFFSET, HEADING = slice(0, 3), slice(3, 6), 6


def _c_ln(azimuth: float) -> np.ndarray:
    """ENU to heading-aligned level frame for an azimuth (clockwise from north)."""
    c, s = np.cos(azimuth - np.pi / 2), np.sin(azimuth - np.pi / 2)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


class TurntableCalibrationKF:
    """Seven-state magnetometer calibration filter.

    Parameters
    ----------
    field_enu : array_like, shape (3,)
        A-priori field H_et in ENU, T (e.g. ``field_elements(...).enu``).
    anomaly_std : float
        Prior σ of each anomaly component, T.
    offset_std : float
        Prior σ of each zero offset, T.
    heading_bias_std : float
        Prior σ of ΔK, rad.
    field_std : float
        σ of the white noise of each tilt-compensated field component, T.
    random_walk : float
        Wiener-process intensity of every state, (unit)/√s; 0 makes the states constants.
    """

    def __init__(self, field_enu, anomaly_std: float = 2e-6, offset_std: float = 20e-6,
                 heading_bias_std: float = np.radians(5.0), field_std: float = 100e-9,
                 random_walk: float = 0.0):
        self.h_et = np.asarray(field_enu, float)
        self.x = np.zeros(7)
        self.P = np.diag(np.r_[[anomaly_std] * 3, [offset_std] * 3, heading_bias_std] ** 2)
        self.R = field_std ** 2 * np.eye(3)
        self.q = random_walk ** 2
        self._t = None

    def predict(self, t: float):
        """Propagate to time t (s): F = 0, so only the Wiener-process noise grows P."""
        if self._t is not None and self.q > 0 and t > self._t:
            self.P += self.q * (t - self._t) * np.eye(7)
        self._t = t

    def update(self, t: float, mag_b, roll: float, pitch: float, azimuth_ref: float) -> np.ndarray:
        """Process one sample; returns the innovation (T, level frame).

        Parameters
        ----------
        t : float
            Sample time, s.
        mag_b : array_like, shape (3,)
            Magnetometer reading in body FLU axes, T (raw, or after the soft-iron correction).
        roll, pitch : float
            ROS roll and pitch from the INS, rad.
        azimuth_ref : float
            Reference heading of the table K_et, clockwise from north, rad.
        """
        self.predict(t)
        c_lb = dcm_from_euler(roll, pitch, 0.0)
        c_ln = _c_ln(azimuth_ref + self.x[HEADING])
        field_l = c_ln @ (self.h_et + self.x[ANOMALY])
        H = np.zeros((3, 7))
        H[:, ANOMALY] = c_ln
        H[:, OFFSET] = c_lb
        H[:, HEADING] = skew([0.0, 0.0, 1.0]) @ field_l
        innovation = c_lb @ np.asarray(mag_b, float) - (field_l + c_lb @ self.x[OFFSET])
        S = H @ self.P @ H.T + self.R
        K = np.linalg.solve(S, H @ self.P).T
        self.x = self.x + K @ innovation
        ikh = np.eye(7) - K @ H
        self.P = ikh @ self.P @ ikh.T + K @ self.R @ K.T  # Joseph form keeps P symmetric PSD
        return innovation

    @property
    def offsets(self) -> np.ndarray:
        """Estimated zero offsets ΔF, body FLU, T."""
        return self.x[OFFSET].copy()

    @property
    def anomaly(self) -> np.ndarray:
        """Estimated field-model error A, ENU, T."""
        return self.x[ANOMALY].copy()

    @property
    def heading_bias(self) -> float:
        """Estimated ΔK, rad."""
        return float(self.x[HEADING])

    @property
    def std(self) -> np.ndarray:
        """Standard deviations of the seven states (the seed's plot_PAh / plot_PDTxyz)."""
        return np.sqrt(np.diag(self.P))

    def heading_correction(self, declination: float) -> float:
        """Azimuth to subtract from (magnetic azimuth + model declination) to get true azimuth, rad.

        The observable total: ΔK plus the change of declination that the anomaly causes.
        """
        h = self.h_et + self.x[ANOMALY]
        return float(wrap_pi(self.x[HEADING] + declination - np.arctan2(h[0], h[1])))


def lab3_profile(rate_hz: float = 10.0, pause: float = 180.0, calibration_tilts=()):
    """Table motion of seed 004 Lab 3 (§4.3 and §6.2), sampled at ``rate_hz``.

    1. Three slow revolutions (1080°) in about 12 min, level (§6.2, T3.1);
    2. yaw steps of +10°, +20°, +30°, +60° at 5°/s with ``pause`` s after each, then back to
       the start heading and a pause (§6.2, T3.2);
    3. a 10° tilt about the longitudinal axis (roll) for ``pause`` s (§6.2);
    4. optionally one revolution at each (roll, pitch) of ``calibration_tilts`` (rad): a
       rotary-tilt table turning the tilted unit about the vertical, for the soft-iron ellipsoid
       fit (not in the seed, which calibrates offsets only).

    Returns
    -------
    t, roll, pitch, azimuth : ndarray
        Time (s), ROS roll and pitch (rad) and table heading (clockwise from north, rad).
    """
    dt = 1.0 / rate_hz
    segs = []  # (duration, roll, pitch, azimuth start, azimuth rate)

    def hold(duration, roll, pitch, az):
        segs.append((duration, roll, pitch, az, 0.0))

    def turn(angle, roll, pitch, az, rate):
        segs.append((abs(angle) / rate, roll, pitch, az, np.sign(angle) * rate))
        return az + angle

    az = turn(3 * 2 * np.pi, 0.0, 0.0, 0.0, 3 * 2 * np.pi / 720.0)
    step_rate = np.radians(5.0)
    for step in np.radians([10.0, 20.0, 30.0, 60.0]):
        az = turn(step, 0.0, 0.0, az, step_rate)
        hold(pause, 0.0, 0.0, az)
    az = turn(-np.radians(120.0), 0.0, 0.0, az, step_rate)
    hold(pause, 0.0, 0.0, az)
    hold(pause, np.radians(10.0), 0.0, az)
    for roll, pitch in calibration_tilts:
        az = turn(2 * np.pi, roll, pitch, az, 2 * np.pi / 240.0)

    t, roll, pitch, azimuth, t0 = [], [], [], [], 0.0
    for duration, r, p, a0, rate in segs:
        tau = np.arange(0.0, duration, dt)
        t.append(t0 + tau)
        roll.append(np.full_like(tau, r))
        pitch.append(np.full_like(tau, p))
        azimuth.append(a0 + rate * tau)
        t0 += len(tau) * dt
    return (np.concatenate(t), np.concatenate(roll), np.concatenate(pitch),
            wrap_2pi(np.concatenate(azimuth)))
