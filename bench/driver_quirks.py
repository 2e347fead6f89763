"""Rewrite a bag as a driver with a quirk would have recorded it, for replaying unseen-recording
cases that the fault injector (``trial replay --faults``) does not make.

Quirks:

* ``imu_stamps_unset``: every ``imu/data_raw`` and ``imu/mag_raw`` header stamp 0 (a driver
  that fills none);
* ``gnss_stamps_unset``: the same for every ``gnss/*`` message;
* ``imu_frd``: ``imu/data_raw`` in FRD axes (y and z of the rates and specific force negated:
  a driver that keeps the sensor's NED-convention axes);
* ``gnss_vel_twist``: ``gnss/vel`` as a ``geometry_msgs/TwistStamped`` (nmea_navsat_driver's
  ``vel``: no covariance).

The log times stay as they were (the messages' arrival). A NaN altitude (a 2-D fix) is a fault:
``{kind: nan, topic: /gnss/fix, field: altitude}``.

Usage::

    .venv/bin/python bench/driver_quirks.py SIM OUT imu_stamps_unset
    .venv/bin/python -m ins_gnss_ros.trial.cli replay OUT --config config/default.yaml --out RUN

(docs/results/product_path.md, "2026-12-05 (session 24)")
"""
from __future__ import annotations

import argparse

from ins_gnss_ros import io

QUIRKS = ("imu_stamps_unset", "gnss_stamps_unset", "imu_frd", "gnss_vel_twist")


def rewrite(msg, topic: str, quirk: str):
    """One decoded message of ``topic`` (absolute name) with ``quirk`` applied (in place, or
    a message of another type)."""
    if quirk == "gnss_vel_twist" and topic == "/gnss/vel":
        from geometry_msgs.msg import TwistStamped

        return TwistStamped(header=msg.header, twist=msg.twist.twist)
    if (quirk == "imu_stamps_unset" and topic in ("/imu/data_raw", "/imu/mag_raw")) or \
            (quirk == "gnss_stamps_unset" and topic.startswith("/gnss/")):
        msg.header.stamp.sec = msg.header.stamp.nanosec = 0
    elif quirk == "imu_frd" and topic == "/imu/data_raw":
        for v in (msg.angular_velocity, msg.linear_acceleration):
            v.y, v.z = -v.y, -v.z
    return msg


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("bag")
    parser.add_argument("out")
    parser.add_argument("quirk", choices=QUIRKS)
    args = parser.parse_args(argv)
    with io.BagWriter(args.out) as out:
        for m in io.iter_bag(args.bag):
            out.write(m.topic, rewrite(m.msg, m.topic, args.quirk), m.t_ns)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
