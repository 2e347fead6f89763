"""The ``mag_compass`` node's work without ROS: magnetometer samples, roll/pitch and position in,
headings out (seed 004 §2.3).

Per magnetometer sample (base_link axes, as the ``imu_preprocessor`` publishes ``imu/mag``) the
:class:`CompassFrontEnd` takes the latest roll and pitch (from an INS state, or levelled from
the accelerometer where no INS runs), the WMM (:mod:`ins_gnss_ros.magnetic.wmm`) at the
position (the last valid GNSS fix, else the INS's, else the ``position.*`` parameters) and at
the sample's date, and hands them to the
:class:`~ins_gnss_ros.magnetic.compass.MagneticCompass` (hard/soft iron, tilt compensation, the
disturbance gate, the field calibration). The ``mag_compass`` node translates messages into
these calls and publishes the readings; ``trial replay --offline`` feeds it the bag's
magnetometer and its filter's attitude, so that both paths fuse the same compass.

Every withheld sample is reported with why (``count``: the node's /diagnostics counter).
"""
from __future__ import annotations

import math
from pathlib import Path
from typing import Callable

import numpy as np

from ..nav.alignment import level
from ..nav.rotations import quat_to_euler
from ..params import Param, ParameterError
from ..params_io import ParamsFileError, load_yaml_file
from ..tools import write_yaml
from .compass import CompassReading, MagneticCompass
from .disturbance import DisturbanceDetector
from .ellipsoid_fit import HardSoftIron
from .field_calibration import FieldCalibration, FieldCalibrationConfig
from .wmm import FieldAlongTrack, decimal_year

__all__ = ["PARAMS", "CompassFrontEnd"]

_IDENTITY = [1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0]
_FILE_KEYS = {"hard_iron", "soft_iron", "heading_bias", "heading_sigma"}

#: The ``mag_compass`` node's parameters.
PARAMS = (
    Param("calibration_file", "",
          "YAML hard/soft-iron calibration (mag_calibrate_cli or online_calibration.save_file "
          "output: key mag_calibration with hard_iron, soft_iron, optional heading_bias and "
          "heading_sigma, rad); empty: the calibration.* parameters"),
    Param("calibration.hard_iron", [0.0, 0.0, 0.0],
          "hard-iron offset c in base_link (b = W (m - c)), T", -1e-3, 1e-3, length=3),
    Param("calibration.soft_iron", _IDENTITY,
          "soft-iron correction W, 3x3 row-major, dimensionless", -10.0, 10.0, length=9),
    Param("calibration.heading_bias_deg", 0.0,
          "installation azimuth error to subtract (turntable calibration), deg", -180.0, 180.0),
    Param("online_calibration.enabled", False,
          "fit the hard/soft iron in the field from the readings as the vehicle turns "
          "(the WMM horizontal and vertical field as constraints) and publish only once the "
          "fit is good enough; a calibration given above is used until a fit is better"),
    Param("online_calibration.max_heading_sigma_deg", 2.0,
          "largest heading error of the fit over a full circle for it to be used, deg",
          0.01, 45.0),
    Param("online_calibration.soft_iron_sigma", 0.05,
          "prior sigma of the soft-iron matrix elements about the identity, -", 1e-4, 1.0),
    Param("online_calibration.save_file", "",
          "write each calibration the online fit adopts here (YAML for calibration_file: "
          "the next run starts calibrated); empty: not saved"),
    Param("reference", "true", "north reference of the published azimuth",
          choices=("true", "magnetic")),
    Param("attitude_source", "ins_state",
          "roll/pitch from ins/state, or levelled from the accelerometer on imu/data (only "
          "right when the vehicle does not accelerate)", choices=("ins_state", "imu_data")),
    Param("max_attitude_age_s", 0.5,
          "largest stamp difference between a field sample and the roll/pitch used, s",
          0.0, 60.0),
    Param("level_time_constant_s", 1.0,
          "low-pass time constant of the specific force for imu_data levelling, s", 0.0, 600.0),
    Param("position.latitude_deg", 59.9, "latitude until gnss/fix or ins/state gives one, deg",
          -90.0, 90.0),
    Param("position.longitude_deg", 30.3, "longitude until a fix, deg", -180.0, 360.0),
    Param("position.altitude_m", 0.0, "ellipsoidal height until a fix, m", -1000.0, 100000.0),
    Param("decimal_year", 0.0,
          "date for the WMM, decimal year; 0: the date of each sample's stamp (set it when "
          "replaying data whose stamps are not dates)", 0.0, 2100.0),
    Param("field_std_nT", 100.0, "noise of the calibrated field per axis, nT", 0.0, 1e5),
    Param("roll_std_deg", 0.05, "roll error of the attitude source (a larger tilt sigma on "
          "nav/status is taken instead), deg", 0.0, 90.0),
    Param("pitch_std_deg", 0.05, "pitch error of the attitude source (a larger tilt sigma on "
          "nav/status is taken instead), deg", 0.0, 90.0),
    Param("disturbance.model_total_tol", 0.08,
          "relative tolerance of |F| against the WMM, -", 0.0, 10.0),
    Param("disturbance.model_inclination_deg", 4.0,
          "tolerance of the inclination against the WMM, deg", 0.0, 90.0),
    Param("disturbance.running_total_tol", 0.01,
          "relative tolerance of |F| against its running mean, -", 0.0, 10.0),
    Param("disturbance.running_inclination_deg", 0.5,
          "tolerance of the inclination against its running mean, deg", 0.0, 90.0),
    Param("disturbance.release", 0.5,
          "fraction of every tolerance below which the flag may drop, -", 0.0, 1.0),
    Param("disturbance.clear_time_s", 2.0,
          "time below the release level before the flag drops, s", 0.0, 3600.0),
    Param("disturbance.time_constant_s", 60.0, "time constant of the running means, s",
          0.1, 1e5),
    Param("frame_id", "base_link", "frame_id of mag/heading"),
)


