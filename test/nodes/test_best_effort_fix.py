"""A receiver driver publishing gnss/fix best effort (REP-2003 SensorDataQoS, as ublox_dgnss
does) feeds every node that uses the fix: ekf, mag_compass, phase_heading (on DDS)."""
from __future__ import annotations

from rclpy.qos import qos_profile_sensor_data
from sensor_msgs.msg import NavSatFix, NavSatStatus

from ins_gnss_ros.io import sec_to_stamp
from rosutil import spin_until


def test_best_effort_fix_reaches_every_user(ros_context, executor, probe):
    from ins_gnss_ros.nodes.ekf_node import EkfNode
    from ins_gnss_ros.nodes.mag_compass_node import MagCompassNode
    from ins_gnss_ros.nodes.phase_heading_node import PhaseHeadingNode

    ekf, compass, phase = (cls(context=ros_context)
                           for cls in (EkfNode, MagCompassNode, PhaseHeadingNode))
    for node in (ekf, compass, phase):
        executor.add_node(node)
    pub = probe.create_publisher(NavSatFix, "gnss/fix", qos_profile_sensor_data)
    spin_until(executor, lambda: pub.get_subscription_count() == 3, 10.0,
               "three subscriptions matched with the best-effort publisher")
    fix = NavSatFix(latitude=59.93, longitude=30.31, altitude=12.0)
    fix.header.stamp = sec_to_stamp(1.7e9)
    fix.status.status = NavSatStatus.STATUS_FIX
    pub.publish(fix)
    spin_until(executor, lambda: "gnss/fix" in ekf.aiding.inputs
               and compass.front.fix_seen and phase.pipeline.position is not None,
               10.0, "the fix at every node")
