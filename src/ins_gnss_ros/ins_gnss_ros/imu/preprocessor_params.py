"""The ``imu_preprocessor`` node's parameters and the preprocessor they make, ROS-free.

The node declares :data:`PARAMS` to ROS; the offline replay resolves a profile's
``imu_preprocessor`` section against the same specifications
(:func:`ins_gnss_ros.params.resolve`) and builds the same
:class:`~ins_gnss_ros.imu.preprocessor.ImuPreprocessor` with :func:`preprocessor_from_params`.
"""
from __future__ import annotations

import numpy as np

from ..io import NS
from ..nav.coning import METHODS
from ..nav.increments import MAX_RATE, MAX_SPECIFIC_FORCE
from ..params import Param, ParameterError
from .calibration import ImuCalibration, read_calibration_file
from .orientation_heading import OrientationHeadings
from .preprocessor import ImuPreprocessor, SettingError

__all__ = ["PARAMS", "calibration_from_params", "preprocessor_from_params"]

_TRIAD_PARAMS = ("bias", "scale", "nonorthogonality")


def _triad_params(name: str, unit: str, bound: float) -> tuple[Param, ...]:
    return (
        Param(f"calibration.{name}.bias", [0.0, 0.0, 0.0],
              f"{name} bias polynomial b(T) = sum_k c_k (T - T_ref)^k, 3K values (x, y, z of c_0, "
              f"then of c_1, ...), {unit} per degC^k", -bound, bound),
        Param(f"calibration.{name}.scale", [0.0, 0.0, 0.0],
              f"{name} scale-factor error polynomial s(T), 3K values, dimensionless per degC^k",
              -1.0, 1.0),
        Param(f"calibration.{name}.nonorthogonality", [0.0] * 9,
              f"{name} non-orthogonality N, 3x3 row-major with zero diagonal, rad", -1.0, 1.0,
              length=9),
    )


#: The imu_preprocessor node's parameters.
PARAMS = (
    Param("calibration_file", "",
          "YAML calibration (imu_calibrate_cli output: key imu_calibration, or the bare "
          "ImuCalibration dict); empty: use the inline calibration.* parameters"),
    *_triad_params("gyro", "rad/s", 10.0),
    *_triad_params("accel", "m/s^2", 100.0),
    Param("calibration.gyro_g_sensitivity", [0.0] * 9,
          "gyro g-sensitivity G, 3x3 row-major, rad/s per m/s^2", -1.0, 1.0, length=9),
    Param("calibration.temperature_ref", 20.0,
          "reference temperature T_ref of the polynomials, degC", -100.0, 200.0),
    Param("mounting_rpy_deg", [0.0, 0.0, 0.0],
          "roll, pitch, yaw (ROS) of the rotation taking sensor-frame vectors to base_link, "
          "deg (or mounting_rpy in the calibration file, not both)", -360.0, 360.0, length=3),
    Param("rate_hz", 0.0, "nominal sensor sample rate, Hz; 0: measured from the first "
          "stamps (their samples are held until then, about 0.5 s)", 0.0, 10000.0),
    Param("nav_rate_hz", 100.0, "wanted rate of imu/delta, Hz: an increment spans the whole "
          "number of samples nearest to 1 / nav_rate_hz (the effective rate is on "
          "/diagnostics)", 1.0, 10000.0),
    Param("coning_method", "auto",
          "coning/sculling algorithm: two_sample needs an even number of samples per "
          "increment; auto takes it then, one_sample otherwise", choices=("auto", *METHODS)),
    Param("sensor_clock.enabled", True,
          "give each sample its instant on the sensor's own clock, fitted causally to the "
          "driver's jittered stamps (imu/sensor_clock.py); false: the stamps as they come"),
    Param("sensor_clock.jitter_s", 0.001, "standard deviation of the driver's stamps about "
          "the sampling instants, s", 1e-6, 0.1),
    Param("sensor_clock.time_constant_s", 30.0, "memory of the sensor-clock fit, s",
          1.0, 3600.0),
    # At most the bounds every consumer of imu/delta holds an increment to: a reading
    # passed here must not be dropped as implausible downstream.
    Param("gyro_range_dps", 2000.0,
          "gyro measurement range; |reading| >= range is saturated, deg/s", 1.0,
          float(np.degrees(MAX_RATE))),
    Param("accel_range_mps2", 160.0,
          "accelerometer range; |reading| >= range is saturated, m/s^2", 1.0,
          MAX_SPECIFIC_FORCE),
    Param("max_bridge_samples", 5,
          "longest run of missing/rejected samples bridged; longer gaps restart the "
          "integration, samples", 0, 10000),
    Param("bridge", "interpolate", "how missing samples are synthesised",
          choices=("interpolate", "hold")),
    Param("max_identical_samples", 5,
          "this many consecutive samples with bit-identical readings on all six channels are "
          "a frozen sensor: rejected (counted) until the readings change; 0 disables the "
          "check (noise-free simulated streams), 1 is not allowed, samples", 0, 100000),
    Param("use_temperature", False,
          "subscribe imu/temperature (sensor_msgs/Temperature, degC) for the temperature "
          "polynomials; false: T_ref"),
    Param("apply_filter_corrections", False,
          "apply the filter's bias/scale increments from ins/correction here; exactly one of "
          "this and strapdown.apply_sensor_corrections may be true (default: the strapdown)"),
    Param("frame_id", "base_link", "frame of the calibrated outputs"),
    Param("sample_model", "interval_mean",
          "what a raw sample is: interval_mean (the mean rate over the interval ending at its "
          "stamp: increment = rate dt) or instant (the rate at the stamp: increment by the "
          "trapezoid of neighbouring samples; rate dt would lag it by half a sample)",
          choices=("interval_mean", "instant")),
    Param("clock_jump.min_s", 0.1, "a stamp step that differs from the arrival step (node "
          "clock) by at least this while the samples arrive one period apart is a jump of the "
          "sensor clock, taken out of the stamps (0: never), s", 0.0, 10.0),
    Param("clock_jump.max_s", 2.5, "larger stamp jumps are a new time base (a restarted or "
          "looped source) and pass unchanged, s", 0.0, 3600.0),
    Param("orientation_heading.rate_hz", 5.0, "rate of imu/heading from the IMU's own "
          "orientation where its covariance says the yaw is valid (REP-145), Hz; 0: none",
          0.0, 1000.0),
    Param("orientation_heading.reference", "magnetic", "north of that orientation's yaw: "
          "magnetic (a 9-axis AHRS; the ekf applies the WMM declination) or true",
          choices=("magnetic", "true")),
    Param("time_offset_s", 0.0, "added to the sensor stamps to put them on GNSS time (the "
          "IMU clock's offset, e.g. -0.125 for the car drive's logger), s", -10.0, 10.0),
)


