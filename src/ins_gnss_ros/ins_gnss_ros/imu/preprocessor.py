"""The IMU preprocessor's per-sample pipeline: raw driver samples to calibrated rates and
navigation-rate increments (and magnetometer samples into base_link), without ROS.

Per raw sample (sensor frame, any mounting, stamps in integer ns on the driver's clock):

0. the time offset (IMU clock to GNSS time) is added,
   :class:`~ins_gnss_ros.imu.sample_checks.ClockJumps` takes jumps of the sensor clock out of
   the stamps (a stamp step unlike the step of the arrival times while the samples arrive at
   their regular period), and :class:`~ins_gnss_ros.imu.sensor_clock.SensorClock` gives each
   sample its sampling instant on the sensor's own clock in place of the driver's jittered
   stamp; the sample rate is given or measured from the first stamps, with their scatter
   (:func:`~ins_gnss_ros.imu.sensor_clock.fit_stamps`), and the navigation interval is the
   whole number of samples nearest to the wanted one (:func:`navigation_interval`);
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
import struct
from typing import NamedTuple

import numpy as np

from ..nav.coning import METHODS, Integrator
from ..nav.increments import SensorErrors
from .calibration import ImuCalibration
from .gravity_check import SpecificForceCheck
from .sample_checks import ArrivalDrift, ClockJumps, SampleChecker
from .sensor_clock import SensorClock, fit_stamps

__all__ = ["EVENTS", "ImuPreprocessor", "Increment", "Processed", "SettingError",
           "navigation_interval"]

NS = 1_000_000_000
_NINE_DOUBLES = struct.Struct("<9d")  # a 3x3 covariance as a memo key


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
    angle_var, velocity_var : float
        Variance per axis of what the interval's bridged samples may miss (rad^2, (m/s)^2;
        :class:`~ins_gnss_ros.imu.sample_checks.BridgeMiss`, the misses of one gap taken as
        one): 0 when none was bridged.
    """

    t_ns: int
    dtheta: object
    dv: object
    dt: float
    angle_var: float = 0.0
    velocity_var: float = 0.0


class Processed(NamedTuple):
    """What one raw sample gave.

    Attributes
    ----------
    t_ns : int
        Its stamp after the time offset, the clock-jump correction and the sensor-clock fit, ns.
    reason : str
        The :data:`~ins_gnss_ros.imu.sample_checks.REASONS` verdict: "ok", "gap_bridged" and
        "gap" (integration restarted) are usable samples, any other is a rejection.
    rates : tuple of (omega_b, f_b) or None
        Calibrated angular rate (rad/s) and specific force (m/s^2) in base_link as float
        3-tuples; None when the sample was rejected.
    increments : sequence of Increment
        Increments completed by this sample and the samples bridging the gap before it.
    events : tuple of str
        Of :data:`EVENTS`, at this sample.
    tag : object
        What the caller passed with the sample (the node: its message).
    """

    t_ns: int
    reason: str
    rates: tuple | None
    increments: tuple | list
    events: tuple
    tag: object


#: :attr:`Processed.events`: a jump of the sensor clock taken out of the stamps by the arrival
#: clock; the sample rate measured (this is the first sample processed); the sensor-clock fit
#: restarted (a step of the driver's clock or an ambiguous gap); two_sample coning impossible
#: with the measured rate, one_sample used; a stretch of the specific force judged
#: (:attr:`ImuPreprocessor.gravity`); a block of the sensor clock's drift against the arrival
#: clock measured (:attr:`ImuPreprocessor.arrival_drift`).
EVENTS = ("clock_jump", "rate_measured", "sensor_clock_restart", "coning_fallback",
          "specific_force_judged", "arrival_drift_measured")

#: Samples and span of the stamps that measure the sample rate (rate_hz 0): a median over 40
#: intervals shrugs off a few lost samples, and half a second of span makes the rate good to
#: a fraction of a percent with millisecond jitter (the sensor-clock fit then refines it).
RATE_WINDOW_SAMPLES, RATE_WINDOW_S = 41, 0.5
#: Relative sigma of the measured rate the sensor-clock fit starts from (half its prior): stamps
#: scattered more widely (samples stamped per USB frame) are taken over a longer span first.
RATE_SIGMA = 1e-3
#: Samples held at most while the rate is measured.
PENDING_MAX = 100 * RATE_WINDOW_SAMPLES


