"""``trial import``: recorded trials converted into bags with the contract's topics.

Time axis: the project's stamps are UTC on the ROS time axis (README): GPS times of recorded
data become GPS seconds since 1980-01-06 + :data:`GPS_TO_ROS_S` minus the leap seconds of the
recording's date, the same mapping the gnss_driver applies live.

* ``rtklib-drive`` (:mod:`ins_gnss_ros.trial.car_drive`): ``imu/data_raw`` in the IMU's OWN axes
  (SI units, frame ``imu_link``; the mounting rotation is left to the imu_preprocessor's
  ``mounting_rpy_deg``, see :func:`car_mounting_rpy_deg` and config/car.yaml), stamped by the
  tag-file mapping with the source's -0.125 s IMU clock offset NOT applied (it is a calibration
  of that installation, kept as a parameter, not baked into the data); every RTKLIB epoch as
  ``gnss/fix`` + ``gnss/vel`` (status GBAS_FIX for RTK fixed/float, FIX for single); the RTK-fixed
  epochs as ``truth/state`` (antenna position and velocity; orientation NaN: the data set has no
  attitude truth; the 5 cm antenna-IMU offset is not removed).
* ``ubx`` (:mod:`ins_gnss_ros.gnss.stream`): RXM-RAWX epochs as ``gnss/observations``, broadcast
  ephemerides assembled from RXM-SFRBX as ``gnss/ephemeris`` (stamped at the epoch that completed
  them), NAV-PVT as ``gnss/fix`` and ``gnss/vel``; with an RTKLIB ``.pos`` of the same data, its
  fixed epochs as ``truth/state``.
* ``vessel-parquet`` (:mod:`ins_gnss_ros.trial.vessel`): the measured IMU as ``imu/data_raw``
  (body FLU, identity mounting), the 5 cm GNSS fixes as ``gnss/fix``, the 0.1 deg compass as
  ``gnss/heading`` (source RECEIVER, reference TRUE), truth as ``truth/state`` and
  ``truth/heading``; simulation time 0 is placed at
  :data:`~ins_gnss_ros.trial.simulate.SIM_EPOCH_NS`.
"""
from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from ins_gnss_ros import io as bag
from ins_gnss_ros.trial import contract_messages as msgs

#: Unix time of the GPS epoch 1980-01-06T00:00:00, s.
GPS_TO_ROS_S = 315_964_800


def gps_to_ns(t_gps):
    """ROS-axis (UTC) ns of GPS seconds, whole seconds kept exact; one leap-second count for the
    whole array (that of its first time: recordings do not span a leap second here)."""
    from ins_gnss_ros.gnss.time import gps_to_utc, leap_seconds

    t_gps = np.asarray(t_gps, float)
    whole = np.floor(t_gps)
    first = float(np.ravel(t_gps)[0])
    leap = leap_seconds(gps_to_utc(first, leap_seconds(gps_to_utc(first, 0))))
    return bag.sec_to_ns(t_gps - whole) + (whole.astype(np.int64) + GPS_TO_ROS_S - leap) \
        * 1_000_000_000


# ---------------------------------------------------------------------------------------------
# Car drive (rtklibexplorer GNSS_IMU drive_0708)
# ---------------------------------------------------------------------------------------------
def car_mounting_rpy_deg():
    """(roll, pitch, yaw) deg of the IMU in base_link: v_base = Rz(yaw) Ry(pitch) Rx(roll) v_imu,
    the value of the imu_preprocessor's ``mounting_rpy_deg`` for the car bag."""
    from ins_gnss_ros.nav.rotations import dcm_to_quat, quat_to_euler
    from ins_gnss_ros.trial.car_drive import imu_to_body_dcm

    return tuple(float(np.degrees(a)) for a in quat_to_euler(dcm_to_quat(imu_to_body_dcm())))


