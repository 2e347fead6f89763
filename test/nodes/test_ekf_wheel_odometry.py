"""ekf node with wheel/odom on the in-process bus, against simulated truth.

A simulated car (MEMS IMU, 5 Hz GNSS withheld for the last 40 s, 20 Hz wheel odometry with a
1 % scale error and encoder counts) is fed to two ekf nodes, one with use_wheel_odometry: the
wheels must hold the position through the outage where the IMU alone drifts, and a wheel spin
injected in the outage must be refused by the gate.
"""
from __future__ import annotations

import numpy as np
import pytest
from rclpy.parameter import Parameter

from ins_gnss_ros.io import sec_to_ns
from ins_gnss_ros.nav.error_model import nav_error
from ins_gnss_ros.nav.sensor_errors import MEMS_ADIS16405
from ins_gnss_ros.nav.strapdown import NavState
from ins_gnss_ros.nodes.base import InProcessBus
from ins_gnss_ros.sim.imu_sim import ImuSpec, simulate_imu
from ins_gnss_ros.sim.scenarios import car
from ins_gnss_ros.sim.wheel_sim import WheelSpec, simulate_wheel
from ins_gnss_ros.trial import contract_messages as msgs

T0_NS = 1_750_000_000 * 10 ** 9
OUTAGE = (60.0, 100.0)
SLIP_RATIO = 0.3
WHEEL_LEVER = (0.0, 0.0, -0.4)


def _messages():
    """(t, topic, message) in time order, and the truth, the slip window and the outage."""
    traj = car(duration=OUTAGE[1], seed=3, rate=100.0, static=20.0).trajectory
    imu = simulate_imu(traj, ImuSpec(MEMS_ADIS16405, rate=100.0), seed=5)
    wheel = simulate_wheel(traj, WheelSpec(rate=20.0, scale_error=0.01, tick=0.02,
                                           lever_arm_b=np.array(WHEEL_LEVER)))
    # A spin of SLIP_RATIO for 1 s in the outage, where the car drives at over 5 m/s.
    moving = (wheel.t > OUTAGE[0] + 5.0) & (wheel.true_speed > 5.0)
    t_slip = wheel.t[np.argmax(moving)]
    slipping = (wheel.t >= t_slip) & (wheel.t < t_slip + 1.0)
    speed = np.where(slipping, (1.0 + SLIP_RATIO) * wheel.speed, wheel.speed)
    rng = np.random.default_rng(7)
    out = []
    for k in range(0, len(traj.t), 20):  # 5 Hz GNSS
        t = traj.t[k]
        if OUTAGE[0] <= t < OUTAGE[1]:
            continue
        d = rng.normal(0.0, 0.3, 3)
        lat = traj.lat[k] + d[1] / 6.37e6
        lon = traj.lon[k] + d[0] / (6.39e6 * np.cos(traj.lat[k]))
        out.append((t, "gnss/fix", msgs.fix_msg(T0_NS + sec_to_ns(t), lat, lon,
                                                 traj.h[k] + d[2], [0.09] * 3)))
        out.append((t, "gnss/vel", msgs.twist_msg(T0_NS + sec_to_ns(t), traj.v_enu[k]
                                                  + rng.normal(0.0, 0.05, 3), [0.0025] * 3,
                                                  "gnss")))
    for t, v in zip(wheel.t, speed):
        out.append((t, "wheel/odom", msgs.wheel_odom_msg(T0_NS + sec_to_ns(t), v,
                                                         [0.2 ** 2, 0.1 ** 2, 0.1 ** 2])))
    for t, a, v in zip(imu.t, imu.dtheta, imu.dv):
        out.append((t, "imu/delta", msgs.delta_msg(T0_NS + sec_to_ns(t), a, v, imu.dt)))
    out.sort(key=lambda x: x[0])  # stable: a reading before the increment of its time
    return out, traj, wheel.t[slipping]


@pytest.fixture(scope="module")
def runs():
    """The two nodes' last solutions and nav/status messages (one run for both tests)."""
    import rclpy

    from ins_gnss_ros.nodes.ekf_node import EkfNode

    ros_context = rclpy.Context()
    rclpy.init(context=ros_context)

    messages, traj, slip_t = _messages()
    common = [Parameter("imu_grade", value="mems_adis16405"),
              Parameter("bias_model", value="rw")]
    wheel = common + [Parameter("use_wheel_odometry", value=True),
                      Parameter("wheel.lever_arm", value=list(WHEEL_LEVER)),
                      Parameter("wheel.delay_s", value=0.025)]  # half the 20 Hz interval
    result = {}
    for name, params in (("wheel", wheel), ("imu", common)):
        bus = InProcessBus()
        node = EkfNode(context=ros_context, bus=bus, parameter_overrides=params)
        statuses = []
        bus.subscribe("nav/status", statuses.append)
        for _, topic, msg in messages:
            bus.publish(topic, msg)
            bus.drain()
        result[name] = (node.navigator.solution, statuses)
        node.destroy_node()
    rclpy.shutdown(context=ros_context)
    k = len(traj.t) - 1
    truth = NavState(traj.lat[k], traj.lon[k], traj.h[k], traj.v_enu[k], traj.q_nb[k], traj.t[k])
    return result, truth, slip_t


def test_wheel_odometry_holds_the_position_through_the_outage(runs):
    result, truth, _ = runs
    drift = {name: float(np.hypot(*nav_error(sol, truth)[0][:2]))
             for name, (sol, _) in result.items()}
    assert drift["wheel"] < 3.0, drift
    assert drift["imu"] > 5.0 * drift["wheel"], drift


def test_a_wheel_spin_is_refused_by_the_gate(runs):
    result, _, slip_t = runs
    updates = [u for status in result["wheel"][1] for u in status.updates if u.name == "wheel"]
    t = np.array([u.stamp.sec + u.stamp.nanosec * 1e-9 for u in updates]) - T0_NS * 1e-9
    accepted = np.array([u.accepted for u in updates])
    spinning = np.isin(np.round(t + 0.025, 6), np.round(slip_t, 6))
    # The first reading of the spin may pass (the gate needs the speed error beyond ~4 sigma).
    assert spinning.sum() >= 19 and (~accepted[spinning]).sum() >= spinning.sum() - 1
    assert {u.reason for u in np.array(updates)[spinning & ~accepted]} == {"gated"}
    assert (~accepted[~spinning]).mean() < 0.02  # elsewhere the wheels are believed
