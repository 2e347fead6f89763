"""``imu_preprocessor`` node: raw IMU and magnetometer samples to calibrated, checked streams.

Per raw ``imu/data_raw`` sample (sensor frame, any mounting, any rate that is an integer
multiple of the navigation rate, e.g. 1200 Hz for seed 004's ISON-1):

0. :class:`~ins_gnss_ros.imu.sample_checks.ClockJumps` takes jumps of the sensor clock out of the
   stamps: a stamp step unlike the step of the arrival times (node clock: ``/clock`` in a
   replay) while the samples arrive at their regular period (``clock_jump.*``);
1. :class:`~ins_gnss_ros.imu.sample_checks.SampleChecker` rejects NaN/inf, saturated readings,
   duplicated or backwards stamps and a frozen sensor (``max_identical_samples`` bit-identical
   readings in a row) (counted on /diagnostics, never passed on), bridges gaps of up to
   ``max_bridge_samples`` and reports longer ones, after which integration restarts (the
   ``strapdown`` and ``ekf`` then see the gap in ``imu/delta`` and bridge or restart);
2. :class:`~ins_gnss_ros.imu.calibration.ImuCalibration` removes bias, scale factor,
   non-orthogonality and g-sensitivity (with the temperature from ``imu/temperature`` if
   enabled) and rotates into ``base_link`` (seed 004 §2.3); optionally the filter's residual
   estimates from ``ins/correction`` too;
3. the calibrated sample goes out on ``imu/data``, and every ``rate_hz / nav_rate_hz`` samples the
   :class:`~ins_gnss_ros.nav.coning.Integrator` emits coning/sculling-compensated increments on
   ``imu/delta``, stamped at the end of the interval.

A sensor_msgs/Imu sample is the mean rate over the interval ending at its stamp (the convention
of :mod:`ins_gnss_ros.sim.imu_sim`), so its increment is rate x (stamp - previous stamp); the
stamp differences are taken in integer nanoseconds because a float POSIX time resolves only
~0.2 µs. Bridged samples feed the integrator (so ``imu/delta`` keeps its regular step) but are
not published on ``imu/data``: they are not measurements.

Magnetometer samples (``imu/mag_raw``) are rotated into ``base_link`` with the same mounting and
published on ``imu/mag``; hard/soft iron belongs to the vehicle and is removed by ``mag_compass``.
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
from ins_gnss_msgs.msg import ImuDelta, InsCorrection
from sensor_msgs.msg import Imu, MagneticField, Temperature

from ..imu.calibration import ImuCalibration, ResidualErrors
from ..imu.sample_checks import ClockJumps, SampleChecker
from ..io import NS, new, set_stamp_ns, stamp_to_ns
from ..nav.coning import METHODS, Integrator
from ..params_io import ParamsFileError, load_yaml_file
from .base import DRIVER_QOS, SENSOR_QOS, STATE_QOS, NavNode, Param, ParameterError, run
from .convert import set_vector3, vec


def rotate_covariance(cov, c) -> list:
    """Row-major 3x3 covariance of a vector rotated by ``c``; unknown (-1 first) stays unknown."""
    if cov[0] == -1.0:
        return list(cov)
    return (c @ np.reshape(np.asarray(cov, float), (3, 3)) @ c.T).ravel().tolist()


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
        Param("rate_hz", 200.0, "nominal sensor sample rate, Hz (an integer multiple of "
              "nav_rate_hz)", 1.0, 10000.0),
        Param("nav_rate_hz", 100.0, "rate of imu/delta, Hz", 1.0, 10000.0),
        Param("coning_method", "two_sample",
              "coning/sculling algorithm (two_sample needs an even rate_hz / nav_rate_hz)",
              choices=METHODS),
        Param("gyro_range_dps", 2000.0,
              "gyro measurement range; |reading| >= range is saturated, deg/s", 1.0, 100000.0),
        Param("accel_range_mps2", 160.0,
              "accelerometer range; |reading| >= range is saturated, m/s^2", 1.0, 100000.0),
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
        n_sub = p["rate_hz"] / p["nav_rate_hz"]
        if abs(n_sub - round(n_sub)) > 1e-9 * n_sub:
            raise ParameterError(f"parameter 'rate_hz' = {p['rate_hz']} is not an integer multiple"
                                 f" of nav_rate_hz = {p['nav_rate_hz']}")
        try:
            self.integrator = Integrator(int(round(n_sub)), p["coning_method"])
        except ValueError as err:
            raise ParameterError(f"parameter 'coning_method': {err} (rate_hz / nav_rate_hz = "
                                 f"{int(round(n_sub))}; use one_sample)") from None
        try:
            self.checker = SampleChecker(p["rate_hz"], np.radians(p["gyro_range_dps"]),
                                         p["accel_range_mps2"], p["max_bridge_samples"],
                                         p["bridge"], max_identical=p["max_identical_samples"])
        except ValueError as err:
            raise ParameterError(f"parameter 'max_identical_samples': {err}") from None
        self.clock = None
        if p["clock_jump.min_s"] > 0.0:
            try:
                self.clock = ClockJumps(p["rate_hz"], p["clock_jump.min_s"], p["clock_jump.max_s"])
            except ValueError as err:
                raise ParameterError(f"parameter 'clock_jump.max_s': {err}") from None
        # None until the filter sends a correction: removing zero errors changes no bit but
        # costs work on every sample.
        self.residual: ResidualErrors | None = None
        self.offset_ns = int(round(p["time_offset_s"] * NS))
        self.temperature: float | None = None
        self.synthesised = 0
        self._origin_ns: int | None = None   # stamps go to the checker relative to the first one
        self._last_ns: int | None = None     # end of the last integrated sample
        self._last_rates = None              # its rates (trapezoid of instant samples)
        self._last_mag_ns: int | None = None
        # Read per sample: attributes, not parameter-dict lookups and string comparisons.
        self._period = 1.0 / p["rate_hz"]
        self._instant = p["sample_model"] == "instant"
        self._frame_id = p["frame_id"]
        self._rotated_cache: dict[bytes, np.ndarray] = {}
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
            d = self._read_calibration_file(Path(p["calibration_file"]))
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

    @staticmethod
    def _read_calibration_file(path: Path) -> dict:
        try:
            d = load_yaml_file(path)
        except ParamsFileError as err:
            raise ParameterError(f"parameter 'calibration_file': {err}") from None
        if isinstance(d, dict) and "imu_calibration" in d:
            d = d["imu_calibration"]
        if not isinstance(d, dict):
            raise ParameterError(f"parameter 'calibration_file': {path} holds no calibration dict")
        return d

    # -- IMU samples ---------------------------------------------------------------------------
    def on_imu(self, msg: Imu) -> None:
        t_ns = stamp_to_ns(msg.header.stamp) + self.offset_ns
        if self.clock is not None:
            jumps = self.clock.jumps
            t_ns = self.clock.correct(t_ns, self.now_ns())
            if self.clock.jumps != jumps:
                self.diag.count("imu clock jump: stamps corrected by the arrival clock")
                self.diag.set_value("imu clock correction, s", -self.clock.offset_ns / NS)
        if self._origin_ns is None:
            self._origin_ns = t_ns
        w, f = msg.angular_velocity, msg.linear_acceleration
        gyro, accel = (w.x, w.y, w.z), (f.x, f.y, f.z)
        result = self.checker.check((t_ns - self._origin_ns) / NS, gyro, accel)
        if not result.ok:
            self.diag.count(f"imu sample rejected: {result.reason}")
            return
        if result.reason == "gap":
            self.diag.count("imu gap longer than max_bridge_samples: integration restarted")
            self.integrator.reset()
            self._last_ns = self._last_rates = None
        elif result.reason == "gap_bridged":
            self.diag.count("imu gap bridged")
            self.synthesised += len(result.fill_stamps)
            self.diag.set_value("imu samples synthesised", self.synthesised)
        correct = self.cal.correct_sample
        for t, g, a in zip(result.fill_stamps.tolist(), result.fill_gyro.tolist(),
                           result.fill_accel.tolist()):
            self._integrate(self._origin_ns + int(round(t * NS)),
                            *correct(g, a, self.temperature, self.residual))
        w_b, f_b = correct(gyro, accel, self.temperature, self.residual)
        self._integrate(t_ns, w_b, f_b)
        self._publish_data(msg, t_ns, w_b, f_b)

    def _integrate(self, t_ns: int, w_b: tuple, f_b: tuple) -> None:
        dt = self._period if self._last_ns is None else (t_ns - self._last_ns) / NS
        self._last_ns = t_ns
        if self._instant and self._last_rates is not None:
            w_mean = [0.5 * (a + b) for a, b in zip(self._last_rates[0], w_b)]
            f_mean = [0.5 * (a + b) for a, b in zip(self._last_rates[1], f_b)]
        else:
            w_mean, f_mean = w_b, f_b
        self._last_rates = (w_b, f_b)
        out = self.integrator.add_rates(w_mean, f_mean, dt)
        if out is None:
            return
        phi, dv, dt_nav = out
        delta = new(ImuDelta)
        delta.dt = dt_nav
        set_vector3(delta.delta_angle, phi)
        set_vector3(delta.delta_velocity, dv)
        set_stamp_ns(delta.header.stamp, t_ns)
        delta.header.frame_id = self._frame_id
        self.pub_delta.publish(delta)

    def _publish_data(self, raw: Imu, t_ns: int, w_b: tuple, f_b: tuple) -> None:
        out = new(Imu)
        w, f = out.angular_velocity, out.linear_acceleration
        (w.x, w.y, w.z), (f.x, f.y, f.z) = w_b, f_b
        set_stamp_ns(out.header.stamp, t_ns)
        out.header.frame_id = self._frame_id
        out.orientation_covariance[0] = -1.0  # REP-145: no orientation estimate
        # Written into the message's own arrays: assigning a list runs the generated setter's
        # per-element type and range checks.
        out.angular_velocity_covariance[:] = self._rotated(raw.angular_velocity_covariance)
        out.linear_acceleration_covariance[:] = self._rotated(raw.linear_acceleration_covariance)
        self.pub_data.publish(out)

    def _rotated(self, cov) -> np.ndarray:
        """:func:`rotate_covariance` by the mounting, memoised: a driver repeats the same few
        covariances on every sample, and the matrix products cost more than the lookup. The
        array is the memo's own: callers copy it into their message."""
        key = np.asarray(cov, float).tobytes()
        out = self._rotated_cache.get(key)
        if out is None:
            if len(self._rotated_cache) > 64:  # a driver with varying covariances
                self._rotated_cache.clear()
            out = self._rotated_cache[key] = np.array(rotate_covariance(cov, self.cal.c_bs))
        return out

    def on_temperature(self, msg: Temperature) -> None:
        if not np.isfinite(msg.temperature):
            self.diag.count("non-finite temperature ignored")
            return
        self.temperature = float(msg.temperature)

    def on_correction(self, msg: InsCorrection) -> None:
        incr = [vec(msg.gyro_bias), vec(msg.gyro_scale_factor), vec(msg.accel_bias),
                vec(msg.accel_scale_factor)]
        if not all(np.all(np.isfinite(x)) for x in incr):
            self.diag.count("non-finite sensor correction rejected")
            return
        r = self.residual or ResidualErrors()
        # Increments to the applied estimates, from this sample on (the past is not redone here).
        self.residual = ResidualErrors(r.gyro_bias + incr[0], r.gyro_scale + incr[1],
                                       r.accel_bias + incr[2], r.accel_scale + incr[3])

    # -- magnetometer --------------------------------------------------------------------------
    def on_mag(self, msg: MagneticField) -> None:
        m = vec(msg.magnetic_field)
        t_ns = stamp_to_ns(msg.header.stamp) + self.offset_ns
        if not np.all(np.isfinite(m)):
            self.diag.count("magnetometer sample rejected: non_finite")
            return
        if self._last_mag_ns is not None and t_ns <= self._last_mag_ns:
            self.diag.count("magnetometer sample rejected: stamp not after the previous one")
            return
        self._last_mag_ns = t_ns
        c = self.cal.c_bs
        out = new(MagneticField)
        set_vector3(out.magnetic_field, c @ m)
        set_stamp_ns(out.header.stamp, t_ns)
        out.header.frame_id = self._frame_id
        out.magnetic_field_covariance[:] = self._rotated(msg.magnetic_field_covariance)
        self.pub_mag.publish(out)


def main(args=None) -> int:
    return run(ImuPreprocessorNode, args)


if __name__ == "__main__":
    sys.exit(main())
