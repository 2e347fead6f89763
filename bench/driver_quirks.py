"""Rewrite a bag as a driver with a quirk would have recorded it, for replaying unseen-recording
cases that the fault injector (``trial replay --faults``) does not make.

Quirks:

* ``imu_stamps_unset``: every ``imu/data_raw`` and ``imu/mag_raw`` header stamp 0 (a driver
  that fills none);
* ``gnss_stamps_unset``: the same for every ``gnss/*`` message;
* ``imu_frd``: ``imu/data_raw`` in FRD axes (y and z of the rates and specific force negated:
  a driver that keeps the sensor's NED-convention axes);
* ``imu_reversed``: ``imu/data_raw`` in the axes of an IMU mounted backwards (yawed 180 deg:
  x and y negated) with nothing in the recording to say so;
* ``gnss_vel_twist``: ``gnss/vel`` as a ``geometry_msgs/TwistStamped`` (nmea_navsat_driver's
  ``vel``: no covariance);
* ``imu_mounted_tf``: ``imu/data_raw`` in the axes of an IMU mounted rolled 180 deg and yawed
  90 deg in base_link (``MOUNTING_RPY_DEG``: z down, x to the left), and the installation on
  ``/tf_static`` as a URDF gives it (REP-145): base_link -> imu_link (that rotation) and
  base_link -> gnss (the simulated antenna's place);
* ``installation_tf``: the data as simulated (the IMU in base_link's axes) with that
  installation on ``/tf_static`` (imu_link unrotated): a recording whose URDF gives the
  antenna's place;
* ``imu_orientation_ned``: the IMU's own orientation (``trial simulate --imu-orientation``)
  published as the sensor's NED/FRD one, the rates and specific force left in FLU (a driver
  that converts the measurements to REP-145 but not the orientation);
* ``imu_yaw_relative``: that orientation's yaw relative to the first sample's, its covariance
  still small (a 6-axis unit's yaw, or a driver's, that REP-145 would mark unknown).

The log times stay as they were (the messages' arrival). A NaN altitude (a 2-D fix) is a fault:
``{kind: nan, topic: /gnss/fix, field: altitude}``.

Usage::

    .venv/bin/python bench/driver_quirks.py SIM OUT imu_stamps_unset
    .venv/bin/python -m ins_gnss_ros.trial.cli replay OUT --config config/default.yaml --out RUN

(docs/results/product_path.md, "2026-12-05 (session 24)")
"""
from __future__ import annotations

import argparse

import numpy as np

from ins_gnss_ros import io
from ins_gnss_ros.nav.rotations import dcm_from_euler, dcm_to_quat, quat_to_dcm

QUIRKS = ("imu_stamps_unset", "gnss_stamps_unset", "imu_frd", "imu_reversed", "gnss_vel_twist",
          "imu_mounted_tf", "installation_tf", "imu_orientation_ned", "imu_yaw_relative")
#: The IMU's mounting of ``imu_mounted_tf``: roll, pitch, yaw in base_link, deg.
MOUNTING_RPY_DEG = (180.0, 0.0, 90.0)
#: The quirks that add an installation on /tf_static: quirk -> the IMU's mounting there, deg.
TF_QUIRKS = {"imu_mounted_tf": MOUNTING_RPY_DEG, "installation_tf": (0.0, 0.0, 0.0)}
#: ENU -> NED and FLU -> FRD, as rotation matrices.
ENU_TO_NED = np.array([[0.0, 1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, -1.0]])
FLU_TO_FRD = np.diag([1.0, -1.0, -1.0])


def rewrite(msg, topic: str, quirk: str, first: dict):
    """One decoded message of ``topic`` (absolute name) with ``quirk`` applied (in place, or
    a message of another type); ``first`` keeps what a quirk needs of the first messages."""
    if quirk == "gnss_vel_twist" and topic == "/gnss/vel":
        from geometry_msgs.msg import TwistStamped

        return TwistStamped(header=msg.header, twist=msg.twist.twist)
    if (quirk == "imu_stamps_unset" and topic in ("/imu/data_raw", "/imu/mag_raw")) or \
            (quirk == "gnss_stamps_unset" and topic.startswith("/gnss/")):
        msg.header.stamp.sec = msg.header.stamp.nanosec = 0
    elif quirk == "imu_frd" and topic == "/imu/data_raw":
        for v in (msg.angular_velocity, msg.linear_acceleration):
            v.y, v.z = -v.y, -v.z
    elif quirk == "imu_reversed" and topic == "/imu/data_raw":
        if msg.orientation_covariance[0] >= 0.0:
            raise ValueError("imu_reversed turns rates and specific force, not orientation")
        for v in (msg.angular_velocity, msg.linear_acceleration):
            v.x, v.y = -v.x, -v.y
    elif quirk == "imu_mounted_tf" and topic == "/imu/data_raw":
        if msg.orientation_covariance[0] >= 0.0:
            raise ValueError("imu_mounted_tf rotates rates and specific force, not orientation")
        c_sb = dcm_from_euler(*np.radians(MOUNTING_RPY_DEG)).T  # base_link -> the IMU's axes
        for v in (msg.angular_velocity, msg.linear_acceleration):
            v.x, v.y, v.z = (float(x) for x in c_sb @ [v.x, v.y, v.z])
    elif quirk in ("imu_orientation_ned", "imu_yaw_relative") and topic == "/imu/data_raw":
        if msg.orientation_covariance[0] < 0.0:
            raise ValueError(f"{quirk} needs the IMU's own orientation (--imu-orientation)")
        o = msg.orientation
        c_ns = quat_to_dcm(np.array([o.w, o.x, o.y, o.z]))
        if quirk == "imu_orientation_ned":
            c_ns = ENU_TO_NED @ c_ns @ FLU_TO_FRD
        else:
            yaw0 = first.setdefault("yaw", np.arctan2(c_ns[1, 0], c_ns[0, 0]))
            c_ns = dcm_from_euler(0.0, 0.0, -yaw0) @ c_ns
        o.w, o.x, o.y, o.z = (float(x) for x in dcm_to_quat(c_ns))
    return msg


def installation_tf(stamp, imu_frame: str, gnss_frame: str, mounting_rpy_deg):
    """The /tf_static of a URDF: base_link -> imu_frame (the mounting, deg) and base_link ->
    gnss_frame (the simulated antenna's lever arm)."""
    from ins_gnss_ros.nodes.tf_messages import static_tf
    from ins_gnss_ros.trial.simulate import SimOptions

    return static_tf(stamp, "base_link", [
        (imu_frame, (0.0, 0.0, 0.0), dcm_from_euler(*np.radians(mounting_rpy_deg))),
        (gnss_frame, SimOptions.antenna_lever_arm, np.eye(3))])


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("bag")
    parser.add_argument("out")
    parser.add_argument("quirk", choices=QUIRKS)
    args = parser.parse_args(argv)
    frames, first = {}, {}
    with io.BagWriter(args.out) as out:
        for m in io.iter_bag(args.bag):
            if args.quirk in TF_QUIRKS and m.topic in ("/imu/data_raw", "/gnss/fix") \
                    and m.topic not in frames:
                frames[m.topic] = m.msg.header.frame_id
                if len(frames) == 2:  # (logged with the first messages, as a recorder does)
                    out.write("/tf_static", installation_tf(m.msg.header.stamp,
                                                            frames["/imu/data_raw"],
                                                            frames["/gnss/fix"],
                                                            TF_QUIRKS[args.quirk]), m.t_ns)
            out.write(m.topic, rewrite(m.msg, m.topic, args.quirk, first), m.t_ns)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