def preprocessor_from_params(p: dict) -> ImuPreprocessor:
    """The ImuPreprocessor of the node's parameters; ParameterError names the parameter at
    fault."""
    calibration = calibration_from_params(p)
    try:
        return ImuPreprocessor(
            calibration, p["rate_hz"], p["nav_rate_hz"], p["coning_method"],
            gyro_range=np.radians(p["gyro_range_dps"]), accel_range=p["accel_range_mps2"],
            max_bridge=p["max_bridge_samples"], bridge=p["bridge"],
            max_identical_samples=p["max_identical_samples"],
            instant=p["sample_model"] == "instant",
            clock_jump=((p["clock_jump.min_s"], p["clock_jump.max_s"])
                        if p["clock_jump.min_s"] > 0.0 else None),
            sensor_clock=((p["sensor_clock.jitter_s"], p["sensor_clock.time_constant_s"])
                          if p["sensor_clock.enabled"] else None),
            time_offset_ns=int(round(p["time_offset_s"] * NS)))
    except SettingError as err:
        name = {"clock_jump": "clock_jump.max_s",
                "sensor_clock": "sensor_clock.jitter_s"}.get(err.name, err.name)
        raise ParameterError(f"parameter '{name}': {err}") from None


def orientation_headings_from_params(p: dict, c_bs) -> tuple[OrientationHeadings | None,
                                                               float | None]:
    """The imu/heading source of the node's parameters for mounting c_bs (None: turned off),
    and the declination its headings need: NaN (magnetic north, the WMM's declination to be
    applied by the filter) or None (true north)."""
    rate = p["orientation_heading.rate_hz"]
    if rate <= 0.0:
        return None, None
    return OrientationHeadings(rate, c_bs), (
        float("nan") if p["orientation_heading.reference"] == "magnetic" else None)


def mounting_given(p: dict) -> bool:
    """Whether parameters (a profile's section or the node's) give the IMU's mounting: a
    non-zero ``mounting_rpy_deg`` or a ``calibration_file`` (which may hold it). Zero stands
    for "not known", which /tf_static may then tell (trial/installation.py, the node)."""
    return any(p.get("mounting_rpy_deg", ())) or bool(p.get("calibration_file"))


def calibration_from_params(p: dict) -> ImuCalibration:
    """ImuCalibration from the file or the inline parameters; ParameterError names the cause."""
    source = "calibration.*"
    if p["calibration_file"]:
        defaults = {s.name: s.default for s in PARAMS if s.name.startswith("calibration.")}
        if any(p[k] != v for k, v in defaults.items()):
            raise ParameterError("parameter 'calibration_file': give the calibration either as "
                                 "a file or as calibration.* parameters, not both")
        try:
            d = read_calibration_file(p["calibration_file"])
        except ValueError as err:
            raise ParameterError(f"parameter 'calibration_file': {err}") from None
        source = f"calibration_file {p['calibration_file']}"
    else:
        d = _inline_calibration(p)
    mounting = np.radians(p["mounting_rpy_deg"])
    if "mounting_rpy" in d:
        if np.any(mounting != 0.0):
            raise ParameterError(f"parameter 'mounting_rpy_deg': {source} sets mounting_rpy "
                                 "already; give it in one place")
    else:
        d = {**d, "mounting_rpy": mounting.tolist()}
    try:
        return ImuCalibration.from_dict(d)
    except (ValueError, TypeError) as err:
        raise ParameterError(f"{source}: {err}") from None

def _inline_calibration(p: dict) -> dict:
    """The calibration.* parameters as an ImuCalibration dict (flat ROS arrays reshaped)."""
    d = {}
    for name in ("gyro", "accel"):
        d[name] = {}
        for k in _TRIAD_PARAMS:
            values = p[f"calibration.{name}.{k}"]
            if len(values) % 3:
                raise ParameterError(f"parameter 'calibration.{name}.{k}': {len(values)} "
                                     "values, expected a multiple of 3")
            d[name][k] = np.reshape(values, (-1, 3)).tolist()
    d["gyro_g_sensitivity"] = np.reshape(p["calibration.gyro_g_sensitivity"],
                                         (3, 3)).tolist()
    d["temperature_ref"] = p["calibration.temperature_ref"]
    return d
