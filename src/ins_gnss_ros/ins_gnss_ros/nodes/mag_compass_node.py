"""``mag_compass`` node: calibrated magnetometer + roll/pitch -> ``mag/heading`` (seed 004 §2.3).

Per ``imu/mag`` sample (base_link axes, from the ``imu_preprocessor``) the
:class:`~ins_gnss_ros.magnetic.compass.MagneticCompass` removes the vehicle's hard and soft iron
(``mag_calibrate_cli`` output or inline parameters; with ``online_calibration.enabled`` fitted
in the field as the vehicle turns, :mod:`ins_gnss_ros.magnetic.field_calibration`, nothing
published until that fit's heading error is small enough, /diagnostics ``calibration`` saying
what it waits for, and a given calibration taken as one from an earlier run), tilt-compensates
with the latest roll and pitch (from ``ins/state``, or levelled from the accelerometer on ``imu/data`` where no INS runs)
and gates the sample with the :class:`~ins_gnss_ros.magnetic.disturbance.DisturbanceDetector`:
while a disturbance is flagged nothing is published and /diagnostics says why. An ``ins/state``
in ALIGNING that no filter has corrected yet (``correction_sequence`` 0: a strapdown
integrating from its initial-attitude parameters) has no known roll and pitch: nothing is
published from it. The roll/pitch error of the attitude source (``roll_std_deg``,
``pitch_std_deg``, or the larger tilt σ the ekf reports on ``nav/status``) enters the variance
and the detector's noise floor: a MEMS INS's tilt, uncertain by tenths of a degree, cannot show
a dip change of half a degree. The WMM
(:mod:`ins_gnss_ros.magnetic.wmm`) at the position (``gnss/fix``, else ``ins/state``, else the
``position.*`` parameters) and at the decimal year of the sample's stamp gives the declination and
the expected field the detector checks against.

The published ``ins_gnss_msgs/Heading`` is the azimuth of the body x axis, clockwise from true
north (or magnetic north with ``reference: magnetic``), with ``declination`` filled in either
case (true = magnetic + declination); pitch and roll are not observed by a compass: NaN.
"""

from __future__ import annotations

import math
import sys
from pathlib import Path

import numpy as np
from ins_gnss_msgs.msg import FilterStatus, Heading, InsState
from sensor_msgs.msg import Imu, MagneticField, NavSatFix, NavSatStatus

from ..io import stamp_to_sec
from ..magnetic.compass import MagneticCompass
from ..magnetic.disturbance import DisturbanceDetector
from ..magnetic.ellipsoid_fit import HardSoftIron
from ..magnetic.field_calibration import FieldCalibration, FieldCalibrationConfig
from ..magnetic.wmm import FieldAlongTrack, decimal_year
from ..nav.alignment import level
from ..nav.rotations import quat_to_euler
from ..params_io import ParamsFileError, load_yaml_file
from ..tools import write_yaml
from .base import DRIVER_QOS, SENSOR_QOS, STATE_QOS, NavNode, Param, ParameterError, run
from .convert import quat, vec

_IDENTITY = [1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0]
_FILE_KEYS = {"hard_iron", "soft_iron", "heading_bias", "heading_sigma"}