def import_rtklib_drive(folder, out):
    """Convert the car trial folder (imu_1934.csv, .tag, gnss_1934_sf.pos) into a bag."""
    from sensor_msgs.msg import NavSatStatus

    from ins_gnss_ros.trial.car_drive import load_car_drive
    from ins_gnss_ros.trial.rtklib import Q_FIX, Q_FLOAT

    folder = Path(folder)
    drive = load_car_drive(folder)
    writer = bag.BagWriter(out)
    _write_imu_log(writer, folder / "imu_1934.csv")
    gnss = drive.gnss
    t_gnss = gps_to_ns(gnss.time)
    for i, t in enumerate(t_gnss):
        cov = np.diagonal(gnss.pos_cov_enu[i]) if gnss.pos_cov_enu is not None else [np.nan] * 3
        fix = msgs.fix_msg(t, gnss.lat[i], gnss.lon[i], gnss.height[i], cov)
        fix.status.status = (NavSatStatus.STATUS_GBAS_FIX if gnss.quality[i] in (Q_FIX, Q_FLOAT)
                             else NavSatStatus.STATUS_FIX)
        writer.write("gnss/fix", fix)
        if gnss.vel_enu is not None:
            vcov = (np.diagonal(gnss.vel_cov_enu[i]) if gnss.vel_cov_enu is not None
                    else [np.nan] * 3)
            writer.write("gnss/vel", msgs.twist_msg(t, gnss.vel_enu[i], vcov, "gnss"))
    truth = drive.truth
    for i, t in enumerate(gps_to_ns(truth.time)):
        writer.write("truth/state", msgs.ins_state_msg(
            t, truth.lat[i], truth.lon[i], truth.height[i],
            None if truth.vel_enu is None else truth.vel_enu[i], None))
    return writer.close()


def _write_imu_log(writer, csv_path):
    """``imu/data_raw`` from an rtklibexplorer IMU log (``.csv`` + ``.csv.tag``): the sensor's
    own axes and SI units (frame ``imu_link``: the mounting is the imu_preprocessor's
    ``mounting_rpy_deg``), stamped by the tag file's mapping with no clock offset applied (it is
    the imu_preprocessor's ``time_offset_s``)."""
    from ins_gnss_ros.trial.car_drive import STANDARD_GRAVITY, imu_times, read_imu_csv
    from ins_gnss_ros.trial.rtklib import read_time_tag

    csv_path = Path(csv_path)
    values, tick_ms = read_imu_csv(csv_path)
    t_imu = gps_to_ns(imu_times(tick_ms, read_time_tag(csv_path.with_name(csv_path.name + ".tag"))))
    accel = STANDARD_GRAVITY * values[:, :3]
    gyro = np.radians(values[:, 3:])
    writer.write_all("imu/data_raw", (msgs.imu_msg(t, w, f)
                                      for t, w, f in zip(t_imu, gyro, accel)))


# ---------------------------------------------------------------------------------------------
# u-blox stream (rtklibexplorer GNSS_IMU walk_0827)
# ---------------------------------------------------------------------------------------------
def import_ubx(path, out, truth_pos=None, geoid_separation=0.0, imu_csv=None, truth_float=False):
    """Convert a recorded u-blox byte stream (and optionally an RTKLIB .pos as truth, its heights
    made ellipsoidal with ``geoid_separation``, see :func:`~ins_gnss_ros.trial.rtklib.read_pos`:
    its RTK-fixed epochs, with ``truth_float`` its RTK-float ones too; and the IMU log
    ``imu_csv`` recorded with it, see :func:`_write_imu_log`).

    The stream goes through the ``gnss_driver`` node itself (file source as fast as possible,
    on an in-process bus): the bag holds exactly what the driver publishes live.
    """
    import rclpy
    from rclpy.parameter import Parameter

    from ins_gnss_ros.nodes.base import InProcessBus
    from ins_gnss_ros.nodes.gnss_driver_node import GnssDriverNode

    writer = bag.BagWriter(out)
    bus = InProcessBus()
    bus.recorders.append(lambda topic, msg: topic != "/diagnostics" and writer.write(topic, msg))
    context = rclpy.Context()
    rclpy.init(context=context)
    try:
        source = f"file://{Path(path).resolve()}?pace=fast"
        node = GnssDriverNode(context=context, bus=bus,
                              parameter_overrides=[Parameter("source", value=source)])
        while not node.source.finished:
            node.poll()
            bus.drain()
        node.destroy_node()
    finally:
        rclpy.shutdown(context=context)
    if truth_pos is not None:
        _write_pos_truth(writer, truth_pos, geoid_separation, truth_float)
    if imu_csv is not None:
        _write_imu_log(writer, imu_csv)
    return writer.close()


