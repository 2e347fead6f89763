"""The IMU preprocessor's per-sample pipeline: raw driver samples to calibrated rates and
navigation-rate increments (and magnetometer samples into base_link), without ROS.

Per raw sample (sensor frame, any mounting, stamps in integer ns on the driver's clock):

0. the time offset (IMU clock to GNSS time) is added, and
   :class:`~ins_gnss_ros.imu.sample_checks.ClockJumps` takes jumps of the sensor clock out of
   the stamps: a stamp step unlike the step of the arrival times while the samples arrive at
   their regular period;
1. :class:`~ins_gnss_ros.imu.sample_checks.SampleChecker` rejects NaN/inf, saturated readings,
   duplicated or backwards stamps and a frozen sensor, bridges gaps of up to ``max_bridge``
   samples and reports longer ones, after which the integration restarts (the consumers of the
   increments then see the gap and bridge or restart);
2. :meth:`~ins_gnss_ros.imu.calibration.ImuCalibration.correct_sample` removes bias, scale
   factor, non-orthogonality and g-sensitivity and rotates into base_link (seed 004 §2.3), and
   the filter's running sensor-error estimates (:class:`~ins_gnss_ros.nav.increments.SensorErrors`,
   when this is where they are fed back) are removed too;
3. every ``n_sub`` samples the :class:`~ins_gnss_ros.nav.coning.Integrator` completes a
   coning/sculling-compensated increment, stamped at the end of its interval.

A sample is the mean rate over the interval ending at its stamp (``interval_mean``, the
convention of :mod:`ins_gnss_ros.sim.imu_sim`), so its increment is rate x (stamp - previous
stamp), or the rate at its stamp (``instant``), integrated by the trapezoid of neighbouring
samples. Stamp differences are taken in integer nanoseconds because a float POSIX time resolves
only ~0.2 µs. Bridged samples feed the integrator (the increments keep their regular step) but
are not measurements: they are not returned as calibrated rates.
"""
from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np

from ..nav.coning import METHODS, Integrator
from ..nav.increments import SensorErrors
from .calibration import ImuCalibration
from .sample_checks import ClockJumps, SampleChecker

__all__ = ["ImuPreprocessor", "Increment", "Processed", "SettingError", "navigation_interval"]

NS = 1_000_000_000


class SettingError(ValueError):
    """A setting of :class:`ImuPreprocessor` that cannot work; ``name`` is its keyword."""

    def __init__(self, name: str, message: str):
        super().__init__(message)
        self.name = name


class Increment(NamedTuple):
    """One navigation-rate increment, body frame (base_link, FLU).

    Attributes
    ----------
    t_ns : int
        End of its interval, ns (the stamp of its last sample).
    dtheta : ndarray (3,)
        Coning-compensated rotation vector over the interval, rad.
    dv : ndarray (3,)
        Sculling- and rotation-compensated specific-force velocity increment, m/s.
    dt : float
        Length of the interval, s.
    """

    t_ns: int
    dtheta: object
    dv: object
    dt: float


class Processed(NamedTuple):
    """What one raw sample gave.

    Attributes
    ----------
    t_ns : int
        Its stamp after the time offset and the clock-jump correction, ns.
    reason : str
        The :data:`~ins_gnss_ros.imu.sample_checks.REASONS` verdict: "ok", "gap_bridged" and
        "gap" (integration restarted) are usable samples, any other is a rejection.
    rates : tuple of (omega_b, f_b) or None
        Calibrated angular rate (rad/s) and specific force (m/s^2) in base_link as float
        3-tuples; None when the sample was rejected.
    increments : sequence of Increment
        Increments completed by this sample and the samples bridging the gap before it.
    clock_jump : bool
        A jump of the sensor clock was found at this sample and taken out of the stamps.
    """

    t_ns: int
    reason: str
    rates: tuple | None
    increments: tuple | list
    clock_jump: bool