def calibration_from_params(p: dict) -> tuple[HardSoftIron, float, float, bool]:
    """Hard/soft iron, heading bias (rad), the calibration's own heading sigma (rad) and
    whether one was given, from ``calibration_file`` or the inline ``calibration.*``."""
    inline = {"hard_iron": list(p["calibration.hard_iron"]),
              "soft_iron": np.reshape(p["calibration.soft_iron"], (3, 3)).tolist()}
    bias = math.radians(p["calibration.heading_bias_deg"])
    source = "calibration.*"
    defaults = {s.name: s.default for s in PARAMS if s.name.startswith("calibration.")}
    stored = any(p[k] != v for k, v in defaults.items())
    if p["calibration_file"]:
        if stored:
            raise ParameterError("parameter 'calibration_file': give the calibration either as "
                                 "a file or as calibration.* parameters, not both")
        path = Path(p["calibration_file"])
        try:
            d = load_yaml_file(path)
        except ParamsFileError as err:
            raise ParameterError(f"parameter 'calibration_file': {err}") from None
        d = d.get("mag_calibration", d) if isinstance(d, dict) else d
        if not isinstance(d, dict) or set(d) - _FILE_KEYS:
            raise ParameterError(f"parameter 'calibration_file': {path} is not a dict of "
                                 f"{', '.join(sorted(_FILE_KEYS))}")
        inline, bias, source = d, d.get("heading_bias", 0.0), f"calibration_file {path}"
        stored = True
    try:
        return (HardSoftIron.from_dict(inline), float(bias),
                float(inline.get("heading_sigma", 0.0)), stored)
    except (ValueError, TypeError) as err:
        raise ParameterError(f"{source}: {err}") from None


