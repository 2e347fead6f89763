"""The ``ekf`` node's parameters and the navigator configuration they make, ROS-free.

The live node declares :data:`PARAMS` to ROS; the offline replay resolves a profile's ``ekf``
section against the same specifications (:func:`ins_gnss_ros.params.resolve`) and builds the
same :class:`~ins_gnss_ros.nav.navigator.NavigatorConfig` with :func:`navigator_config`, so that
one profile configures one filter whichever path runs it.
"""
from __future__ import annotations

import numpy as np

from ..params import Param
from .ekf import LEVER_ARM_EXTRAS, ExtraState
from .error_model import LAYOUTS
from .navigator_config import NavigatorConfig
from .sensor_errors import GRADES, BlockNoise, FilterNoise, filter_noise
from .vehicle_constraint import BORESIGHT_SIGMA_DEG

__all__ = ["PARAMS", "navigator_config", "noise_model"]

#: The ekf node's parameters (the names the profiles' ``ekf`` sections use).
PARAMS = (
    Param("layout", "15", "error-state layout (error_model.LAYOUTS key)", choices=tuple(LAYOUTS)),
    Param("imu_grade", "mems_uncalibrated",
          "IMU noise model preset (sensor_errors.GRADES)", choices=tuple(GRADES)),
    Param("bias_model", "rw", "bias process: rw (a random walk carrying the in-run "
          "instability) or gm (constant + Gauss-Markov states: in a layout that has them, e.g. "
          "21gm; elsewhere as rw)", choices=("gm", "rw")),
    Param("noise.gyro_white", 0.0, "gyro white noise, rad/s/sqrt(Hz) (0: the grade's)", 0.0, 1.0),
    Param("noise.accel_white", 0.0, "accelerometer white noise, m/s^2/sqrt(Hz) (0: the grade's)",
          0.0, 10.0),
    Param("noise.gyro_bias_sigma", 0.0, "initial gyro bias sigma, rad/s (0: the grade's)",
          0.0, 1.0),
    Param("noise.gyro_bias_walk", 0.0, "gyro bias random walk, rad/s/sqrt(s) (0: the grade's)",
          0.0, 1.0),
    Param("noise.accel_bias_sigma", 0.0, "initial accelerometer bias sigma, m/s^2 (0: the "
          "grade's)", 0.0, 10.0),
    Param("noise.accel_bias_walk", 0.0, "accelerometer bias random walk, m/s^2/sqrt(s) (0: the "
          "grade's)", 0.0, 10.0),
    Param("lever_arm", [0.0, 0.0, 0.0], "GNSS antenna position in base_link (FLU), m; all zero: "
          "not known (the ekf node then takes it from /tf_static, before its filter starts)",
          -100.0, 100.0, length=3),
    Param("lever_arm_sigma_m", [0.0, 0.0, 0.0],
          "uncertainty of lever_arm per axis (FLU), m, carried in the covariance and never "
          "estimated (a consider state; all 0: the lever arm is exact)", 0.0, 100.0, length=3),
    Param("lever_arm_published_sigma_m", [0.0, 0.0, 0.0],
          "uncertainty of lever_arm per axis (FLU), m, added to the published position "
          "covariance only (an installation nobody measured; a consider state, "
          "lever_arm_sigma_m, weighs the fixes by it too)", 0.0, 100.0, length=3),
    Param("gate_probability", 0.9999, "chi-square gate probability of every update", 0.5, 1.0),
    Param("covariance_interval_s", 0.1, "covariance propagation interval, s", 0.005, 1.0),
    Param("gnss.position_sigma_floor_m", 0.02, "floor of the GNSS position sigma per axis, m",
          0.0, 100.0),
    Param("gnss.velocity_sigma_floor_mps", 0.02, "floor of the GNSS velocity sigma, m/s",
          0.0, 10.0),
    Param("gnss.velocity_delay_s", 0.0, "latency of the receiver's velocity solution: a "
          "gnss/vel stamped t is applied at t - delay, s", 0.0, 2.0),
    Param("gnss.velocity_latency_sigma_s", 0.0, "initial sigma of the filter state of the "
          "receiver velocity's latency beyond gnss.velocity_delay_s, s (0: no state)", 0.0, 1.0),
    Param("coupling", "loose", "GNSS aiding: loose (fix + velocity), tight (pseudorange + "
          "Doppler; needs a layout with the clock block, e.g. 24) or auto (tight below "
          "auto.min_satellites)", choices=("loose", "tight", "auto")),
    Param("auto.min_satellites", 5, "auto coupling: fewer usable satellites than this in an "
          "epoch switch to tight", 1, 64),
    Param("tight.gps", True, "tight coupling uses GPS L1 C/A"),
    Param("tight.galileo", True, "tight coupling uses Galileo E1 (one receiver clock with GPS)"),
    Param("tight.code_sigma_m", [0.5, 0.5], "pseudorange sigma a, b of a^2 + b^2/sin^2(el), m",
          0.0, 100.0, length=2),
    Param("tight.doppler_sigma_hz", [0.05, 0.05], "Doppler sigma a, b, Hz", 0.0, 100.0,
          length=2),
    Param("tight.klobuchar", [0.0] * 8, "broadcast ionosphere alpha0-3, beta0-3 (IS-GPS-200 "
          "units: s, s/semicircle^n); all zero: no ionosphere correction", -1e7, 1e7, length=8),
    Param("tight.elevation_mask_deg", 10.0, "satellites below this elevation are not used, deg",
          0.0, 60.0),
    Param("tight.align_on_observations", False, "tight coupling: align on the single-point "
          "fix and Doppler velocity of gnss/observations, and subscribe neither gnss/fix nor "
          "gnss/vel (a receiver whose own fix is no input, e.g. the RTK reference of a trial)"),
    Param("use_heading", True, "use gnss/heading (phase-difference or receiver azimuth)"),
    Param("use_phase_dd", False, "fuse the fixed carrier-phase double differences of "
          "gnss/phase_dd as attitude measurements (the antenna baselines and the full DD "
          "covariance they carry) once the heading is known; gnss/heading then only aligns it"),
    Param("use_magnetic_heading", False, "use mag/heading as backup heading aiding"),
    Param("use_imu_heading", True, "use imu/heading (the IMU's own orientation where its "
          "covariance says the yaw is valid) as a heading source"),
    Param("imu_heading_bias_sigma_deg", 5.0, "initial sigma of the imu/heading bias state, deg "
          "(an AHRS's yaw error: magnetic disturbance, its own alignment; 0: no bias state)",
          0.0, 30.0),
    Param("magnetic_bias_sigma_deg", 2.0,
          "initial sigma of the magnetic-heading bias state, deg (0: no bias state)", 0.0, 30.0),
    Param("magnetic_levelled_by_ins", True, "mag/heading was levelled with this filter's roll "
          "and pitch (mag_compass attitude_source: ins_state): in motion its error holds the "
          "filter's tilt error times the tangent of the field's inclination, fused as such; "
          "false for a compass that levels itself"),
    Param("use_speed_log", False,
          "use log/speed (water speed along body x) with water-current and log-scale states"),
    Param("speed_log.current_sigma_mps", 0.3, "initial sigma of the water current, m/s",
          0.0, 10.0),
    Param("speed_log.scale_sigma", 0.02, "initial sigma of the log scale error, -", 0.0, 1.0),
    Param("use_wheel_odometry", False,
          "use wheel/odom (nav_msgs/Odometry, twist in its child frame at wheel.lever_arm): the "
          "forward speed with a scale-error state, lateral and vertical as non-holonomic "
          "constraints, zero speed as a zero-velocity update"),
    Param("wheel.lever_arm", [0.0, 0.0, 0.0], "wheel odometry reference point (rear-axle "
          "centre) in base_link (FLU), m", -100.0, 100.0, length=3),
    Param("wheel.scale_sigma", 0.02, "initial sigma of the wheel odometry scale error, -",
          0.0, 1.0),
    Param("wheel.speed_sigma_mps", 0.1, "forward speed sigma of a wheel/odom without its "
          "variance, m/s", 0.0, 10.0),
    Param("wheel.nonholonomic_sigma_mps", [0.1, 0.1], "lateral, vertical sigma of a wheel/odom "
          "without their variances (skid, suspension), m/s; 0 leaves the axis out",
          0.0, 10.0, length=2),
    Param("wheel.zero_speed_mps", 0.01, "a wheel/odom at or below this forward speed is a "
          "zero-velocity update, m/s (0: never)", 0.0, 1.0),
    Param("wheel.zero_speed_time_s", 0.5, "the forward speed must have stayed at or below "
          "wheel.zero_speed_mps this long (encoder counts read zero at a crawl too), s",
          0.0, 60.0),
    Param("wheel.zero_velocity_sigma_mps", 0.02, "sigma of the zero-velocity update at zero "
          "wheel speed, m/s", 0.0, 1.0),
    Param("wheel.delay_s", 0.0, "latency of wheel/odom: a reading stamped t is applied at "
          "t - delay (transport plus half the speed's averaging interval), s", 0.0, 2.0),
    Param("time_offset_sigma_s", 0.0,
          "initial sigma of the IMU-GNSS time-offset state, s (0: no state, unless gnss/* "
          "come stamped on their arrival: then 0.2, nav/aiding.py Aiding.arrival)", 0.0, 1.0),
    Param("nonholonomic_sigma_mps", [0.0, 0.0],
          "wheeled-vehicle constraint noise (lateral, vertical), m/s; 0: learned or off "
          "(nonholonomic.learn)", 0.0, 10.0, length=2),
    Param("nonholonomic.lever_arm", [0.0, 0.0, 0.0],
          "point where the non-holonomic constraint holds (rear-axle centre) relative to the "
          "IMU, base_link (FLU), m", -100.0, 100.0, length=3),
    Param("nonholonomic.rate_arm_m", 0.0,
          "how far the rear axle may be along x from nonholonomic.lever_arm, m: the yaw rate "
          "times it widens the lateral constraint noise (a turn moves the IMU sideways)",
          0.0, 100.0),
    Param("nonholonomic.learn", True,
          "without nonholonomic_sigma_mps: learn from the GNSS-aided solution whether the "
          "vehicle moves like a wheeled one (body lateral and vertical velocity RMS within "
          "0.3 m/s over 30 s of motion) and apply the constraint with the noise learned"),
    Param("init.position_sigma_m", 1.0, "initial position sigma at the first fix, m", 0.0, 1e4),
    Param("init.velocity_sigma_mps", 0.1, "initial velocity sigma, m/s", 0.0, 100.0),
    Param("init.tilt_sigma_deg", 1.0, "initial roll/pitch sigma, deg", 0.0, 90.0),
    Param("init.moving_accel_sigma_mps2", 1.0, "a start on the move that no two gnss/vel "
          "measure (a still IMU aside): sigma of the vehicle's mean horizontal acceleration "
          "over the levelling, which the levelled roll and pitch take for gravity, m/s^2",
          0.0, 20.0),
    Param("align.speed_mps", 0.5, "GNSS speed at which the heading is taken from motion, m/s",
          0.0, 50.0),
    Param("align.static_speed_mps", 0.1, "GNSS speed below which the vehicle is at rest, m/s",
          0.0, 10.0),
    Param("dead_reckoning_after_s", 2.0, "no accepted aiding for this long: DEAD_RECKONING, s",
          0.1, 3600.0),
    Param("history_s", 3.0, "how late a measurement may arrive and still be used, s", 0.1, 60.0),
    Param("forced.floor_tau_s", 30.0, "time constant of the noise floor a measurement kind "
          "keeps after it was forced in (decays while the kind is accepted), s", 0.1, 3600.0),
    Param("forced.degraded_ratio", 3.0, "the mode is DEAD_RECKONING (degraded) while a forced "
          "kind's floor exceeds this many times its own standard deviation, until the kind has "
          "been accepted for forced.confirm_time_s since it was last forced or rejected, -",
          0.0, 1000.0),
    Param("forced.confirm_time_s", 10.0, "a forced kind accepted this long without being forced "
          "or rejected again confirms the solution (its floor stays in the covariance), s",
          0.0, 3600.0),
    Param("max_imu_gap_s", 2.5, "longest gap in imu/delta bridged by holding the rates of the "
          "increment after it; a longer one loses the IMU and the filter aligns again, s",
          0.0, 60.0),
    Param("imu_gap.accel_sigma_mps2", 1.0, "over a bridged imu/delta gap: sigma of the "
          "difference between the held and the true specific force, m/s^2", 0.0, 100.0),
    Param("imu_gap.rate_sigma_dps", 5.0, "over a bridged imu/delta gap: sigma of the "
          "difference between the held and the true angular rate, deg/s", 0.0, 1000.0),
    Param("sync.min_interval_s", 0.0, "shortest interval between two corrections, s (0: one after "
          "every update; the strapdown, and what follows it, lags the filter by up to this)",
          0.0, 10.0),
    Param("sync.resend_after_s", 1.0,
          "send a correction against the newest ins/state if none matched for this long, s",
          0.1, 60.0),
    Param("output_rate_hz", 10.0, "rate of nav/odom and nav/fix (from the synchronised "
          "ins/state), Hz", 0.1, 1000.0),
    Param("datum.from_first_fix", True, "map-frame origin at the first fix (else datum.*)"),
    Param("datum.latitude_deg", 0.0, "map-frame origin latitude, deg", -90.0, 90.0),
    Param("datum.longitude_deg", 0.0, "map-frame origin longitude, deg", -180.0, 360.0),
    Param("datum.altitude_m", 0.0, "map-frame origin ellipsoidal height, m", -1000.0, 1e5),
)

