"""gnss_simulator node: in-process on the InProcessBus (truth input and internal scenario) against
known truth, bad input counted not fatal, and one pub/sub round over ROS."""

from __future__ import annotations

import datetime as dt
import math

import numpy as np
import pymap3d
import pytest
from rclpy.parameter import Parameter

from ins_gnss_ros.io import sec_to_stamp, stamp_to_sec
from ins_gnss_ros.nav.lever_arm import lever_arm_position
from ins_gnss_ros.nav.rotations import quat_from_euler
from ins_gnss_ros.nodes.convert import to_quaternion, to_vector3

LAT, LON, H = math.radians(59.9), math.radians(30.3), 22.0
Q_NB = quat_from_euler(0.0, 0.0, 1.0)
START_GPS = 1440433800.0       # GPS seconds: 2025-08-28 16:29:42 UTC (GPST - UTC = 18 s)
C = 299792458.0


def _truth(t, lat=LAT):
    from ins_gnss_msgs.msg import InsState

    msg = InsState(latitude=lat, longitude=LON, altitude=H)
    msg.header.stamp = sec_to_stamp(t)
    msg.velocity = to_vector3(np.zeros(3))
    msg.orientation = to_quaternion(Q_NB)
    msg.angular_velocity = to_vector3(np.zeros(3))
    return msg


def _node(ros_context, bus, **params):
    from ins_gnss_ros.nodes.gnss_simulator_node import GnssSimulatorNode

    base = {"start_gps_time_s": START_GPS, "half_cycle_resolve_s": 1.0, "seed": 3}
    overrides = [Parameter(k, value=v) for k, v in {**base, **params}.items()]
    return GnssSimulatorNode(context=ros_context, bus=bus, parameter_overrides=overrides)


@pytest.fixture
def bus_run(ros_context):
    """3 s of static truth at 20 Hz through a node on the in-process bus; outputs by topic."""
    from ins_gnss_ros.nodes.base import InProcessBus

    bus = InProcessBus()
    out: dict = {}
    bus.recorders.append(lambda topic, msg: out.setdefault(topic, []).append(msg))
    node = _node(ros_context, bus)
    for k in range(61):
        bus.publish("sim/truth", _truth(1000.0 + 0.05 * k))
        bus.drain()
    yield node, out
    node.destroy_node()


def test_observations_per_antenna_at_the_epoch_rate(bus_run):
    node, out = bus_run
    obs = out["/gnss/observations"]
    assert len(obs) == 2 * 16                      # 5 Hz over 3 s, two antennas
    assert [m.antenna_id for m in obs[:4]] == [0, 1, 0, 1]
    stamps = sorted({stamp_to_sec(m.header.stamp) for m in obs})
    assert stamps == pytest.approx(1000.0 + 0.2 * np.arange(16))
    for a, b in zip(obs[0::2], obs[1::2]):
        assert a.header.stamp == b.header.stamp and len(a.prn) >= 8
        assert set(a.system) == {0, 2}             # u-blox gnssId: GPS and Galileo
        # The receiver's time tag: true GNSS time + its clock offset (< 1 ms for a TCXO here).
        t_true = START_GPS + stamp_to_sec(a.header.stamp) - 1000.0
        assert a.gps_week == 2381
        assert abs(a.gps_week * 604800.0 + a.time_of_week - t_true) < 1e-3
        # 1.5 m baseline: code ranges differ by the baseline projection plus noise.
        assert np.max(np.abs(np.subtract(a.pseudorange, b.pseudorange))) < 15.0
    # Half-cycle ambiguity of GPS L1 C/A (data channel): phase NaN for the first second, then
    # valid and flagged once; Galileo E1-C (pilot) has none: valid from the first epoch.
    gps = [i for i, s in enumerate(obs[0].system) if s == 0]
    gal = [i for i, s in enumerate(obs[0].system) if s == 2]
    assert all(math.isfinite(obs[0].carrier_phase[i]) for i in gal)
    first_valid = next(i for i, m in enumerate(obs) if not math.isnan(m.carrier_phase[gps[0]]))
    assert stamp_to_sec(obs[first_valid].header.stamp) == pytest.approx(1001.0)
    assert all(math.isfinite(obs[first_valid].carrier_phase[i]) for i in gps)
    assert all(obs[first_valid].loss_of_lock[i] for i in gps)
    assert not any(obs[first_valid].loss_of_lock[i] for i in gal)
    assert not any(obs[first_valid + 2].loss_of_lock)
    assert sum(node.diag.counts.values()) == 0