class MagCompassNode(NavNode):
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

    def __init__(self, **kwargs):
        super().__init__("mag_compass", **kwargs)
        p = self.p
        calibration, heading_bias, heading_sigma, stored = self._calibration()
        self.position = (math.radians(p["position.latitude_deg"]),
                         math.radians(p["position.longitude_deg"]), p["position.altitude_m"])
        self.field = FieldAlongTrack()  # the WMM at self.position
        self._fix_seen = False
        self.attitude: tuple[float, float, float] | None = None  # (t, roll, pitch)
        self._uncorrected = False  # the latest ins/state: a strapdown never corrected
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
        self.pub = self.publisher(Heading, "mag/heading", SENSOR_QOS)
        self.subscribe(MagneticField, "imu/mag", self.on_mag, SENSOR_QOS)
        self.subscribe(NavSatFix, "gnss/fix", self.on_fix, DRIVER_QOS)
        # Read per field sample (and fix), not decoded at the navigation rate.
        self.ins_state = self.subscribe_latest(InsState, "ins/state", SENSOR_QOS,
                                             self.on_ins_state)
        if p["attitude_source"] == "imu_data":
            self.subscribe(Imu, "imu/data", self.on_imu, SENSOR_QOS)
        else:
            self.subscribe(FilterStatus, "nav/status", self.on_filter_status, STATE_QOS)

    def _calibration(self) -> tuple[HardSoftIron, float, float, bool]:
        """Hard/soft iron, heading bias (rad), the calibration's own heading sigma (rad) and
        whether one was given, from the file or the inline parameters."""
        p = self.p
        inline = {"hard_iron": list(p["calibration.hard_iron"]),
                  "soft_iron": np.reshape(p["calibration.soft_iron"], (3, 3)).tolist()}
        bias = math.radians(p["calibration.heading_bias_deg"])
        source = "calibration.*"
        defaults = {s.name: s.default for s in self.PARAMS if s.name.startswith("calibration.")}
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

    # -- inputs other than the field -------------------------------------------------------------
    def on_fix(self, msg: NavSatFix) -> None:
        self.ins_state.handle()  # as if it had been handled when it came: before the fix
        pos = (msg.latitude, msg.longitude, msg.altitude)
        if msg.status.status < NavSatStatus.STATUS_FIX or not all(map(math.isfinite, pos)):
            self.diag.count("gnss/fix without a valid position ignored", log=False)
            return
        self.position = (math.radians(pos[0]), math.radians(pos[1]), pos[2])
        self._fix_seen = True

    def on_ins_state(self, msg: InsState) -> None:
        q = quat(msg.orientation)
        if msg.mode == InsState.MODE_INVALID or not np.all(np.isfinite(q)) or \
                abs(np.linalg.norm(q) - 1.0) > 1e-3:
            self.diag.count("invalid ins/state ignored")
            return
        pos = (msg.latitude, msg.longitude, msg.altitude)
        if not self._fix_seen and all(map(math.isfinite, pos)):
            self.position = pos
        if self.p["attitude_source"] != "ins_state":
            return
        # However level it looks, the attitude of a strapdown no filter has corrected is its
        # initial-attitude parameters plus drift.
        self._uncorrected = msg.mode == InsState.MODE_ALIGNING and \
            msg.correction_sequence == 0
        if self._uncorrected:
            self.attitude = None
            return
        roll, pitch, _ = quat_to_euler(q)
        self.attitude = (stamp_to_sec(msg.header.stamp), float(roll), float(pitch))

    def on_filter_status(self, msg: FilterStatus) -> None:
        """The ekf's tilt σ (its ENU attitude-error angles about east and north) for the
        attitude of ins/state; the parameters are the floor (NaN before the filter levels)."""
        std = dict(zip(msg.state_names, msg.state_std))
        att = [std.get(f"att[{i}]", math.nan) for i in range(2)]
        tilt = max(att) if all(map(math.isfinite, att)) else 0.0
        self.compass.set_attitude_std(max(math.radians(self.p["roll_std_deg"]), tilt),
                                      max(math.radians(self.p["pitch_std_deg"]), tilt))

    def on_imu(self, msg: Imu) -> None:
        f = vec(msg.linear_acceleration)
        t = stamp_to_sec(msg.header.stamp)
        if not np.all(np.isfinite(f)) or (self._last_imu_t is not None and t <= self._last_imu_t):
            self.diag.count("imu/data sample for levelling rejected")
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
    def on_mag(self, msg: MagneticField) -> None:
        self.ins_state.handle()
        t = stamp_to_sec(msg.header.stamp)
        m = vec(msg.magnetic_field)
        if not np.all(np.isfinite(m)):
            self.diag.count("magnetometer sample rejected: non_finite")
            return
        if self._last_mag_t is not None and t <= self._last_mag_t:
            self.diag.count("magnetometer sample rejected: stamp not after the previous one")
            return
        self._last_mag_t = t
        if self._uncorrected:
            self.diag.count("ins/state not corrected by a filter yet (roll/pitch unknown): "
                            "heading withheld")
            return
        if self.attitude is None or abs(t - self.attitude[0]) > self.p["max_attitude_age_s"]:
            self.diag.count("no roll/pitch within max_attitude_age_s: heading withheld")
            return
        year = self.p["decimal_year"] or decimal_year(t)
        try:
            wmm = self.field(*self.position, year)
        except ValueError as err:
            self.diag.count(f"WMM unavailable: heading withheld ({err})")
            return
        self.compass.set_field_model(wmm.total, wmm.inclination, wmm.horizontal, -wmm.down)
        reading, status = self.compass.update(t, m, self.attitude[1], self.attitude[2],
                                              wmm.declination)
        if self.compass.field_calibration is not None:
            self._field_calibration_news()
        if self.compass.calibrating:
            self.diag.count("magnetometer not calibrated yet: heading withheld", log=False)
            return
        if reading is None:
            self.diag.count("magnetic disturbance: heading withheld")
            if status.reasons:
                self.diag.set_value("last disturbance", ", ".join(status.reasons))
            return
        true_ref = self.p["reference"] == "true"
        out = Heading(azimuth=reading.true_azimuth if true_ref else reading.magnetic_azimuth,
                      pitch=math.nan, roll=math.nan, azimuth_variance=reading.variance,
                      pitch_variance=math.nan, roll_variance=math.nan,
                      reference=Heading.REFERENCE_TRUE if true_ref else Heading.REFERENCE_MAGNETIC,
                      source=Heading.SOURCE_MAGNETIC, declination=reading.declination,
                      status=Heading.STATUS_NONE)
        out.header.stamp = msg.header.stamp
        out.header.frame_id = self.p["frame_id"]
        self.pub.publish(out)


    def _field_calibration_news(self) -> None:
        """/diagnostics of the online calibration; a newly adopted one saved for the next run."""
        cal = self.compass.field_calibration
        self.diag.set_value("calibration", cal.state())
        if cal.current is self._saved:
            return
        self._saved = cal.current
        self.get_logger().info(f"mag_compass: {cal.state()}")
        if self.p["online_calibration.save_file"]:
            write_yaml({"mag_calibration": {**cal.current.calibration.to_dict(),
                                            "heading_sigma": cal.current.heading_sigma}},
                       self.p["online_calibration.save_file"])


def main(args=None) -> int:
    return run(MagCompassNode, args)


if __name__ == "__main__":
    sys.exit(main())
