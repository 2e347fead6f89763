"""Tilt-compensated magnetic compass (seed 004 §2.3, eqs. 2.3.1-2.3.3).

Frames. The body frame is FLU; roll and pitch are the ROS angles of C_nb = Rz(yaw) Ry(pitch)
Rx(roll) from the INS. The heading-aligned level frame L has x along the horizontal projection of
the forward axis, y to its left and z up, so C_Lb = Ry(pitch) Rx(roll) (C_nb with yaw = 0) and
C_nL = Rz(yaw). The seed's heading-aligned frame E_k N_k H_k (E_k to starboard, N_k forward,
H up; its C_{h_k,o} of eq. 2.3.1 for body x-starboard/y-forward axes) is the same plane with
F_Nk = F_Lx and F_Ek = -F_Ly.

Heading. With the horizontal field pointing to magnetic north and the forward axis at magnetic
azimuth A (clockwise from magnetic north), F_Lx = H cos A and F_Ly = H sin A, so

    A = atan2(F_Ly, F_Lx) = atan2(-F_Ek, F_Nk)  in [0, 2π)

which is the seed's eq. 2.3.3 with the minus sign its extraction had to reconstruct. True
azimuth = magnetic azimuth + declination (declination positive east, WMM convention).
"""
from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache
from typing import TYPE_CHECKING

import numpy as np

from ins_gnss_ros.magnetic.disturbance import DisturbanceDetector, DisturbanceStatus
from ins_gnss_ros.magnetic.ellipsoid_fit import HardSoftIron
from ins_gnss_ros.nav.conventions import wrap_2pi
from ins_gnss_ros.nav.rotations import dcm_from_euler

if TYPE_CHECKING:  # field_calibration levels with this module's functions
    from ins_gnss_ros.magnetic.field_calibration import FieldCalibration


def level_field(mag_b, roll, pitch) -> np.ndarray:
    """Body field rotated into the heading-aligned level frame: F_L = Ry(pitch) Rx(roll) F_b.

    Parameters
    ----------
    mag_b : array_like, shape (..., 3)
        Calibrated magnetic field in body FLU axes, any unit.
    roll, pitch : float or array_like
        ROS roll and pitch, rad.
    """
    return np.einsum("...ij,...j->...i", level_rotation(roll, pitch), np.asarray(mag_b, float))


def level_rotation(roll, pitch) -> np.ndarray:
    """C_Lb = Ry(pitch) Rx(roll) of ROS roll and pitch (rad), shape (..., 3, 3); one attitude's
    is kept (read-only): a compass sample is levelled once for its azimuth and again by the
    field calibration (its readings, its share of the variance), and building the rotation cost
    more than the rest."""
    if np.ndim(roll) == 0 and np.ndim(pitch) == 0:
        return _level_rotation(float(roll), float(pitch))
    return dcm_from_euler(roll, pitch, np.zeros_like(np.asarray(roll, float)))


@lru_cache(maxsize=2)
def _level_rotation(roll: float, pitch: float) -> np.ndarray:
    c_lb = dcm_from_euler(roll, pitch, 0.0)
    c_lb.flags.writeable = False
    return c_lb


def magnetic_azimuth(mag_b, roll, pitch):
    """Magnetic azimuth of the forward axis, clockwise from magnetic north, [0, 2π) rad."""
    return levelled_azimuth(level_field(mag_b, roll, pitch))


def levelled_azimuth(field_level):
    """:func:`magnetic_azimuth` of a field already levelled (F_L, :func:`level_field`)."""
    return wrap_2pi(np.arctan2(field_level[..., 1], field_level[..., 0]))


def azimuth_variance(mag_b, roll: float, pitch: float, field_std: float, roll_std: float,
                     pitch_std: float) -> float:
    """Variance of the magnetic azimuth of one sample, rad².

    First-order propagation: isotropic white field noise (std ``field_std``, the unit of mag_b)
    enters through the horizontal component as σ_F² / H²; roll and pitch errors through
    ∂F_L/∂pitch = [e_y×] F_L and ∂F_L/∂roll = [(C_Ly e_x)×] F_L, projected on
    ∂A/∂F_L = (-F_Ly, F_Lx, 0) / H².
    """
    return levelled_azimuth_variance(level_field(mag_b, roll, pitch), pitch, field_std,
                                     roll_std, pitch_std)


def levelled_azimuth_variance(field_level, pitch: float, field_std: float, roll_std: float,
                              pitch_std: float) -> float:
    """:func:`azimuth_variance` of a sample already levelled (F_L, :func:`level_field`) at
    pitch (rad). In Python floats (the stacked numpy form cost ~90 us a sample), each sum and
    product in the order that form took, zero terms left out (they change no bit)."""
    f_x, f_y, f_z = np.asarray(field_level, float).tolist()
    h2 = f_x * f_x + f_y * f_y
    grad_x, grad_y = -f_y / h2, f_x / h2                      # ∂A/∂F_L, its up part 0
    cos_p, sin_p = float(np.cos(pitch)), float(np.sin(pitch))  # (numpy's, as there)
    # [(C_Ly e_x)×] F_L with C_Ly e_x = (cos p, 0, -sin p); [e_y×] F_L = (f_z, 0, -f_x)
    along_roll = grad_x * (sin_p * f_y) + grad_y * (-sin_p * f_x + -cos_p * f_z)
    along_pitch = grad_x * f_z
    roll_part, pitch_part = along_roll * roll_std, along_pitch * pitch_std
    return field_std ** 2 / h2 + roll_part ** 2 + pitch_part ** 2