def test_truth_stamps_a_little_off_the_epoch_grid_still_give_every_epoch(ros_context):
    from builtin_interfaces.msg import Time

    from ins_gnss_ros.nodes.base import InProcessBus

    bus = InProcessBus()
    obs = []
    bus.subscribe("gnss/observations", obs.append)
    node = _node(ros_context, bus, lever_arms=[0.0, 0.0, 1.0])
    # Truth at the 5 Hz epoch rate, stamps rounded a few ns either side of the grid (as float
    # seconds give them); one sample 2 ms early is not an epoch, the grid point after it is.
    offsets_ns = [0, 200_000_000 - 3, 400_000_000 + 3, 598_000_000, 600_000_000,
                  800_000_000 - 250]
    for off in offsets_ns:
        msg = _truth(1000.0)
        msg.header.stamp = Time(sec=1000, nanosec=off)
        bus.publish("sim/truth", msg)
    bus.drain()
    stamps = [m.header.stamp.nanosec for m in obs]
    assert stamps == [0, 200_000_000 - 3, 400_000_000 + 3, 600_000_000, 800_000_000 - 250]
    node.destroy_node()


def test_fix_velocity_ephemeris_and_time_reference_against_truth(bus_run):
    _, out = bus_run
    fixes = out["/gnss/fix"]
    assert len(fixes) == 16
    lat, lon, h = lever_arm_position(LAT, LON, H, Q_NB, np.array([0.75, 0.0, 1.0]))
    for fix in fixes:
        e, n, u = pymap3d.geodetic2enu(fix.latitude, fix.longitude, fix.altitude,
                                       math.degrees(lat), math.degrees(lon), h)
        cov = np.reshape(fix.position_covariance, (3, 3))
        assert math.hypot(e, n) < 4.0 * math.sqrt(cov[0, 0] + cov[1, 1])
        assert abs(u) < 4.0 * math.sqrt(cov[2, 2])
    for vel in out["/gnss/vel"]:
        v = vel.twist.twist.linear
        sigma = np.sqrt(np.diag(np.reshape(vel.twist.covariance, (6, 6)))[:3])
        assert np.all(np.abs([v.x, v.y, v.z]) < 5 * sigma + 0.01)
    ephs = out["/gnss/ephemeris"]
    assert len(ephs) == 10 and {m.system for m in ephs} == {0, 2}
    for m in ephs:
        assert m.week == (2381 if m.system == 0 else 2381 - 1024)   # GST week = GPS week - 1024
        assert 5150.0 < m.sqrt_a < 5160.0 if m.system == 0 else 5435.0 < m.sqrt_a < 5445.0
    times = out["/gnss/time_reference"]
    assert len(times) == 4                       # whole GPS seconds 0, 1, 2, 3
    for m in times:
        utc = dt.datetime(2025, 8, 28, 16, 29, 42) + dt.timedelta(
            seconds=stamp_to_sec(m.header.stamp) - 1000.0)
        posix = (utc - dt.datetime(1970, 1, 1)).total_seconds()
        assert stamp_to_sec(m.time_ref) == pytest.approx(posix, abs=1e-6)
        assert m.source == "gps"


def test_bad_truth_is_counted_and_the_node_keeps_running(ros_context):
    from ins_gnss_ros.nodes.base import InProcessBus

    bus = InProcessBus()
    obs = []
    bus.subscribe("gnss/observations", obs.append)
    node = _node(ros_context, bus, lever_arms=[0.0, 0.0, 1.0])
    bus.publish("sim/truth", _truth(10.0))
    bus.publish("sim/truth", _truth(10.2, lat=float("nan")))
    zero_q = _truth(10.2)
    zero_q.orientation = to_quaternion(np.zeros(4))
    bus.publish("sim/truth", zero_q)
    bus.publish("sim/truth", _truth(9.0))            # backwards
    bus.publish("sim/truth", _truth(10.2))
    bus.drain()
    assert node.diag.counts["non-finite or invalid truth dropped"] == 2
    assert node.diag.counts["truth stamp not after the previous one: dropped"] == 1
    assert len(obs) == 2 and all(m.antenna_id == 0 for m in obs)
    node.destroy_node()


def test_bad_lever_arms_are_one_clear_error(ros_context):
    from ins_gnss_ros.nodes.base import InProcessBus, ParameterError

    with pytest.raises(ParameterError, match="lever_arms"):
        _node(ros_context, InProcessBus(), lever_arms=[0.0, 0.0, 1.0, 1.0])