def navigation_interval(rate_hz: float, nav_rate_hz: float, coning_method: str) -> int:
    """Samples per navigation interval, checked against the coning method.

    Parameters
    ----------
    rate_hz, nav_rate_hz : float
        Sensor sample rate and increment rate, Hz; rate_hz must be an integer multiple.
    coning_method : {"one_sample", "two_sample"}
        "two_sample" needs an even number of samples per interval.

    Raises
    ------
    SettingError
        Naming the setting that cannot work.
    """
    n_sub = rate_hz / nav_rate_hz
    if abs(n_sub - round(n_sub)) > 1e-9 * n_sub:
        raise SettingError("rate_hz", f"{rate_hz} is not an integer multiple of nav_rate_hz = "
                                      f"{nav_rate_hz}")
    n_sub = int(round(n_sub))
    if coning_method not in METHODS:
        raise SettingError("coning_method", f"{coning_method!r}, expected one of {METHODS}")
    if coning_method == "two_sample" and n_sub % 2:
        raise SettingError("coning_method", f"two_sample needs an even n_sub (rate_hz / "
                                            f"nav_rate_hz = {n_sub}; use one_sample)")
    return n_sub


class ImuPreprocessor:
    """Raw IMU samples in, calibrated rates and navigation-rate increments out (module doc).

    Parameters
    ----------
    calibration : ImuCalibration
        Sensor calibration and mounting (sensor frame to base_link).
    rate_hz, nav_rate_hz : float
        Nominal sample rate and increment rate, Hz (see :func:`navigation_interval`).
    coning_method : {"one_sample", "two_sample"}
    gyro_range, accel_range : float
        Measurement ranges, rad/s and m/s^2: a reading at or beyond is saturated.
    max_bridge : int
        Longest run of missing or rejected samples bridged, samples.
    bridge : {"interpolate", "hold"}
        How the bridged samples are made.
    max_identical_samples : int
        Bit-identical readings in a row that make a frozen sensor (0: no check).
    instant : bool
        Samples are rates at their stamps (trapezoid rule), not interval means.
    clock_jump : (float, float) or None
        (min, max) stamp jump taken out by the arrival clock, s; None: no correction.
    time_offset_ns : int
        Added to every stamp (IMU clock to GNSS time), ns.

    Attributes
    ----------
    temperature : float or None
        Sensor temperature for the calibration polynomials, degC (None: T_ref).
    sensor_errors : SensorErrors or None
        The filter's running sensor-error estimates removed from every sample (None: none yet).
    synthesised : int
        Samples made so far to bridge gaps.
    """

    def __init__(self, calibration: ImuCalibration, rate_hz: float, nav_rate_hz: float,
                 coning_method: str = "two_sample", *, gyro_range: float, accel_range: float,
                 max_bridge: int = 5, bridge: str = "interpolate", max_identical_samples: int = 5,
                 instant: bool = False, clock_jump: tuple[float, float] | None = (0.1, 2.5),
                 time_offset_ns: int = 0):
        self.calibration = calibration
        self.integrator = Integrator(navigation_interval(rate_hz, nav_rate_hz, coning_method),
                                     coning_method)
        try:
            self.checker = SampleChecker(rate_hz, gyro_range, accel_range, max_bridge, bridge,
                                         max_identical=max_identical_samples)
        except ValueError as err:
            raise SettingError("max_identical_samples", str(err)) from None
        self.clock = None
        if clock_jump is not None:
            try:
                self.clock = ClockJumps(rate_hz, *clock_jump)
            except ValueError as err:
                raise SettingError("clock_jump", str(err)) from None
        self.offset_ns = int(time_offset_ns)
        self.temperature: float | None = None
        # None until the filter sends a correction: removing zero errors changes no bit but
        # costs work on every sample.
        self.sensor_errors: SensorErrors | None = None
        self.synthesised = 0
        self._period = 1.0 / rate_hz
        self._instant = bool(instant)
        self._origin_ns: int | None = None   # stamps go to the checker relative to the first one
        self._last_ns: int | None = None     # end of the last integrated sample
        self._last_rates = None              # its rates (trapezoid of instant samples)
        self._last_mag_ns: int | None = None

    def add_sensor_errors(self, increment: SensorErrors) -> bool:
        """Add the filter's increment to the sensor-error estimates, from the next sample on (the
        past is not redone); False (and nothing changed) if it is not finite."""
        if not all(math.isfinite(x) for v in (increment.gyro_bias, increment.accel_bias,
                                              increment.gyro_scale, increment.accel_scale)
                   for x in v.tolist()):
            return False
        self.sensor_errors = (self.sensor_errors or SensorErrors()) + increment
        return True

    def add(self, stamp_ns: int, arrival_ns: int, gyro, accel) -> Processed:
        """Process one raw sample.

        Parameters
        ----------
        stamp_ns : int
            Its stamp on the driver's clock, ns.
        arrival_ns : int
            When it arrived (the node clock), ns; paces the clock-jump check.
        gyro, accel : sequence of 3 float
            Raw sensor-frame angular rate (rad/s) and specific force (m/s^2).
        """
        t_ns = stamp_ns + self.offset_ns
        jumped = False
        if self.clock is not None:
            jumps = self.clock.jumps
            t_ns = self.clock.correct(t_ns, arrival_ns)
            jumped = self.clock.jumps != jumps
        if self._origin_ns is None:
            self._origin_ns = t_ns
        result = self.checker.check((t_ns - self._origin_ns) / NS, gyro, accel)
        if not result.ok:
            return Processed(t_ns, result.reason, None, (), jumped)
        if result.reason == "gap":
            self.integrator.reset()
            self._last_ns = self._last_rates = None
        elif result.reason == "gap_bridged":
            self.synthesised += len(result.fill_stamps)
        increments = []
        correct = self.calibration.correct_sample
        for t, g, a in zip(result.fill_stamps.tolist(), result.fill_gyro.tolist(),
                           result.fill_accel.tolist()):
            self._integrate(self._origin_ns + int(round(t * NS)),
                            *correct(g, a, self.temperature, self.sensor_errors), increments)
        w_b, f_b = self.calibration.correct_sample(gyro, accel, self.temperature,
                                                   self.sensor_errors)
        self._integrate(t_ns, w_b, f_b, increments)
        return Processed(t_ns, result.reason, (w_b, f_b), increments, jumped)

    def _integrate(self, t_ns: int, w_b: tuple, f_b: tuple, out: list) -> None:
        dt = self._period if self._last_ns is None else (t_ns - self._last_ns) / NS
        self._last_ns = t_ns
        if self._instant and self._last_rates is not None:
            w_mean = [0.5 * (a + b) for a, b in zip(self._last_rates[0], w_b)]
            f_mean = [0.5 * (a + b) for a, b in zip(self._last_rates[1], f_b)]
        else:
            w_mean, f_mean = w_b, f_b
        self._last_rates = (w_b, f_b)
        done = self.integrator.add_rates(w_mean, f_mean, dt)
        if done is not None:
            out.append(Increment(t_ns, *done))

    def add_magnetic(self, stamp_ns: int, field) -> tuple[int, np.ndarray] | str:
        """One magnetometer sample, rotated into base_link with the IMU's mounting (hard and soft
        iron belong to the vehicle: :mod:`ins_gnss_ros.magnetic`).

        Parameters
        ----------
        stamp_ns : int
            Its stamp on the driver's clock (the IMU's), ns.
        field : array_like (3,)
            Sensor-frame magnetic field, any unit (T for sensor_msgs/MagneticField).

        Returns
        -------
        (t_ns, field_b) or str
            Its stamp with the time offset (ns) and the field in base_link, or why it was
            rejected ("non_finite", "stamp not after the previous one").
        """
        t_ns = stamp_ns + self.offset_ns
        m = np.asarray(field, float)
        if not np.all(np.isfinite(m)):
            return "non_finite"
        if self._last_mag_ns is not None and t_ns <= self._last_mag_ns:
            return "stamp not after the previous one"
        self._last_mag_ns = t_ns
        return t_ns, self.calibration.c_bs @ m