@dataclass(frozen=True)
class CompassReading:
    """One heading measurement (the content of a ``mag/heading`` Heading message).

    Attributes
    ----------
    magnetic_azimuth, true_azimuth : float
        Azimuth of the forward axis from magnetic / true north, clockwise, [0, 2π) rad.
    variance : float
        Azimuth variance, rad² (the same for magnetic and true: the declination is treated as
        exact).
    declination : float
        Declination used, rad.
    """

    magnetic_azimuth: float
    true_azimuth: float
    variance: float
    declination: float


class MagneticCompass:
    """Calibrate, tilt-compensate, gate and convert magnetometer samples into headings.

    Parameters
    ----------
    calibration : HardSoftIron, optional
        Hard/soft-iron correction of the raw readings (identity if omitted).
    detector : DisturbanceDetector, optional
        Disturbance gate; while it flags, :meth:`update` returns no reading.
    heading_bias : float
        Systematic azimuth error of the installation to remove (ΔK_mk of the turntable
        calibration), rad.
    field_std, roll_std, pitch_std : float
        Noise of the calibrated field (T) and of the INS roll and pitch (rad), for the variance
        and the detector's noise floor.
    field_calibration : FieldCalibration, optional
        Calibrate in the field as the vehicle turns: ``calibration`` then comes from it, no
        reading is given before it is good enough, and its heading error joins the variance.
        Needs :meth:`set_field_model`.
    """

    def __init__(self, calibration: HardSoftIron | None = None,
                 detector: DisturbanceDetector | None = None, heading_bias: float = 0.0,
                 field_std: float = 100e-9, roll_std: float = np.radians(0.05),
                 pitch_std: float = np.radians(0.05),
                 field_calibration: FieldCalibration | None = None):
        self.calibration = calibration
        self.detector = detector
        self.heading_bias = heading_bias
        self.field_std = field_std
        self.field_calibration = field_calibration
        self._model = None  # (horizontal, up) intensity of the field model, T
        if field_calibration is not None and field_calibration.ready:
            self.calibration = field_calibration.current.calibration
        self.set_attitude_std(roll_std, pitch_std)

    def set_field_model(self, total: float, inclination: float, horizontal: float,
                        up: float) -> None:
        """The field model at the current position and date (T, rad; ``up`` = minus the WMM
        Z): the detector's reference and the field calibration's constraints."""
        if self.detector is not None:
            self.detector.set_reference(total, inclination)
        self._model = (horizontal, up)

    @property
    def calibrating(self) -> bool:
        """The field calibration is not good enough yet: no readings."""
        return self.field_calibration is not None and not self.field_calibration.ready

    def set_attitude_std(self, roll_std: float, pitch_std: float) -> None:
        """Roll and pitch error (rad) of the attitude the next samples are levelled with."""
        self.roll_std, self.pitch_std = roll_std, pitch_std
        if self.detector is not None:
            self.detector.set_noise(self.field_std, max(roll_std, pitch_std))

    def update(self, t: float, mag_raw, roll: float, pitch: float, declination: float):
        """Process one sample.

        Parameters
        ----------
        t : float
            Sample time, s.
        mag_raw : array_like, shape (3,)
            Raw magnetometer reading in body FLU axes, T.
        roll, pitch : float
            INS roll and pitch, rad.
        declination : float
            Declination at the current position, rad (e.g. from
            :func:`ins_gnss_ros.magnetic.wmm.field_elements`).

        Returns
        -------
        reading : CompassReading or None
            None while a disturbance is flagged or while :attr:`calibrating`.
        status : DisturbanceStatus or None
            The detector's verdict (None without a detector or while calibrating).
        """
        cal = self.field_calibration
        if cal is not None:
            # The levelled field's error of one reading: the sensor's noise and the tilt error
            # times the field (its vertical part turned into the horizontal).
            field_std = float(np.hypot(self.field_std, np.hypot(*self._model)
                                       * max(self.roll_std, self.pitch_std)))
            if cal.update(t, mag_raw, roll, pitch, *self._model, field_std):
                self.calibration = cal.current.calibration
                if self.detector is not None:
                    self.detector.restart()
            if not cal.ready:
                return None, None
        mag_b = self.calibration.apply(mag_raw) if self.calibration else np.asarray(mag_raw, float)
        field_level = level_field(mag_b, roll, pitch)
        status: DisturbanceStatus | None = None
        if self.detector is not None:
            status = self.detector.update(t, field_level)
            if status.disturbed:
                return None, status
        mag_az = float(wrap_2pi(levelled_azimuth(field_level) - self.heading_bias))
        var = levelled_azimuth_variance(field_level, pitch, self.field_std, self.roll_std,
                                        self.pitch_std)
        if cal is not None:
            var += cal.azimuth_variance(mag_raw, roll, pitch)
        return CompassReading(mag_az, float(wrap_2pi(mag_az + declination)), var,
                              float(declination)), status