def navigation_interval(rate_hz: float, nav_rate_hz: float, coning_method: str) -> tuple[int, str]:
    """Samples per navigation interval and the coning/sculling method for it.

    Parameters
    ----------
    rate_hz, nav_rate_hz : float
        Sensor sample rate and the wanted increment rate, Hz. The interval is the whole number
        of samples nearest to 1 / nav_rate_hz (at least one): the effective increment rate is
        rate_hz / n_sub.
    coning_method : {"auto", "one_sample", "two_sample"}
        "two_sample" needs an even number of samples per interval; "auto" takes it then and
        "one_sample" otherwise (with one sample per interval that is the previous-interval
        correction of Savage ch. 7, still exact for rates linear in time).

    Returns
    -------
    n_sub : int
    method : {"one_sample", "two_sample"}

    Raises
    ------
    SettingError
        Naming the setting that cannot work.
    """
    n_sub = max(1, int(round(rate_hz / nav_rate_hz)))
    if coning_method == "auto":
        return n_sub, "one_sample" if n_sub % 2 else "two_sample"
    if coning_method not in METHODS:
        raise SettingError("coning_method", f"{coning_method!r}, expected auto or one of "
                                            f"{METHODS}")
    if coning_method == "two_sample" and n_sub % 2:
        raise SettingError("coning_method", f"two_sample needs an even n_sub (rate_hz / "
                                            f"nav_rate_hz = {n_sub}; use one_sample or auto)")
    return n_sub, coning_method