#: nav/status comes after every update and at least this often, s (the ekf node; --offline
#: writes it at this period and hands its compass the tilt sigma on the node's schedule).
STATUS_PERIOD_S = 1.0

#: Heading topics of the ekf -> the parameter that turns each on (nav/aiding.HEADING_SOURCES
#: says which bias state each has).
HEADING_INPUTS = {"gnss/heading": "use_heading", "mag/heading": "use_magnetic_heading",
                  "imu/heading": "use_imu_heading"}


def noise_model(p: dict) -> FilterNoise:
    """The grade's filter noise with the ``noise.*`` parameters that are set put in its place.

    Parameters
    ----------
    p : dict
        The ``ekf`` node's parameters (``imu_grade``, ``bias_model``, ``noise.*``).
    """
    # The exact bias model needs the layout's Gauss-Markov states: without them the grade's
    # in-run instability would be neither a state nor a noise, and the filter grows sure of
    # constant biases the IMU does not have (the vessel trial with layout 15: attitude NEES 26,
    # pitch 0.6 deg off). The reduced model carries it in the bias random walk instead.
    exact = p["bias_model"] == "gm" and {"gmg", "gma"} <= set(LAYOUTS[p["layout"]])
    noise = filter_noise(GRADES[p["imu_grade"]], "gm" if exact else "rw")
    blocks = dict(noise.blocks)
    for block, sigma, walk in (("bg", "noise.gyro_bias_sigma", "noise.gyro_bias_walk"),
                               ("ba", "noise.accel_bias_sigma", "noise.accel_bias_walk")):
        b = blocks[block]
        blocks[block] = BlockNoise(p[sigma] or b.sigma0, b.tau,
                                   p[walk] ** 2 if p[walk] else b.psd)
    return FilterNoise(p["noise.gyro_white"] ** 2 or noise.gyro_psd,
                       p["noise.accel_white"] ** 2 or noise.accel_psd, blocks)


