"""The ekf node's services (robot_localization's reset, set_pose, set_datum, to_ll, from_ll)
in-process on the bus and over DDS from another process; nav/datum latched.

Truth: pymap3d's ENU <-> geodetic conversion, and a pose that a standing vehicle keeps.
"""
from __future__ import annotations

import math

import numpy as np
import pymap3d
import pytest
from geometry_msgs.msg import PoseWithCovarianceStamped
from ins_gnss_msgs.msg import ImuDelta
from ins_gnss_msgs.srv import FromLL, SetDatum, SetPose, ToLL
from std_srvs.srv import Empty

from conftest import REPO
from ins_gnss_ros.io import sec_to_stamp
from ins_gnss_ros.nav.earth import earth_rate_enu, normal_gravity
from ins_gnss_ros.nav.rotations import quat_from_euler, quat_to_dcm
from ins_gnss_ros.nodes.base import LATCHED_QOS, InProcessBus
from ins_gnss_ros.nodes.convert import to_quaternion, to_vector3
from rosutil import NodeProcess, spin_until

DATUM = (59.93, 30.31, 12.0)  # deg, deg, m
T0 = 1.7e9


def _pose(x, y, z, yaw, t=T0):
    req = SetPose.Request()
    req.pose = PoseWithCovarianceStamped()
    req.pose.header.stamp, req.pose.header.frame_id = sec_to_stamp(t), "map"
    p = req.pose.pose.pose.position
    p.x, p.y, p.z = x, y, z
    req.pose.pose.pose.orientation = to_quaternion(quat_from_euler(0.0, 0.0, yaw))
    req.pose.pose.covariance = np.diag([0.01, 0.01, 0.04, 1e-4, 1e-4, 1e-3]).flatten().tolist()
    return req


def _standing_increments(yaw, n, dt=0.01):
    """Increments of a level IMU standing at the datum with heading yaw (ENU): gravity up and
    the Earth rate."""
    lat = math.radians(DATUM[0])
    c_bn = quat_to_dcm(quat_from_euler(0.0, 0.0, yaw)).T
    dtheta = c_bn @ earth_rate_enu(lat) * dt
    dv = np.array([0.0, 0.0, normal_gravity(lat, DATUM[2])]) * dt
    for k in range(1, n + 1):
        msg = ImuDelta(dt=dt)
        msg.header.stamp = sec_to_stamp(T0 + k * dt)
        msg.delta_angle, msg.delta_velocity = to_vector3(dtheta), to_vector3(dv)
        yield msg


def test_services_in_process(ros_context):
    from ins_gnss_ros.nodes.ekf_node import EkfNode
    from ins_gnss_ros.nodes.strapdown_node import StrapdownNode

    bus = InProcessBus()
    strapdown = StrapdownNode(context=ros_context, bus=bus)
    ekf = EkfNode(context=ros_context, bus=bus)
    out = {"/nav/datum": [], "/nav/odom": [], "/tf": []}
    for topic, seen in out.items():
        bus.subscribe(topic, seen.append)
    try:
        # no datum yet: conversions and set_pose say so
        assert not bus.call("/ekf/to_ll", ToLL.Request()).success
        assert not bus.call("/ekf/set_pose", _pose(1.0, 2.0, 0.0, 0.0)).success
        bad = bus.call("/ekf/set_datum", SetDatum.Request(latitude=95.0))
        assert not bad.success and "latitude" in bad.message
        ok = bus.call("/ekf/set_datum", SetDatum.Request(latitude=DATUM[0], longitude=DATUM[1],
                                                        altitude=DATUM[2]))
        assert ok.success
        (datum,) = out["/nav/datum"]
        assert (datum.latitude, datum.longitude, datum.altitude) == pytest.approx(DATUM)
        assert datum.header.frame_id == "map"

        ll = bus.call("/ekf/to_ll", ToLL.Request(map_point=to_point(100.0, -200.0, 5.0)))
        expected = pymap3d.enu2geodetic(100.0, -200.0, 5.0, *DATUM)
        assert ll.success
        assert (ll.latitude, ll.longitude, ll.altitude) == pytest.approx(expected, abs=1e-9)
        back = bus.call("/ekf/from_ll", FromLL.Request(latitude=ll.latitude,
                                                       longitude=ll.longitude,
                                                       altitude=ll.altitude))
        p = back.map_point
        assert back.success and (p.x, p.y, p.z) == pytest.approx((100.0, -200.0, 5.0), abs=1e-6)

        # set_pose: navigating at once from the pose, nav/odom and /tf on it while standing
        yaw = math.radians(30.0)
        assert bus.call("/ekf/set_pose", _pose(10.0, 20.0, 1.0, yaw)).success
        assert ekf.navigator.mode == "NAVIGATING"
        for msg in _standing_increments(yaw, 150):
            bus.publish("imu/delta", msg)
            bus.drain()
        assert out["/nav/odom"] and out["/tf"]
        last = out["/nav/odom"][-1].pose.pose
        assert (last.position.x, last.position.y, last.position.z) == pytest.approx(
            (10.0, 20.0, 1.0), abs=0.05)
        tf = out["/tf"][-1].transforms[0]
        assert (tf.header.frame_id, tf.child_frame_id) == ("map", "base_link")
        assert tf.transform.translation.x == pytest.approx(last.position.x)

        bus.call("/ekf/reset", Empty.Request())
        assert ekf.navigator.mode == "ALIGNING" and not ekf.navigator.started
    finally:
        ekf.destroy_node()
        strapdown.destroy_node()


def to_point(x, y, z):
    from geometry_msgs.msg import Point

    return Point(x=x, y=y, z=z)


def test_services_over_dds(probe, executor):
    """Each service called from this process on an ekf process; nav/datum reaches a late
    subscriber (latched)."""
    clients = {name: probe.create_client(srv, f"/ekf/{name}") for name, srv in (
        ("set_datum", SetDatum), ("to_ll", ToLL), ("from_ll", FromLL), ("set_pose", SetPose),
        ("reset", Empty))}

    def call(name, request):
        future = clients[name].call_async(request)
        spin_until(executor, future.done, 10.0, f"~/{name} answered")
        return future.result()

    with NodeProcess("ekf", params_file=REPO / "config" / "default.yaml") as proc:
        proc.wait_on_graph(probe, executor)
        spin_until(executor, lambda: all(c.service_is_ready() for c in clients.values()),
                   20.0, "the ekf's services")
        assert call("set_datum", SetDatum.Request(latitude=DATUM[0], longitude=DATUM[1],
                                                  altitude=DATUM[2])).success
        ll = call("to_ll", ToLL.Request(map_point=to_point(100.0, -200.0, 5.0)))
        assert (ll.latitude, ll.longitude, ll.altitude) == pytest.approx(
            pymap3d.enu2geodetic(100.0, -200.0, 5.0, *DATUM), abs=1e-9)
        p = call("from_ll", FromLL.Request(latitude=ll.latitude, longitude=ll.longitude,
                                           altitude=ll.altitude)).map_point
        assert (p.x, p.y, p.z) == pytest.approx((100.0, -200.0, 5.0), abs=1e-6)
        assert call("set_pose", _pose(10.0, 20.0, 1.0, 0.5)).success
        assert isinstance(call("reset", Empty.Request()), Empty.Response)

        from sensor_msgs.msg import NavSatFix
        datums = []
        probe.create_subscription(NavSatFix, "/nav/datum", datums.append, LATCHED_QOS)
        spin_until(executor, lambda: datums, 10.0, "the latched nav/datum")
        assert (datums[0].latitude, datums[0].longitude) == pytest.approx(DATUM[:2])