def _write_pos_truth(writer, pos_path, geoid_separation, with_float=False):
    from ins_gnss_ros.trial.rtklib import Q_FIX, Q_FLOAT, read_pos

    pos = read_pos(pos_path, geoid_separation)
    fixed = pos.select(np.isin(pos.quality, (Q_FIX, Q_FLOAT) if with_float else (Q_FIX,)))
    for i, t in enumerate(gps_to_ns(fixed.time)):
        writer.write("truth/state", msgs.ins_state_msg(
            t, fixed.lat[i], fixed.lon[i], fixed.height[i],
            None if fixed.vel_enu is None else fixed.vel_enu[i], None))


# ---------------------------------------------------------------------------------------------
# Vessel in waves (smsfusion test data)
# ---------------------------------------------------------------------------------------------
#: Compass noise of the source (0.1 deg white), as the Heading variance, rad^2.
COMPASS_VARIANCE = np.radians(0.1) ** 2
#: GNSS position noise of the source (5 cm white per axis), m.
VESSEL_GNSS_SIGMA = 0.05


def import_vessel_parquet(path, out):
    """Convert ``ains_ahrs_imu.parquet`` into a bag."""
    from ins_gnss_ros.trial.simulate import SIM_EPOCH_NS
    from ins_gnss_ros.trial.vessel import load_vessel

    vessel = load_vessel(path)
    t_ns = bag.sec_to_ns(vessel.time, SIM_EPOCH_NS)
    writer = bag.BagWriter(out)
    writer.write_all("imu/data_raw", (msgs.imu_msg(t, w, f, frame_id="base_link")
                                      for t, w, f in zip(t_ns, vessel.gyro_flu, vessel.accel_flu)))
    g, tr = vessel.gnss, vessel.truth
    var = [VESSEL_GNSS_SIGMA ** 2] * 3
    for i, t in enumerate(t_ns):
        writer.write("gnss/fix", msgs.fix_msg(t, g.lat[i], g.lon[i], g.height[i], var))
        writer.write("gnss/heading", msgs.heading_msg(t, azimuth=vessel.compass_azimuth[i],
                                                     azimuth_variance=COMPASS_VARIANCE))
        writer.write("truth/state", msgs.ins_state_msg(
            t, tr.lat[i], tr.lon[i], tr.height[i], tr.vel_enu[i], tr.q_nb[i],
            vessel.gyro_flu_true[i], vessel.accel_flu_true[i]))
        writer.write("truth/heading", msgs.heading_msg(t, tr.q_nb[i]))
    return writer.close()


#: ``trial import KIND``: importer and a one-line description.
IMPORTERS = {
    "rtklib-drive": (import_rtklib_drive,
                     "car trial folder: imu_1934.csv(.tag) + gnss_1934_sf.pos"),
    "ubx": (import_ubx, "u-blox byte stream (.ubx), optional --truth-pos RTKLIB .pos and "
                        "--imu-csv IMU log (.csv + .csv.tag)"),
    "vessel-parquet": (import_vessel_parquet, "smsfusion ains_ahrs_imu.parquet"),
}