def navigator_config(p: dict, record: bool = False) -> NavigatorConfig:
    """The navigator configuration of the ``ekf`` node's parameters (names as in its PARAMS).

    ``record`` keeps the per-epoch output and covariance (offline runs); the live node keeps
    neither.
    """
    extras = {}
    for name, sigma in zip(LEVER_ARM_EXTRAS, p["lever_arm_sigma_m"]):
        if sigma > 0.0:
            extras[name] = ExtraState(1, sigma, consider=True)
    if p["time_offset_sigma_s"] > 0.0:
        extras["td"] = ExtraState(1, p["time_offset_sigma_s"])
    if p["gnss.velocity_latency_sigma_s"] > 0.0:
        extras["vd"] = ExtraState(1, p["gnss.velocity_latency_sigma_s"])
    nhc = tuple(p["nonholonomic_sigma_mps"])
    learn_nhc = p["nonholonomic.learn"] and min(nhc) <= 0.0
    if learn_nhc:  # the learned axes' boresight (vehicle_constraint.py)
        extras["nhc"] = ExtraState(2, np.radians(BORESIGHT_SIGMA_DEG))
    if p["use_magnetic_heading"] and p["magnetic_bias_sigma_deg"] > 0.0:
        extras["mag"] = ExtraState(1, np.radians(p["magnetic_bias_sigma_deg"]))
    if p["use_imu_heading"] and p["imu_heading_bias_sigma_deg"] > 0.0:
        extras["ahrs"] = ExtraState(1, np.radians(p["imu_heading_bias_sigma_deg"]))
    if p["use_speed_log"]:
        # water current east, north (m/s) and log scale error (-), slowly varying
        sigma_current = p["speed_log.current_sigma_mps"]
        extras["log"] = ExtraState(3, np.array([sigma_current, sigma_current,
                                                p["speed_log.scale_sigma"]]), psd=1e-6)
    if p["use_wheel_odometry"]:
        # the tyre radius drifts slowly (temperature, pressure, load): 1e-4/sqrt(s)
        extras["wheel"] = ExtraState(1, p["wheel.scale_sigma"], psd=1e-8)
    return NavigatorConfig(
        noise=noise_model(p),
        layout=p["layout"], extras=extras, lever_arm_b=np.array(p["lever_arm"], float),
        lever_published_var=np.square(np.array(p["lever_arm_published_sigma_m"], float)),
        cov_interval=p["covariance_interval_s"], gate_prob=p["gate_probability"],
        sigma_pos0=p["init.position_sigma_m"], sigma_vel0=p["init.velocity_sigma_mps"],
        sigma_tilt0=np.radians(p["init.tilt_sigma_deg"]),
        moving_accel_sigma=p["init.moving_accel_sigma_mps2"], align_speed=p["align.speed_mps"],
        static_speed=p["align.static_speed_mps"], dr_timeout=p["dead_reckoning_after_s"],
        nhc_sigma=nhc if min(nhc) > 0.0 else None, nhc_learn=learn_nhc,
        nhc_lever_b=np.array(p["nonholonomic.lever_arm"], float),
        nhc_rate_arm=p["nonholonomic.rate_arm_m"],
        history=p["history_s"],
        wheel_lever_b=np.array(p["wheel.lever_arm"], float),
        floor_tau=p["forced.floor_tau_s"], confirm_time=p["forced.confirm_time_s"],
        degraded_ratio=p["forced.degraded_ratio"],
        gap_accel_sigma=p["imu_gap.accel_sigma_mps2"],
        gap_rate_sigma=np.radians(p["imu_gap.rate_sigma_dps"]),
        store_covariance=record, record=record,
        compensated_increments=True)  # imu/delta: coning/sculling-compensated by contract