class CompassFrontEnd:
    """Magnetometer samples -> compass readings, configured by the ``mag_compass`` parameters.

    Parameters
    ----------
    p : dict
        The parameters (:data:`PARAMS`, resolved).
    count : callable
        ``count(text, log=True)``: one withheld sample or ignored input, by why.
    set_value : callable, optional
        ``set_value(key, text)``: the latest disturbance and the field calibration's state.
    info : callable, optional
        ``info(text)``: a newly adopted field calibration.

    Raises
    ------
    ParameterError
        A calibration file that does not read, or one given twice.
    """

    def __init__(self, p: dict, count: Callable[..., None],
                 set_value: Callable[[str, str], None] = lambda key, text: None,
                 info: Callable[[str], None] = lambda text: None):
        self.p, self.count, self.set_value, self.info = p, count, set_value, info
        calibration, heading_bias, heading_sigma, stored = calibration_from_params(p)
        self.position = (math.radians(p["position.latitude_deg"]),
                         math.radians(p["position.longitude_deg"]), p["position.altitude_m"])
        self.field = FieldAlongTrack()  # the WMM at self.position
        self.fix_seen = False  # a valid gnss/fix came: the WMM position is its
        self.attitude: tuple[float, float, float] | None = None  # (t, roll, pitch)
        self._uncorrected = False  # the latest INS state: a strapdown never corrected
        self._filtered = False     # ... one a filter corrects: its tilt σ is the filter's
        self._tilt_reported = False  # the filter's tilt σ is known (tilt_std)
        self._f_lp: np.ndarray | None = None                     # low-passed specific force
        self._last_imu_t: float | None = None
        self._last_mag_t: float | None = None
        # The detector's reference field is replaced from the WMM at every sample.
        detector = DisturbanceDetector(
            1.0, 0.0, p["disturbance.model_total_tol"],
            math.radians(p["disturbance.model_inclination_deg"]),
            p["disturbance.running_total_tol"],
            math.radians(p["disturbance.running_inclination_deg"]), p["disturbance.release"],
            p["disturbance.clear_time_s"], p["disturbance.time_constant_s"])
        field_calibration = None
        if p["online_calibration.enabled"]:
            field_calibration = FieldCalibration(
                FieldCalibrationConfig(
                    soft_iron_sigma=p["online_calibration.soft_iron_sigma"],
                    max_heading_sigma=math.radians(p["online_calibration.max_heading_sigma_deg"])),
                calibration if stored else None, heading_sigma)
        self.compass = MagneticCompass(calibration, detector, heading_bias,
                                       p["field_std_nT"] * 1e-9, math.radians(p["roll_std_deg"]),
                                       math.radians(p["pitch_std_deg"]), field_calibration)
        self._saved = field_calibration.current if field_calibration else None

    @property
    def true_reference(self) -> bool:
        """The published azimuth is from true north (else magnetic)."""
        return self.p["reference"] == "true"

    # -- inputs other than the field -------------------------------------------------------------
    def fix(self, lat_deg: float, lon_deg: float, altitude: float, valid: bool) -> None:
        """A GNSS fix (``valid``: it has a position): the WMM's position from now on. A 2-D
        fix (altitude NaN) puts it at sea level: the declination moves by hundredths of a
        degree per kilometre of height, far below the model's own error."""
        if not (valid and math.isfinite(lat_deg) and math.isfinite(lon_deg)):
            self.count("gnss/fix without a valid position ignored", log=False)
            return
        self.position = (math.radians(lat_deg), math.radians(lon_deg),
                         altitude if math.isfinite(altitude) else 0.0)
        self.fix_seen = True

    def ins_state(self, t: float, q_nb, position, aligning: bool, corrections: int) -> None:
        """An INS solution at t (s): attitude q_nb (Hamilton, w first), position (lat rad,
        lon rad, h m) for the WMM until a fix comes; ``aligning`` and ``corrections`` (the
        InsState's mode ALIGNING and correction_sequence): a strapdown no filter has corrected
        while aligning integrates from its initial-attitude parameters and has no known roll
        and pitch, however level it looks; one a filter corrects has the roll and pitch error
        that filter reports (:meth:`tilt_std`), not the parameters' (a MEMS filter's tilt
        sigma after levelling, about 1 deg, makes a reading's variance over ten times that of
        the parameters' 0.05 deg)."""
        q = np.asarray(q_nb, float)
        if not np.all(np.isfinite(q)) or abs(np.linalg.norm(q) - 1.0) > 1e-3:
            self.count("invalid ins/state ignored")
            return
        if not self.fix_seen and all(map(math.isfinite, position)):
            self.position = tuple(position)
        if self.p["attitude_source"] != "ins_state":
            return
        self._uncorrected = aligning and corrections == 0
        self._filtered = corrections > 0
        if self._uncorrected:
            self.attitude = None
            return
        roll, pitch, _ = quat_to_euler(q)
        self.attitude = (t, float(roll), float(pitch))

    def tilt_std(self, east: float, north: float) -> None:
        """The filter's tilt σ (its ENU attitude-error angles about east and north, rad; NaN
        before it levels): the attitude error of the compass's tilt compensation, the
        ``roll_std_deg`` / ``pitch_std_deg`` parameters its floor."""
        self._tilt_reported = math.isfinite(east) and math.isfinite(north)
        tilt = max(east, north) if self._tilt_reported else 0.0
        self.compass.set_attitude_std(max(math.radians(self.p["roll_std_deg"]), tilt),
                                      max(math.radians(self.p["pitch_std_deg"]), tilt))

    def imu(self, t: float, f) -> None:
        """A calibrated specific force sample (base_link, m/s^2), for ``attitude_source:
        imu_data``: roll and pitch levelled from it, low-passed."""
        f = np.asarray(f, float)
        if not np.all(np.isfinite(f)) or (self._last_imu_t is not None and t <= self._last_imu_t):
            self.count("imu/data sample for levelling rejected")
            return
        tau = self.p["level_time_constant_s"]
        if self._f_lp is None or tau == 0.0:
            self._f_lp = f
        else:
            gain = 1.0 - math.exp(-(t - self._last_imu_t) / tau)
            self._f_lp = self._f_lp + gain * (f - self._f_lp)
        self._last_imu_t = t
        self.attitude = (t, *level(self._f_lp))

    # -- the field ------------------------------------------------------------------------------
    def mag(self, t: float, field_b) -> CompassReading | None:
        """One magnetometer sample at t (s), base_link axes, T: its reading, or None (and
        counted why) while it is withheld."""
        m = np.asarray(field_b, float)
        if not np.all(np.isfinite(m)):
            self.count("magnetometer sample rejected: non_finite")
            return None
        if self._last_mag_t is not None and t <= self._last_mag_t:
            self.count("magnetometer sample rejected: stamp not after the previous one")
            return None
        self._last_mag_t = t
        if self._uncorrected:
            self.count("ins/state not corrected by a filter yet (roll/pitch unknown): "
                       "heading withheld")
            return None
        if self.attitude is None or abs(t - self.attitude[0]) > self.p["max_attitude_age_s"]:
            self.count("no roll/pitch within max_attitude_age_s: heading withheld")
            return None
        if self._filtered and not self._tilt_reported:
            self.count("no roll/pitch error from the filter yet (nav/status): heading withheld")
            return None
        year = self.p["decimal_year"] or decimal_year(t)
        try:
            wmm = self.field(*self.position, year)
        except ValueError as err:
            self.count(f"WMM unavailable: heading withheld ({err})")
            return None
        self.compass.set_field_model(wmm.total, wmm.inclination, wmm.horizontal, -wmm.down)
        reading, status = self.compass.update(t, m, self.attitude[1], self.attitude[2],
                                              wmm.declination)
        if self.compass.field_calibration is not None:
            self._field_calibration_news()
        if self.compass.calibrating:
            self.count("magnetometer not calibrated yet: heading withheld", log=False)
            return None
        if reading is None:
            self.count("magnetic disturbance: heading withheld")
            if status.reasons:
                self.set_value("last disturbance", ", ".join(status.reasons))
        return reading

    def _field_calibration_news(self) -> None:
        """The online calibration's state; a newly adopted one saved for the next run."""
        cal = self.compass.field_calibration
        self.set_value("calibration", cal.state())
        if cal.current is self._saved:
            return
        self._saved = cal.current
        self.info(f"mag_compass: {cal.state()}")
        if self.p["online_calibration.save_file"]:
            write_yaml({"mag_calibration": {**cal.current.calibration.to_dict(),
                                            "heading_sigma": cal.current.heading_sigma}},
                       self.p["online_calibration.save_file"])
