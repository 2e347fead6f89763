"""``imu_preprocessor`` node: raw IMU and magnetometer samples to calibrated, checked streams.

Every raw ``imu/data_raw`` sample goes through
:class:`~ins_gnss_ros.imu.preprocessor.ImuPreprocessor` (sample rate, sensor clock, time offset, clock jumps, sample checks and bridging, calibration and mounting, the filter's
sensor-error feedback, coning/sculling increments; see there). The node maps the parameters onto
it, counts what it reports on /diagnostics, and publishes the calibrated sample on ``imu/data``
and every completed increment on ``imu/delta``, stamped at the end of its interval.

Magnetometer samples (``imu/mag_raw``) are rotated into ``base_link`` with the same mounting and
published on ``imu/mag``; hard/soft iron belongs to the vehicle and is removed by ``mag_compass``.
"""

from __future__ import annotations

import sys

import numpy as np
from ins_gnss_msgs.msg import ImuDelta, InsCorrection
from sensor_msgs.msg import Imu, MagneticField, Temperature

from ..imu.calibration import ImuCalibration, read_calibration_file
from ..imu.preprocessor import ImuPreprocessor, SettingError
from ..io import NS, new, set_stamp_ns, stamp_to_ns
from ..nav.coning import METHODS
from ..nav.increments import MAX_RATE, MAX_SPECIFIC_FORCE, SensorErrors
from .base import DRIVER_QOS, SENSOR_QOS, STATE_QOS, NavNode, Param, ParameterError, run
from .convert import set_vector3, vec


#: ImuPreprocessor events -> diagnostics.
_EVENTS = {"clock_jump": "imu clock jump: stamps corrected by the arrival clock",
           "sensor_clock_restart": "imu sensor clock fit restarted (driver clock step, long gap)",
           "coning_fallback": "coning_method two_sample impossible at the measured rate: "
                              "one_sample used"}
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