class ImuPreprocessor:
    """Raw IMU samples in, calibrated rates and navigation-rate increments out (module doc).

    Parameters
    ----------
    calibration : ImuCalibration
        Sensor calibration and mounting (sensor frame to base_link).
    rate_hz : float
        Nominal sample rate, Hz; 0: measured from the first stamps (:data:`RATE_WINDOW_S`), whose
        samples are held until then and processed at once.
    nav_rate_hz : float
        Wanted increment rate, Hz (see :func:`navigation_interval`).
    coning_method : {"auto", "one_sample", "two_sample"}
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
    sensor_clock : (float, float) or None
        (jitter_s, time_constant_s) of the :class:`~ins_gnss_ros.imu.sensor_clock.SensorClock`
        that gives every sample its sampling instant (with the stamps' measured scatter where
        it is larger and the rate is measured); None: the stamps as they come.
    time_offset_ns : int
        Added to every stamp (IMU clock to GNSS time), ns.

    Attributes
    ----------
    rate_hz, nav_rate_hz : float or None
        Sample rate (given or measured) and effective increment rate, Hz; None until measured.
    stamp_scatter_s : float or None
        RMS scatter of the stamps that measured the rate about its line, s (None: rate given).
    coning_method : str or None
        The method in use.
    temperature : float or None
        Sensor temperature for the calibration polynomials, degC (None: T_ref).
    sensor_errors : SensorErrors or None
        The filter's running sensor-error estimates removed from every sample (None: none yet).
    synthesised : int
        Samples made so far to bridge gaps.
    gravity : SpecificForceCheck
        Whether the increments' specific force is in m/s^2 with gravity in it.
    arrival_drift : ArrivalDrift
        The sensor clock's rate against the arrival clock.
    """

    def __init__(self, calibration: ImuCalibration, rate_hz: float, nav_rate_hz: float,
                 coning_method: str = "auto", *, gyro_range: float, accel_range: float,
                 max_bridge: int = 5, bridge: str = "interpolate", max_identical_samples: int = 5,
                 instant: bool = False, clock_jump: tuple[float, float] | None = (0.1, 2.5),
                 sensor_clock: tuple[float, float] | None = None, time_offset_ns: int = 0):
        self.calibration = calibration
        self._settings = dict(nav_rate_hz=nav_rate_hz, coning_method=coning_method,
                              gyro_range=gyro_range, accel_range=accel_range,
                              max_bridge=max_bridge, bridge=bridge,
                              max_identical_samples=max_identical_samples,
                              clock_jump=clock_jump, sensor_clock=sensor_clock)
        self.rate_hz = self.nav_rate_hz = self.coning_method = None
        self.stamp_scatter_s: float | None = None   # of the stamps that measured the rate, s
        self._pending: list | None = []   # samples held while the rate is measured
        if rate_hz > 0:
            self._start(rate_hz, strict=True)
        elif coning_method not in METHODS + ("auto",):
            navigation_interval(1.0, 1.0, coning_method)   # raises: the method is unknown
        self.offset_ns = int(time_offset_ns)
        self.temperature: float | None = None
        # None until the filter sends a correction: removing zero errors changes no bit but
        # costs work on every sample.
        self.sensor_errors: SensorErrors | None = None
        self.synthesised = 0
        self.gravity = SpecificForceCheck()
        self.arrival_drift = ArrivalDrift()
        self._instant = bool(instant)
        self._origin_ns: int | None = None   # stamps go to the checker relative to the first one
        self._last_ns: int | None = None     # end of the last integrated sample
        self._last_rates = None              # its rates (trapezoid of instant samples)
        self._miss = [0.0, 0.0]   # the open increment's bridged-sample misses: rad, m/s
        self._last_mag_ns: int | None = None
        self._covariances: dict[bytes, tuple] = {}

    def _start(self, rate_hz: float, strict: bool) -> tuple:
        """Build the rate-dependent stages; returns the events of the start. ``strict``: a
        coning method that cannot work raises (given rate) instead of falling back."""
        s = self._settings
        events = ()
        try:
            n_sub, method = navigation_interval(rate_hz, s["nav_rate_hz"], s["coning_method"])
        except SettingError:
            if strict or s["coning_method"] != "two_sample":
                raise
            n_sub, method = navigation_interval(rate_hz, s["nav_rate_hz"], "one_sample")
            events = ("coning_fallback",)
        self.integrator = Integrator(n_sub, method)
        try:
            self.checker = SampleChecker(rate_hz, s["gyro_range"], s["accel_range"],
                                         s["max_bridge"], s["bridge"],
                                         max_identical=s["max_identical_samples"])
        except ValueError as err:
            raise SettingError("max_identical_samples", str(err)) from None
        self.clock = None
        if s["clock_jump"] is not None:
            try:
                self.clock = ClockJumps(rate_hz, *s["clock_jump"])
            except ValueError as err:
                raise SettingError("clock_jump", str(err)) from None
        self.sensor_clock = None
        if s["sensor_clock"] is not None:
            jitter_s, time_constant_s = s["sensor_clock"]
            # the stamps' measured scatter where it exceeds the configured jitter
            jitter_s = max(jitter_s, self.stamp_scatter_s or 0.0)
            try:
                self.sensor_clock = SensorClock(rate_hz, jitter_s, time_constant_s)
            except ValueError as err:
                raise SettingError("sensor_clock", str(err)) from None
        self.rate_hz, self.nav_rate_hz, self.coning_method = rate_hz, rate_hz / n_sub, method
        self._period = 1.0 / rate_hz
        self._pending = None
        return events

    def add_sensor_errors(self, increment: SensorErrors) -> bool:
        """Add the filter's increment to the sensor-error estimates, from the next sample on (the
        past is not redone); False (and nothing changed) if it is not finite."""
        if not all(math.isfinite(x) for v in (increment.gyro_bias, increment.accel_bias,
                                              increment.gyro_scale, increment.accel_scale)
                   for x in v.tolist()):
            return False
        self.sensor_errors = (self.sensor_errors or SensorErrors()) + increment
        return True

    def completing_stamp(self, stamp_ns: int) -> int | None:
        """The driver's stamp of the sample expected to complete the next increment, after the
        sample stamped ``stamp_ns`` (the last one added), at the sample rate; None while the
        rate is being measured."""
        if self._pending is not None:
            return None
        return stamp_ns + round(self.integrator.remaining * NS / self.rate_hz)

    def add(self, stamp_ns: int, arrival_ns: int, gyro, accel, tag=None) -> tuple:
        """Process one raw sample.

        Parameters
        ----------
        stamp_ns : int
            Its stamp on the driver's clock, ns.
        arrival_ns : int
            When it arrived (the node clock), ns; paces the clock-jump check.
        gyro, accel : sequence of 3 float
            Raw sensor-frame angular rate (rad/s) and specific force (m/s^2).
        tag : object, optional
            Returned with it in :attr:`Processed.tag`.

        Returns
        -------
        tuple of Processed
            One per sample processed: this one, none while the rate is being measured, all the
            held ones when it has been.
        """
        if self._pending is None:
            return (self._process(stamp_ns, arrival_ns, gyro, accel, tag, ()),)
        pending = self._pending
        pending.append((stamp_ns, arrival_ns, gyro, accel, tag))
        if len(pending) > PENDING_MAX:   # stamps that do not advance: bounded
            del pending[0]
        span_ns = pending[-1][0] - pending[0][0]
        if len(pending) < RATE_WINDOW_SAMPLES or span_ns < RATE_WINDOW_S * NS:
            return ()
        try:
            fit = fit_stamps([p[0] for p in pending])
        except ValueError:   # stamps that never increase: wait for better ones
            del pending[0]
            return ()
        if fit.rate_sigma > RATE_SIGMA and len(pending) < PENDING_MAX:
            return ()
        self.stamp_scatter_s = fit.scatter_s
        events = ("rate_measured",) + self._start(fit.rate_hz, strict=False)
        out = tuple(self._process(*p, events if k == 0 else ()) for k, p in enumerate(pending))
        return out

    def _process(self, stamp_ns: int, arrival_ns: int, gyro, accel, tag, events) -> Processed:
        t_ns = stamp_ns + self.offset_ns
        if self.clock is not None:
            jumps = self.clock.jumps
            t_ns = self.clock.correct(t_ns, arrival_ns)
            if self.clock.jumps != jumps:
                events += ("clock_jump",)
        if self.arrival_drift.add(t_ns, arrival_ns):
            events += ("arrival_drift_measured",)
        if self.sensor_clock is not None:
            restarts = self.sensor_clock.resets
            t_ns = self.sensor_clock.stamp(t_ns)
            if self.sensor_clock.resets != restarts and restarts:
                events += ("sensor_clock_restart",)
        if self._origin_ns is None:
            self._origin_ns = t_ns
        result = self.checker.check((t_ns - self._origin_ns) / NS, gyro, accel)
        if not result.ok:
            return Processed(t_ns, result.reason, None, (), events, tag)
        if result.reason == "gap":
            self.integrator.reset()
            self._last_ns = self._last_rates = None
            self._miss = [0.0, 0.0]
        elif result.reason == "gap_bridged":
            self.synthesised += len(result.fill_stamps)
        increments = []
        correct = self.calibration.correct_sample
        for t, g, a in zip(result.fill_stamps.tolist(), result.fill_gyro.tolist(),
                           result.fill_accel.tolist()):
            self._integrate(self._origin_ns + int(round(t * NS)),
                            *correct(g, a, self.temperature, self.sensor_errors), increments,
                            result.fill_miss)
        w_b, f_b = correct(gyro, accel, self.temperature, self.sensor_errors)
        self._integrate(t_ns, w_b, f_b, increments)
        for inc in increments:
            if self.gravity.add(inc.dv, inc.dt):
                events += ("specific_force_judged",)
        return Processed(t_ns, result.reason, (w_b, f_b), increments, events, tag)

    def _integrate(self, t_ns: int, w_b: tuple, f_b: tuple, out: list, miss=None) -> None:
        """Integrate one sample (``miss``: a bridged one's BridgeMiss sigmas, rad/s and
        m/s^2: its misses over dt add up with the others of the increment, all of one gap
        being one error)."""
        dt = self._period if self._last_ns is None else (t_ns - self._last_ns) / NS
        if miss is not None:
            self._miss[0] += miss[0] * dt
            self._miss[1] += miss[1] * dt
        self._last_ns = t_ns
        if self._instant and self._last_rates is not None:
            w_mean = [0.5 * (a + b) for a, b in zip(self._last_rates[0], w_b)]
            f_mean = [0.5 * (a + b) for a, b in zip(self._last_rates[1], f_b)]
        else:
            w_mean, f_mean = w_b, f_b
        self._last_rates = (w_b, f_b)
        done = self.integrator.add_rates(w_mean, f_mean, dt)
        if done is not None:
            angle, velocity = self._miss
            if angle or velocity:
                self._miss = [0.0, 0.0]
            out.append(Increment(t_ns, *done, angle * angle, velocity * velocity))

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

    def covariance_in_base(self, cov) -> tuple:
        """A sensor-frame 3x3 covariance (row-major 9, e.g. of a sensor_msgs reading) rotated
        into base_link by the mounting, as 9 floats; unknown (-1 first, REP-145) stays
        unknown.

        Memoised: a driver repeats the same few covariances on every sample, and the matrix
        products cost more than the lookup (keyed by the values' bytes: -0.0 is not 0.0).
        """
        key = _NINE_DOUBLES.pack(*cov)
        out = self._covariances.get(key)
        if out is None:
            if len(self._covariances) > 64:  # a driver with varying covariances
                self._covariances.clear()
            if cov[0] == -1.0:
                out = tuple(float(v) for v in cov)
            else:
                c = self.calibration.c_bs
                out = tuple((c @ np.reshape(np.asarray(cov, float), (3, 3)) @ c.T)
                            .ravel().tolist())
            self._covariances[key] = out
        return out
