"""``trial simulate``: a seeded scenario of :mod:`ins_gnss_ros.sim.scenarios` written as a bag.

The bag holds what the vehicle's sensors would have recorded plus the truth (CONTRACT.md "Truth
and setup"):

* ``imu/data_raw`` (sensor_msgs/Imu, interval-mean rates of :mod:`ins_gnss_ros.sim.imu_sim`) or,
  with ``imu_topic="delta"``, ``imu/delta`` (ImuDelta, the same increments unchanged); the IMU
  axes are the body axes (identity mounting);
* ``gnss/fix`` and ``gnss/vel``: the truth at the antenna lever arm (Groves eqs. 2.165-2.167 via
  :mod:`ins_gnss_ros.nav.lever_arm`) plus white noise;
* with ``antennas`` N >= 1 instead: what the ``gnss_simulator`` node publishes (raw
  ``gnss/observations`` of every antenna from real orbits, ``gnss/ephemeris``, and ``gnss/fix``
  / ``gnss/vel`` from the single-point solution of antenna 0), the node itself fed the truth at
  the GNSS rate on an in-process bus (:func:`_write_raw_gnss`); the antennas lie on an
  ``array`` length x width centred on ``antenna_lever_arm`` (:func:`array_antennas`);
* ``imu/mag_raw``: :mod:`ins_gnss_ros.sim.mag_sim` in the WMM field at the start point and date;
* ``log/speed`` (sea only): :mod:`ins_gnss_ros.sim.log_sim`, longitudinal speed through the water
  (transverse and vertical NaN: a single-axis log), body frame;
* ``wheel/odom`` (with ``wheel_odometry``): :mod:`ins_gnss_ros.sim.wheel_sim`, the forward
  speed of the rear-axle centre with a scale error, slip events, encoder counts and a latency;
* ``truth/state`` (with the true sensor biases in the bias fields) and ``truth/heading``.

Stamps: simulated time 0 is :data:`SIM_EPOCH_NS` on the ROS time axis (2026-01-01T00:00:00,
inside the WMM2025 life span). Every random draw derives from ``seed``: the same seed and
options give the identical (decoded) bag.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from fractions import Fraction

import numpy as np

from ins_gnss_ros import io as bag
from ins_gnss_ros.magnetic.wmm import decimal_year, field_elements
from ins_gnss_ros.nav.earth import radii
from ins_gnss_ros.nav.lever_arm import lever_arm_position, lever_arm_velocity
from ins_gnss_ros.nav.rotations import quat_from_rotvec, quat_mul
from ins_gnss_ros.nav.sensor_errors import GRADES
from ins_gnss_ros.sim import scenarios
from ins_gnss_ros.sim.imu_sim import ImuSpec, simulate_imu
from ins_gnss_ros.sim.log_sim import CurrentModel, LogSpec, simulate_log
from ins_gnss_ros.sim.mag_sim import MagErrors, simulate_magnetometer
from ins_gnss_ros.sim.wheel_sim import WheelSpec, simulate_wheel
from ins_gnss_ros.trial import contract_messages as msgs

#: ROS time of simulated t = 0: 2026-01-01T00:00:00 UTC, ns.
SIM_EPOCH_NS = 1_767_225_600 * 1_000_000_000

#: Delay from a driver's stamp to the message's log time, s (a recorder on the same machine).
TRANSPORT_DELAY_S = (1e-4, 1e-3)

#: IMU grade per scenario when none is given: a MEMS unit in the car (seed 004 Lab 1 uses an
#: ADIS16405-class prototype), a consumer one on the robot (an ICM-20948 class, as such robots
#: carry), a tactical-grade unit on the ship (seed 004 Lab 2).
DEFAULT_GRADE = {"car": "mems_adis16405", "robot": "consumer_mems", "sea": "tactical",
                 "aircraft": "navigation"}


@dataclass(frozen=True)
class SimOptions:
    """Sensor set-up of a simulated trial (SI units, lever arms in base_link FLU).

    Attributes
    ----------
    imu_grade : str or None
        Key of :data:`ins_gnss_ros.nav.sensor_errors.GRADES`; None: :data:`DEFAULT_GRADE`.
    imu_rate : float
        IMU rate, Hz (10 to 1000 or more; the trajectory runs at the least common multiple of
        every sensor rate, so any combination of rates works).
    imu_stamp_jitter : float
        Half-width of the uniform error of the IMU message stamps, s: a USB/driver stamping the
        samples on arrival while the sensor samples on its own clock (the data stay uniform).
    start_static : float or None
        Car and robot scenarios: the standstill before the drive, s (0: a rolling start; None:
        the scenario's 30 s).
    start_grade : float
        Car and robot scenarios: the road's grade at the start, rise over run (0.08: 8 %
        uphill).
    imu_orientation_sigma : float
        Write the IMU's own orientation into ``imu/data_raw`` (an AHRS), its yaw referred to
        magnetic north (the WMM declination) and off by a constant error of this 1-sigma plus
        white noise of a fifth of it, its roll and pitch by white noise of 0.5 deg; the
        covariance says the yaw sigma, deg (0: no orientation).
    imu_topic : {"data_raw", "delta"}
        Write raw rates on ``imu/data_raw`` or increments on ``imu/delta``.
    gnss_rate : float
        Rate of ``gnss/fix`` and ``gnss/vel``, Hz.
    gnss_velocity : bool
        Write ``gnss/vel`` (False: fixes only, as an SBAS/NMEA GGA receiver gives).
    gnss_covariance : bool
        Give ``gnss/fix`` and ``gnss/vel`` their covariances (False: COVARIANCE_TYPE_UNKNOWN,
        and an all-zero velocity covariance).
    gnss_sigma_h, gnss_sigma_v : float
        White position noise per horizontal axis and vertical, m.
    gnss_sigma_h_reported : float or None
        The horizontal sigma ``gnss/fix`` reports, m, the vertical in the same proportion
        (None: the true ones; a driver's placeholder covariance otherwise).
    gnss_sigma_vel : float
        White velocity noise per axis, m/s.
    gnss_sigma_vel_reported : float or None
        The velocity sigma per axis ``gnss/vel`` reports, m/s (None: the true one; a driver's
        placeholder covariance otherwise).
    gnss_latency : float
        Mean delay of ``gnss/*`` after their stamps (log time = stamp + delay), s: the
        receiver's output latency; each epoch's delay is drawn uniformly from 0.5 to 1.5 times
        it (seed 003: the delays relative to the GNSS epochs are non-uniform).
    gnss_stamped_on_arrival : bool
        ``gnss/fix`` and ``gnss/vel`` stamped when they arrive instead of at their epoch (a
        driver that stamps a message when it reads it), ``gnss_latency`` late, and logged
        ``TRANSPORT_DELAY_S`` after that stamp.
    antenna_lever_arm : tuple of 3 float
        GNSS antenna relative to the IMU, m; with ``antennas``, the centre of the array.
    antennas : int
        0: ``gnss/fix`` and ``gnss/vel`` as truth plus noise; 1-4: the raw GNSS of that many
        antennas from the GNSS simulator node (the fix and velocity from its solution, the
        velocity left out without ``gnss_velocity``; the :data:`FIX_NOISE_OPTIONS` refused).
    array : tuple of 2 float
        Length (fore-aft) and width (athwartship) of the antenna array, m.
    broadcast_residuals : bool
        With ``antennas``: the simulated ionosphere, troposphere, orbits and clocks differ from
        the broadcast models (the gnss_simulator node's ``broadcast_residuals``).
    mag_rate : float
        Magnetometer rate, Hz.
    mag_noise : float
        Magnetometer white noise, T.
    mag_iron : int or None
        Give the magnetometer the hard/soft-iron, scale and offset errors of an uncalibrated
        car installation (:meth:`MagErrors.uncalibrated_vehicle`), drawn from this seed: the
        vehicle's, so that the same car can make other drives (other trial seeds); None: an
        ideal, calibrated sensor.
    log_rate, log_noise : float
        Speed-log rate (Hz) and white noise (m/s), sea scenario.
    log_lever_arm : tuple of 3 float
        Speed-log transducer relative to the IMU, m.
    wheel_odometry : bool
        Write ``wheel/odom``.
    wheel_rate, wheel_scale_error, wheel_tick, wheel_latency : float
        Its rate (Hz), scale error (-), distance per encoder count (m) and stamp latency (s).
    wheel_slip_interval : float
        Mean time between slip events (spin or lock of 0.3-1.5 s, slip ratio 0.1-0.3), s.
    wheel_sigma : tuple of 3 float
        Forward, lateral, vertical sigma the odometry claims, m/s (the forward one near its
        quantisation, tick * rate / sqrt(6)).
    wheel_lever_arm : tuple of 3 float
        Rear-axle centre relative to the IMU, m (below it: the simulated car slips nowhere, so
        the axle keeps the constraint there).
    truth_rate : float
        Rate of ``truth/state`` and ``truth/heading``, Hz.
    """

    imu_grade: str | None = None
    imu_rate: float = 200.0
    imu_stamp_jitter: float = 0.0
    imu_orientation_sigma: float = 0.0
    start_static: float | None = None
    start_grade: float = 0.0
    imu_topic: str = "data_raw"
    gnss_rate: float = 5.0
    gnss_velocity: bool = True
    gnss_covariance: bool = True
    gnss_sigma_h: float = 0.5
    gnss_sigma_v: float = 1.0
    gnss_sigma_h_reported: float | None = None
    gnss_sigma_vel: float = 0.05
    gnss_sigma_vel_reported: float | None = None
    gnss_latency: float = 0.0
    gnss_stamped_on_arrival: bool = False
    antenna_lever_arm: tuple = (0.0, 0.0, 1.5)
    antennas: int = 0
    array: tuple = (1.5, 1.0)
    broadcast_residuals: bool = False
    mag_rate: float = 50.0
    mag_noise: float = 100e-9
    mag_iron: int | None = None
    log_rate: float = 2.0
    log_noise: float = 0.05
    log_lever_arm: tuple = (0.0, 0.0, -2.0)
    wheel_odometry: bool = False
    wheel_rate: float = 20.0
    wheel_scale_error: float = 0.01
    wheel_tick: float = 0.02
    wheel_latency: float = 0.05
    wheel_slip_interval: float = 30.0
    wheel_sigma: tuple = (0.2, 0.1, 0.1)
    wheel_lever_arm: tuple = (0.0, 0.0, -0.4)
    truth_rate: float = 20.0


def simulate(scenario: str, duration: float, seed: int, out, options: SimOptions = SimOptions()):
    """Simulate a scenario and write it as a bag folder ``out``.

    Parameters
    ----------
    scenario : {"car", "robot", "sea", "aircraft"}
    duration : float
        s (> 0).
    seed : int
    out : path
        New bag folder.
    options : SimOptions

    Returns
    -------
    Path
        The bag folder.
    """
    if scenario not in scenarios.SCENARIOS:
        raise ValueError(f"unknown scenario {scenario!r}; known: {', '.join(scenarios.SCENARIOS)}")
    if not duration > 0.0:
        raise ValueError(f"duration must be > 0 s, got {duration}")
    if options.imu_topic not in ("data_raw", "delta"):
        raise ValueError(f"imu_topic must be data_raw or delta, got {options.imu_topic!r}")
    grade_name = options.imu_grade or DEFAULT_GRADE[scenario]
    if grade_name not in GRADES:
        raise ValueError(f"unknown IMU grade {grade_name!r}; known: {', '.join(GRADES)}")
    grade = GRADES[grade_name]
    writer = bag.BagWriter(out)  # an existing output is refused before the work
    if not 0 <= options.antennas <= 4:
        raise ValueError(f"antennas must be 0 to 4, got {options.antennas}")
    if options.broadcast_residuals and not options.antennas:
        raise ValueError("broadcast residuals need the raw GNSS of antennas >= 1")
    not_raw = [name for name in FIX_NOISE_OPTIONS
               if getattr(options, name) != getattr(SimOptions, name)]
    if options.antennas and not_raw:
        raise ValueError(f"{', '.join(not_raw)}: options of the fixes as truth plus noise, not "
                         "of the raw GNSS of antennas >= 1 (the gnss_simulator node's errors)")
    if options.gnss_sigma_h_reported is not None and not options.gnss_sigma_h > 0.0:
        raise ValueError("a reported fix sigma needs gnss_sigma_h > 0 (its vertical in "
                         "proportion)")
    # Words of one SeedSequence: a fifth (the wheels), a sixth (the raw GNSS) leave the first
    # ones as they were.
    seeds = np.random.SeedSequence(seed).generate_state(6)
    start = {} if options.start_static is None else {"static": options.start_static}
    if options.start_grade:
        start["start_grade"] = options.start_grade
    if start and scenario not in ("car", "robot"):
        raise ValueError("start_static and start_grade are options of the car and robot "
                         "scenarios")
    sc = scenarios.SCENARIOS[scenario](duration=duration, seed=seed,
                                       rate=trajectory_rate(options, scenario), **start)
    traj = sc.trajectory
    imu = _write_imu(writer, traj, ImuSpec(grade, rate=options.imu_rate), int(seeds[0]), options)
    if options.antennas:
        _write_raw_gnss(writer, traj, options, int(seeds[5]) % 2 ** 31)
    else:
        _write_gnss(writer, traj, options, np.random.default_rng(seeds[1]),
                    np.random.default_rng([seed, 5]))
    _write_mag(writer, traj, options, int(seeds[2]))
    if scenario == "sea":
        _write_log(writer, traj, sc.water_current_enu, options, int(seeds[3]))
    if options.wheel_odometry:
        _write_wheel(writer, traj, options, int(seeds[4]))
    _write_truth(writer, traj, imu, options)
    return writer.close()


def trajectory_rate(options: SimOptions, scenario: str) -> float:
    """The least common multiple of the scenario's sensor rates, Hz: every sensor then samples
    the trajectory exactly (rates as fractions of up to three decimals, e.g. 2.5 Hz)."""
    rates = [options.imu_rate, options.gnss_rate, options.mag_rate, options.truth_rate]
    if scenario == "sea":
        rates.append(options.log_rate)
    if options.wheel_odometry:
        rates.append(options.wheel_rate)
    fractions = [Fraction(r).limit_denominator(1000) for r in rates]
    if min(fractions) <= 0:
        raise ValueError(f"sensor rates must be > 0 Hz, got {rates}")
    numerator = math.lcm(*(f.numerator for f in fractions))
    denominator = math.gcd(*(f.denominator for f in fractions))
    return numerator / denominator


def _every(traj, rate):
    """Indices of trajectory samples at ``rate`` Hz."""
    return np.arange(0, len(traj), traj.decimation(rate))


def _write_imu(writer, traj, spec, seed, options):
    imu = simulate_imu(traj, spec, seed)
    t = imu.t
    if options.imu_stamp_jitter > 0.0:
        # Stamped on arrival: each stamp off by up to the jitter, never out of order.
        rng = np.random.default_rng(seed + 1)
        t = t + rng.uniform(-1.0, 1.0, len(t)) * min(options.imu_stamp_jitter, 0.45 * imu.dt)
    t_ns = bag.sec_to_ns(t, SIM_EPOCH_NS)
    if options.imu_topic == "delta":
        writer.write_all("imu/delta", (msgs.delta_msg(t, a, v, imu.dt)
                                       for t, a, v in zip(t_ns, imu.dtheta, imu.dv)))
    elif options.imu_orientation_sigma > 0.0:
        q, cov = _ahrs_orientation(traj, imu, options.imu_orientation_sigma,
                                   np.random.default_rng(seed + 2))
        writer.write_all("imu/data_raw", (msgs.imu_msg(t, w, f, orientation=o,
                                                       orientation_cov=cov)
                                          for t, w, f, o in zip(t_ns, imu.gyro, imu.accel, q)))
    else:
        writer.write_all("imu/data_raw", (msgs.imu_msg(t, w, f)
                                          for t, w, f in zip(t_ns, imu.gyro, imu.accel)))
    return imu


def _ahrs_orientation(traj, imu, sigma_deg, rng):
    """An AHRS's orientation at the IMU samples (SimOptions.imu_orientation_sigma) and the
    diagonal of its covariance, rad^2."""
    k = np.minimum(np.arange(1, len(imu.t) + 1) * traj.decimation(1.0 / imu.dt), len(traj) - 1)
    year = decimal_year(SIM_EPOCH_NS * 1e-9 + traj.t[0])
    declination = field_elements(traj.lat[0], traj.lon[0], traj.h[0], year).declination
    sigma = np.radians(sigma_deg)
    # magnetic yaw = true yaw + declination (the azimuth is the yaw's complement)
    yaw_error = declination + sigma * rng.standard_normal() + 0.2 * sigma * rng.standard_normal(len(k))
    tilt = np.radians(0.5) * rng.standard_normal((len(k), 2))
    errors = np.column_stack([tilt, yaw_error])
    q = np.array([quat_mul(quat_from_rotvec(e), q) for e, q in zip(errors, traj.q_nb[k])])
    return q, (np.radians(0.5) ** 2, np.radians(0.5) ** 2, sigma ** 2)


def _write_gnss(writer, traj, options, rng, latency_rng):
    k = _every(traj, options.gnss_rate)
    lever = np.asarray(options.antenna_lever_arm, float)
    lat, lon, h = lever_arm_position(traj.lat[k], traj.lon[k], traj.h[k], traj.q_nb[k], lever)
    vel = lever_arm_velocity(traj.v_enu[k], traj.q_nb[k], traj.omega_ib_b[k], lever, traj.lat[k])
    sigma = np.array([options.gnss_sigma_h, options.gnss_sigma_h, options.gnss_sigma_v])
    d_enu = sigma * rng.standard_normal((len(k), 3))
    rm, rn = radii(lat)
    lat = lat + d_enu[:, 1] / (rm + h)
    lon = lon + d_enu[:, 0] / ((rn + h) * np.cos(lat))
    h = h + d_enu[:, 2]
    vel = vel + options.gnss_sigma_vel * rng.standard_normal(vel.shape)
    t_ns = bag.sec_to_ns(traj.t[k], SIM_EPOCH_NS)
    reported = options.gnss_sigma_vel if options.gnss_sigma_vel_reported is None \
        else options.gnss_sigma_vel_reported
    var, var_v = sigma ** 2, [reported ** 2] * 3
    if options.gnss_sigma_h_reported is not None:
        var = var * (options.gnss_sigma_h_reported / options.gnss_sigma_h) ** 2
    arrival = t_ns
    if options.gnss_latency > 0.0:
        arrival = t_ns + bag.sec_to_ns(options.gnss_latency
                                       * latency_rng.uniform(0.5, 1.5, len(t_ns)))
    if options.gnss_stamped_on_arrival:
        # the driver stamps the time it reads the message; it is logged after the transport
        t_ns = arrival
        arrival = t_ns + bag.sec_to_ns(latency_rng.uniform(*TRANSPORT_DELAY_S, len(t_ns)))
    for i, t in enumerate(t_ns):
        writer.write("gnss/fix", msgs.fix_msg(t, lat[i], lon[i], h[i],
                                               var if options.gnss_covariance else None),
                     arrival[i])
        if options.gnss_velocity:
            writer.write("gnss/vel", msgs.twist_msg(t, vel[i], var_v if options.gnss_covariance
                                                    else [0.0] * 3, "gnss"), arrival[i])


def array_antennas(n: int, length: float, width: float, centre=(0.0, 0.0, 0.0)) -> tuple:
    """Positions of n = 1-4 antennas on a length (fore-aft) x width (athwartship) array about
    ``centre`` (base_link FLU, m): one at the centre; two fore and aft on the centre line; three
    or four at the corners, fore-port first (antenna 0, the master), then aft-port, fore-
    starboard, aft-starboard."""
    x, y = length / 2, width / 2
    layouts = {1: ((0.0, 0.0),), 2: ((x, 0.0), (-x, 0.0)),
               3: ((x, y), (-x, y), (x, -y)), 4: ((x, y), (-x, y), (x, -y), (-x, -y))}
    cx, cy, cz = (float(c) for c in centre)
    return tuple((cx + dx, cy + dy, cz) for dx, dy in layouts[n])


#: Topics of the GNSS simulator node a simulated trial keeps (gnss/vel unless
#: SimOptions.gnss_velocity is off).
RAW_GNSS_TOPICS = ("gnss/observations", "gnss/ephemeris", "gnss/fix", "gnss/vel")

#: SimOptions of the fixes as truth plus noise (antennas 0) that the raw GNSS does not take:
#: left at their defaults with antennas >= 1, not ignored.
FIX_NOISE_OPTIONS = ("gnss_covariance", "gnss_sigma_h", "gnss_sigma_v", "gnss_sigma_h_reported",
                     "gnss_sigma_vel", "gnss_sigma_vel_reported", "gnss_latency",
                     "gnss_stamped_on_arrival")


def _write_raw_gnss(writer, traj, options, seed):
    """The ``gnss_simulator`` node's output (:data:`RAW_GNSS_TOPICS`) for the truth at the
    GNSS epochs: the node runs on an in-process bus, as in a graph, so the bag holds what the
    node publishes live (SimOptions.antennas)."""
    import rclpy
    from rclpy.parameter import Parameter

    from ins_gnss_ros.nodes.base import InProcessBus
    from ins_gnss_ros.nodes.gnss_simulator_node import GnssSimulatorNode

    antennas = array_antennas(options.antennas, *options.array, options.antenna_lever_arm)
    context = rclpy.Context()
    rclpy.init(context=context, args=[])
    try:
        bus = InProcessBus()
        node = GnssSimulatorNode(bus=bus, context=context, parameter_overrides=[
            Parameter("source", value="truth"),
            Parameter("lever_arms", value=[v for a in antennas for v in a]),
            Parameter("rate_hz", value=float(options.gnss_rate)), Parameter("seed", value=seed),
            Parameter("broadcast_residuals", value=options.broadcast_residuals)])
        for topic in RAW_GNSS_TOPICS:
            if topic != "gnss/vel" or options.gnss_velocity:
                bus.subscribe(topic, lambda msg, topic=topic: writer.write(topic, msg))
        k = _every(traj, options.gnss_rate)
        for t_ns, i in zip(bag.sec_to_ns(traj.t[k], SIM_EPOCH_NS), k):
            bus.publish("sim/truth", msgs.ins_state_msg(
                t_ns, traj.lat[i], traj.lon[i], traj.h[i], traj.v_enu[i], traj.q_nb[i],
                traj.omega_ib_b[i]))
            bus.drain()
        node.destroy_node()
    finally:
        rclpy.shutdown(context=context)


def _write_mag(writer, traj, options, seed):
    year = decimal_year(SIM_EPOCH_NS * 1e-9 + traj.t[0])
    earth_field = field_elements(traj.lat[0], traj.lon[0], traj.h[0], year).enu
    errors = MagErrors(noise_std=options.mag_noise) if options.mag_iron is None else \
        MagErrors.uncalibrated_vehicle(np.random.default_rng([options.mag_iron, 6]),
                                       options.mag_noise)
    mag = simulate_magnetometer(traj, earth_field, errors, rate=options.mag_rate, seed=seed)
    t_ns = bag.sec_to_ns(mag.t, SIM_EPOCH_NS)
    writer.write_all("imu/mag_raw", (msgs.mag_msg(t, b, options.mag_noise ** 2)
                                     for t, b in zip(t_ns, mag.field_b)))


def _write_log(writer, traj, current_enu, options, seed):
    spec = LogSpec(rate=options.log_rate, noise_std=options.log_noise,
                   lever_arm_b=np.asarray(options.log_lever_arm, float))
    log = simulate_log(traj, CurrentModel(mean_enu=np.asarray(current_enu, float)), spec, seed)
    t_ns = bag.sec_to_ns(log.t, SIM_EPOCH_NS)
    var = [options.log_noise ** 2, np.nan, np.nan]
    writer.write_all("log/speed", (msgs.twist_msg(t, (v, np.nan, np.nan), var, "base_link")
                                   for t, v in zip(t_ns, log.speed)))


def _write_wheel(writer, traj, options, seed):
    spec = WheelSpec(rate=options.wheel_rate, scale_error=options.wheel_scale_error,
                     tick=options.wheel_tick, latency=options.wheel_latency,
                     slip_interval=options.wheel_slip_interval,
                     lever_arm_b=np.asarray(options.wheel_lever_arm, float))
    wheel = simulate_wheel(traj, spec, seed)
    var = np.square(options.wheel_sigma)
    writer.write_all("wheel/odom", (msgs.wheel_odom_msg(t, v, var) for t, v in
                                    zip(bag.sec_to_ns(wheel.stamp, SIM_EPOCH_NS), wheel.speed)))


def _write_truth(writer, traj, imu, options):
    k = _every(traj, options.truth_rate)
    # True bias of the IMU interval ending at or after each truth epoch (the truth of the
    # filter's bias estimates; the first epoch takes the first interval).
    j = np.clip(np.searchsorted(imu.t, traj.t[k] - 1e-9), 0, len(imu.t) - 1)
    gyro_bias, accel_bias = imu.gyro_bias, imu.accel_bias
    t_ns = bag.sec_to_ns(traj.t[k], SIM_EPOCH_NS)
    for n, i in enumerate(k):
        writer.write("truth/state", msgs.ins_state_msg(
            t_ns[n], traj.lat[i], traj.lon[i], traj.h[i], traj.v_enu[i], traj.q_nb[i],
            traj.omega_ib_b[i], traj.f_b[i], gyro_bias[j[n]], accel_bias[j[n]]))
        writer.write("truth/heading", msgs.heading_msg(t_ns[n], traj.q_nb[i]))