class ImuPreprocessorNode(NavNode):
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
        Param("time_offset_s", 0.0, "added to the sensor stamps to put them on GNSS time (the "
              "IMU clock's offset, e.g. -0.125 for the car drive's logger), s", -10.0, 10.0),
    )

    def __init__(self, **kwargs):
        super().__init__("imu_preprocessor", **kwargs)
        p = self.p
        self.cal = self._calibration()
        try:
            self.preprocessor = ImuPreprocessor(
                self.cal, p["rate_hz"], p["nav_rate_hz"], p["coning_method"],
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
        if self.preprocessor.rate_hz is not None:
            self._report_rates()
        # Read per sample: an attribute, not a parameter-dict lookup.
        self._frame_id = p["frame_id"]
        self.pub_data = self.publisher(Imu, "imu/data", SENSOR_QOS)
        self.pub_delta = self.publisher(ImuDelta, "imu/delta", SENSOR_QOS)
        self.pub_mag = self.publisher(MagneticField, "imu/mag", SENSOR_QOS)
        self.subscribe(Imu, "imu/data_raw", self.on_imu, DRIVER_QOS)
        self.subscribe(MagneticField, "imu/mag_raw", self.on_mag, DRIVER_QOS)
        if p["use_temperature"]:
            self.subscribe(Temperature, "imu/temperature", self.on_temperature, DRIVER_QOS)
        if p["apply_filter_corrections"]:
            self.subscribe(InsCorrection, "ins/correction", self.on_correction, STATE_QOS)

    # -- parameters ----------------------------------------------------------------------------
    def _calibration(self) -> ImuCalibration:
        """ImuCalibration from the file or the inline parameters; ParameterError names the cause."""
        p = self.p
        source = "calibration.*"
        if p["calibration_file"]:
            defaults = {s.name: s.default for s in self.PARAMS if s.name.startswith("calibration.")}
            if any(p[k] != v for k, v in defaults.items()):
                raise ParameterError("parameter 'calibration_file': give the calibration either as "
                                     "a file or as calibration.* parameters, not both")
            try:
                d = read_calibration_file(p["calibration_file"])
            except ValueError as err:
                raise ParameterError(f"parameter 'calibration_file': {err}") from None
            source = f"calibration_file {p['calibration_file']}"
        else:
            d = self._inline_calibration()
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

    def _inline_calibration(self) -> dict:
        """The calibration.* parameters as an ImuCalibration dict (flat ROS arrays reshaped)."""
        d = {}
        for name in ("gyro", "accel"):
            d[name] = {}
            for k in _TRIAD_PARAMS:
                values = self.p[f"calibration.{name}.{k}"]
                if len(values) % 3:
                    raise ParameterError(f"parameter 'calibration.{name}.{k}': {len(values)} "
                                         "values, expected a multiple of 3")
                d[name][k] = np.reshape(values, (-1, 3)).tolist()
        d["gyro_g_sensitivity"] = np.reshape(self.p["calibration.gyro_g_sensitivity"],
                                             (3, 3)).tolist()
        d["temperature_ref"] = self.p["calibration.temperature_ref"]
        return d

    # -- IMU samples ---------------------------------------------------------------------------
    def on_imu(self, msg: Imu) -> None:
        w, f = msg.angular_velocity, msg.linear_acceleration
        for out in self.preprocessor.add(stamp_to_ns(msg.header.stamp), self.now_ns(),
                                         (w.x, w.y, w.z), (f.x, f.y, f.z), msg):
            if out.events:
                self._report(out.events)
            if out.rates is None:
                self.diag.count(f"imu sample rejected: {out.reason}")
                continue
            if out.reason == "gap":
                self.diag.count("imu gap longer than max_bridge_samples: integration restarted")
            elif out.reason == "gap_bridged":
                self.diag.count("imu gap bridged")
                self.diag.set_value("imu samples synthesised", self.preprocessor.synthesised)
            for inc in out.increments:
                delta = new(ImuDelta)
                delta.dt = inc.dt
                set_vector3(delta.delta_angle, inc.dtheta)
                set_vector3(delta.delta_velocity, inc.dv)
                set_stamp_ns(delta.header.stamp, inc.t_ns)
                delta.header.frame_id = self._frame_id
                self.pub_delta.publish(delta)
            self._publish_data(out.tag, out.t_ns, *out.rates)

    def _report(self, events: tuple) -> None:
        for event in events:
            if event == "rate_measured":
                self._report_rates()
                continue
            self.diag.count(_EVENTS[event])
            if event == "clock_jump":
                self.diag.set_value("imu clock correction, s",
                                    -self.preprocessor.clock.offset_ns / NS)

    def _report_rates(self) -> None:
        pre = self.preprocessor
        rates = (f"imu {pre.rate_hz:.4f} Hz, imu/delta {pre.nav_rate_hz:.4f} Hz "
                 f"({pre.coning_method})")
        self.diag.set_value("rates", rates)
        self.get_logger().info(rates)

    def _publish_data(self, raw: Imu, t_ns: int, w_b: tuple, f_b: tuple) -> None:
        out = new(Imu)
        w, f = out.angular_velocity, out.linear_acceleration
        (w.x, w.y, w.z), (f.x, f.y, f.z) = w_b, f_b
        set_stamp_ns(out.header.stamp, t_ns)
        out.header.frame_id = self._frame_id
        out.orientation_covariance[0] = -1.0  # REP-145: no orientation estimate
        # Copied into the message's own arrays: assigning a list runs the generated setter's
        # per-element type and range checks.
        out.angular_velocity_covariance[:] = self.preprocessor.covariance_in_base(raw.angular_velocity_covariance)
        out.linear_acceleration_covariance[:] = self.preprocessor.covariance_in_base(raw.linear_acceleration_covariance)
        self.pub_data.publish(out)

    def on_temperature(self, msg: Temperature) -> None:
        if not np.isfinite(msg.temperature):
            self.diag.count("non-finite temperature ignored")
            return
        self.preprocessor.temperature = float(msg.temperature)

    def on_correction(self, msg: InsCorrection) -> None:
        increment = SensorErrors(vec(msg.gyro_bias), vec(msg.accel_bias),
                                 vec(msg.gyro_scale_factor), vec(msg.accel_scale_factor))
        if not self.preprocessor.add_sensor_errors(increment):
            self.diag.count("non-finite sensor correction rejected")

    # -- magnetometer --------------------------------------------------------------------------
    def on_mag(self, msg: MagneticField) -> None:
        out = self.preprocessor.add_magnetic(stamp_to_ns(msg.header.stamp),
                                             vec(msg.magnetic_field))
        if isinstance(out, str):
            self.diag.count(f"magnetometer sample rejected: {out}")
            return
        mag = new(MagneticField)
        set_vector3(mag.magnetic_field, out[1])
        set_stamp_ns(mag.header.stamp, out[0])
        mag.header.frame_id = self._frame_id
        mag.magnetic_field_covariance[:] = self.preprocessor.covariance_in_base(msg.magnetic_field_covariance)
        self.pub_mag.publish(mag)


def main(args=None) -> int:
    return run(ImuPreprocessorNode, args)


if __name__ == "__main__":
    sys.exit(main())