def test_shading_limits_satellites_and_leaves_no_fix(ros_context):
    from ins_gnss_ros.nodes.base import InProcessBus

    bus = InProcessBus()
    out: dict = {}
    bus.recorders.append(lambda topic, msg: out.setdefault(topic, []).append(msg))
    node = _node(ros_context, bus, **{"shading.enabled": True, "shading.first_s": 1.0,
                                      "shading.length_s": 2.0, "shading.counts": [3],
                                      "lever_arms": [0.0, 0.0, 1.0]})
    for k in range(16):
        bus.publish("sim/truth", _truth(50.0 + 0.2 * k))
    bus.drain()
    counts = {round(stamp_to_sec(m.header.stamp) - 50.0, 1): len(m.prn)
              for m in out["/gnss/observations"]}
    assert all(n == 3 for t, n in counts.items() if 1.0 <= t < 3.0)
    assert all(n >= 8 for t, n in counts.items() if t < 1.0 or t >= 3.0)
    assert node.diag.counts["no fix: fewer satellites than unknowns"] == 10
    assert len(out["/gnss/fix"]) == 6
    node.destroy_node()


def test_broadcast_residuals_move_the_ranges_by_metres(ros_context):
    """broadcast_residuals: the same seed's pseudoranges, with a truth apart from the broadcast
    models (ionosphere 2x Klobuchar, zenith troposphere, 1 m SISRE), differ by metres."""
    from ins_gnss_ros.nodes.base import InProcessBus

    ranges = {}
    for residuals in (False, True):
        bus = InProcessBus()
        out = []
        bus.subscribe("gnss/observations", out.append)
        node = _node(ros_context, bus, broadcast_residuals=residuals,
                     **{"lever_arms": [0.0, 0.0, 1.0], "multipath.enabled": False})
        bus.publish("sim/truth", _truth(50.0))
        bus.drain()
        ranges[residuals] = np.array(out[0].pseudorange)
        node.destroy_node()
    change = np.abs(ranges[True] - ranges[False])
    assert np.all(change > 0.1) and np.median(change) > 1.0, change


def test_internal_scenario_follows_its_trajectory(ros_context):
    from ins_gnss_ros.nodes.base import InProcessBus

    bus = InProcessBus()
    out: dict = {}
    bus.recorders.append(lambda topic, msg: out.setdefault(topic, []).append(msg))
    node = _node(ros_context, bus, source="scenario", **{"scenario.duration_s": 20.0,
                                                         "lever_arms": [0.0, 0.0, 0.0]})
    for _ in range(10):
        assert node.step_scenario()
        bus.drain()
    traj = node.scenario_traj
    for k, fix in enumerate(out["/gnss/fix"]):
        # Stamps are GNSS time on the UTC axis: t = 0 is START_GPS - 18 s after 1980-01-06.
        posix = (dt.datetime(2025, 8, 28, 16, 29, 42)
                 - dt.datetime(1970, 1, 1)).total_seconds() + 0.2 * k
        assert stamp_to_sec(fix.header.stamp) == pytest.approx(posix, abs=1e-6)
        e, n, u = pymap3d.geodetic2enu(fix.latitude, fix.longitude, fix.altitude,
                                       math.degrees(traj.lat[2 * k]),
                                       math.degrees(traj.lon[2 * k]), traj.h[2 * k])
        assert math.hypot(e, n) < 10.0 and abs(u) < 20.0
    node.destroy_node()


def test_publishes_over_ros(executor, ros_context, probe):
    from ins_gnss_msgs.msg import GnssObservations, InsState

    from ins_gnss_ros.nodes.base import SENSOR_QOS
    from rosutil import spin_until

    node = _node(ros_context, None, lever_arms=[0.0, 0.0, 1.0])
    executor.add_node(node)
    got = []
    probe.create_subscription(GnssObservations, "gnss/observations", got.append, SENSOR_QOS)
    pub = probe.create_publisher(InsState, "sim/truth", SENSOR_QOS)
    spin_until(executor, lambda: pub.get_subscription_count() > 0, what="sim/truth subscription")
    for k in range(3):
        pub.publish(_truth(20.0 + 0.2 * k))
    spin_until(executor, lambda: len(got) == 3, what="3 gnss/observations")
    assert got[-1].header.stamp == sec_to_stamp(20.4)
