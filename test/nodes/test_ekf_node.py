"""ekf + strapdown nodes in closed loop on the in-process bus, against simulated truth.

A simulated car (MEMS IMU with turn-on biases, scale factors and noise; GNSS position and
velocity at 4 Hz) is fed to the two nodes as ImuDelta / NavSatFix / TwistWithCovarianceStamped
messages. The strapdown's ins/state must follow the truth to the GNSS accuracy (the closed loop
works across nodes), and must equal the offline Navigator run on the same data (the node runs the
same filter code).
"""

from __future__ import annotations

import numpy as np
import pytest
from geometry_msgs.msg import TwistWithCovarianceStamped
from diagnostic_msgs.msg import DiagnosticStatus
from ins_gnss_msgs.msg import FilterStatus, ImuDelta, InsCorrection, InsState
from rclpy.parameter import Parameter
from sensor_msgs.msg import NavSatFix, NavSatStatus

from ins_gnss_ros.io import sec_to_stamp, stamp_to_sec
from ins_gnss_ros.nav.error_model import nav_error
from ins_gnss_ros.nav.lever_arm import lever_arm_position, lever_arm_velocity
from ins_gnss_ros.nav import GnssFix, GnssVelocity, Navigator
from ins_gnss_ros.nav.sensor_errors import MEMS_ADIS16405
from ins_gnss_ros.nav.strapdown import NavState
from ins_gnss_ros.nodes.base import InProcessBus
from ins_gnss_ros.nodes.convert import nav_state_from_msg, to_vector3, vec
from ins_gnss_ros.sim.imu_sim import ImuSpec, simulate_imu
from ins_gnss_ros.sim.scenarios import car

LEVER = np.array([0.5, 0.2, 1.2])
T0 = 1_750_000_000.0  # a UTC epoch for the stamps
SIGMA_POS, SIGMA_VEL = 0.3, 0.05


@pytest.fixture(scope="module")
def trial():
    scen = car(duration=120.0, seed=3, rate=100.0, static=20.0)
    traj = scen.trajectory
    imu = simulate_imu(traj, ImuSpec(MEMS_ADIS16405, rate=100.0), seed=5)
    rng = np.random.default_rng(7)
    gnss = []
    for k in range(0, len(traj.t), 25):  # 4 Hz
        lat, lon, h = lever_arm_position(traj.lat[k], traj.lon[k], traj.h[k], traj.q_nb[k], LEVER)
        v = lever_arm_velocity(traj.v_enu[k], traj.q_nb[k], traj.omega_ib_b[k], LEVER, traj.lat[k])
        gnss.append((traj.t[k], float(lat), float(lon), float(h), v,
                     rng.normal(0.0, SIGMA_POS, 3), rng.normal(0.0, SIGMA_VEL, 3)))
    return traj, imu, gnss


def _fix_msg(t, lat, lon, h, noise):
    from ins_gnss_ros.nav.earth import radii

    rm, rn = radii(lat)
    msg = NavSatFix()
    msg.header.stamp = sec_to_stamp(T0 + t)
    msg.status.status = NavSatStatus.STATUS_FIX
    msg.latitude = np.degrees(lat + noise[1] / (rm + h))
    msg.longitude = np.degrees(lon + noise[0] / ((rn + h) * np.cos(lat)))
    msg.altitude = h + noise[2]
    msg.position_covariance = (np.eye(3) * SIGMA_POS ** 2).flatten().tolist()
    msg.position_covariance_type = NavSatFix.COVARIANCE_TYPE_DIAGONAL_KNOWN
    return msg


def _vel_msg(t, v, noise):
    msg = TwistWithCovarianceStamped()
    msg.header.stamp = sec_to_stamp(T0 + t)
    msg.twist.twist.linear = to_vector3(v + noise)
    cov = np.zeros((6, 6))
    cov[:3, :3] = np.eye(3) * SIGMA_VEL ** 2
    msg.twist.covariance = cov.flatten().tolist()
    return msg


def _ekf_params():
    return [Parameter("lever_arm", value=LEVER.tolist()),
            Parameter("layout", value="21"), Parameter("bias_model", value="rw"),
            Parameter("gnss.position_sigma_floor_m", value=0.0),
            Parameter("gnss.velocity_sigma_floor_mps", value=0.0)]


def _payload(msg) -> bytes:
    """An ImuDelta as the nodes take it: its CDR payload."""
    from ins_gnss_msgs.msg import ImuDelta

    from ins_gnss_ros.io import codec

    return codec(ImuDelta).encode(msg)


def test_closed_loop_follows_truth_and_equals_offline_navigator(trial, ros_context):
    from ins_gnss_ros.nodes.ekf_node import EkfNode
    from ins_gnss_ros.nodes.strapdown_node import StrapdownNode

    traj, imu, gnss = trial
    bus = InProcessBus()
    strapdown = StrapdownNode(context=ros_context, bus=bus)  # starts at its parameter defaults
    ekf = EkfNode(context=ros_context, bus=bus, parameter_overrides=_ekf_params())
    states: list[InsState] = []
    corrections: list[InsCorrection] = []
    statuses: list[FilterStatus] = []
    bus.subscribe("ins/state", states.append)
    bus.subscribe("ins/correction", corrections.append)
    bus.subscribe("nav/status", statuses.append)

    # the same messages, in the same order, through the offline navigator
    offline = Navigator(ekf.config)
    g = 0
    for k in range(len(imu.t)):
        t = imu.t[k]
        while g < len(gnss) and gnss[g][0] <= t:
            tg, lat, lon, h, v, npos, nvel = gnss[g]
            fix, vel = _fix_msg(tg, lat, lon, h, npos), _vel_msg(tg, v, nvel)
            for topic, msg in (("gnss/fix", fix), ("gnss/vel", vel)):
                bus.publish(topic, msg)
                bus.drain()
            offline.add_measurement(GnssFix(
                stamp_to_sec(fix.header.stamp), np.radians(fix.latitude),
                np.radians(fix.longitude), fix.altitude, np.eye(3) * SIGMA_POS ** 2))
            offline.add_measurement(GnssVelocity(stamp_to_sec(vel.header.stamp), vec(
                vel.twist.twist.linear), np.eye(3) * SIGMA_VEL ** 2))
            g += 1
        delta = ImuDelta(dt=float(imu.dt))
        delta.header.stamp = sec_to_stamp(T0 + t)
        delta.delta_angle, delta.delta_velocity = to_vector3(imu.dtheta[k]), to_vector3(imu.dv[k])
        bus.publish("imu/delta", delta)
        bus.drain()
        offline.add_imu(stamp_to_sec(delta.header.stamp), vec(delta.delta_angle),
                        vec(delta.delta_velocity))
    strapdown.destroy_node()
    ekf.destroy_node()

    assert corrections and statuses
    assert statuses[-1].mode == FilterStatus.MODE_NAVIGATING
    # The outputs agree about when the solution is aligned: nav/status says NAVIGATING from the
    # first ins/state that carries the alignment's correction, never over an unaligned one.
    t_nav = min(stamp_to_sec(m.header.stamp) for m in statuses
                if m.mode == FilterStatus.MODE_NAVIGATING)
    aligned = ekf.sync.aligned_sequence
    first = min(stamp_to_sec(m.header.stamp) for m in states if m.correction_sequence >= aligned)
    assert first <= t_nav < first + 0.05
    assert all(m.correction_sequence >= aligned for m in states
               if stamp_to_sec(m.header.stamp) >= t_nav)
    assert states[0].mode == InsState.MODE_ALIGNING  # the strapdown before its first correction
    # ins/state says the filter's mode: levelled at rest and corrected (zero-velocity fixes)
    # for 20 s, the filter is ALIGNING until the car moves; so is the strapdown until it applies
    # the alignment's correction, with nav/status.
    assert {m.mode for m in corrections if m.sequence < aligned} == {InsCorrection.MODE_ALIGNING}
    assert corrections[aligned - 1].mode == InsCorrection.MODE_NAVIGATING
    levelled = [m for m in states if 0 < m.correction_sequence < aligned]
    assert levelled and all(m.mode == InsState.MODE_ALIGNING for m in states
                            if m.correction_sequence < aligned)
    t_moving = traj.t[np.argmax(np.linalg.norm(traj.v_enu, axis=1) > 0.0)]
    assert stamp_to_sec(levelled[-1].header.stamp) - T0 > t_moving  # the whole static start
    assert min(stamp_to_sec(m.header.stamp) for m in states
               if m.mode == InsState.MODE_NAVIGATING) == first
    assert all(m.mode != InsState.MODE_ALIGNING for m in states
               if stamp_to_sec(m.header.stamp) >= first)
    # strapdown vs truth over the last 60 s (after alignment and convergence)
    errors = []
    for msg in states:
        st = nav_state_from_msg(msg)
        k = int(round((st.t - T0 - traj.t[0]) / traj.dt))
        if st.t - T0 < 60.0 or k >= len(traj.t):
            continue
        true = NavState(traj.lat[k], traj.lon[k], traj.h[k], traj.v_enu[k], traj.q_nb[k], st.t)
        errors.append(np.concatenate(nav_error(st, true)))
    errors = np.array(errors)
    horizontal = np.hypot(errors[:, 0], errors[:, 1])
    assert np.sqrt(np.mean(horizontal ** 2)) < 1.0
    assert np.abs(errors[:, 3:6]).max() < 0.3
    assert np.degrees(np.abs(errors[:, 6:8]).max()) < 0.5  # roll/pitch (tilt) errors
    assert np.degrees(np.abs(errors[:, 8]).max()) < 2.0    # MEMS heading, 1-2 min after start
    # the node's filter and the offline navigator are the same code on the same data
    node_final, off_final = ekf.navigator.solution, offline.solution
    assert node_final.t == off_final.t
    dp, dv, phi = nav_error(node_final, off_final)
    assert np.abs(dp).max() == 0.0 and np.abs(dv).max() == 0.0 and np.abs(phi).max() == 0.0


def test_bad_measurements_are_counted_not_used(ros_context):
    from ins_gnss_ros.nodes.ekf_node import EkfNode

    node = EkfNode(context=ros_context, bus=InProcessBus())
    nan_fix = _fix_msg(1.0, 1.0, 0.5, 10.0, np.zeros(3))
    nan_fix.latitude = float("nan")
    node.on_input("gnss/fix", node.inputs.fix, nan_fix)
    no_fix = _fix_msg(1.0, 1.0, 0.5, 10.0, np.zeros(3))
    no_fix.status.status = NavSatStatus.STATUS_NO_FIX
    node.on_input("gnss/fix", node.inputs.fix, no_fix)
    node.on_input("gnss/vel", node.inputs.velocity,
                  _vel_msg(1.0, np.array([np.inf, 0.0, 0.0]), np.zeros(3)))
    assert node.navigator.update_count == 0
    assert node.diag.counts["non-finite gnss/fix rejected"] == 1
    assert node.diag.counts["non-finite gnss/vel rejected"] == 1
    assert node.diag.counts["gnss/fix without a fix ignored"] == 1
    node.destroy_node()


def test_an_input_without_a_stamp_takes_its_arrival_time(ros_context):
    """A driver that fills no header stamp (0): its fixes were refused as stamped 1.75e9 s
    before the IMU; now each takes its arrival time, counted on /diagnostics."""
    from builtin_interfaces.msg import Time

    from ins_gnss_ros.io import stamp_to_ns
    from ins_gnss_ros.nodes.ekf_node import EkfNode

    bus = InProcessBus()
    bus.now_ns = int(T0 * 1e9) + 250_000_000
    node = EkfNode(context=ros_context, bus=bus)
    fix = _fix_msg(0.0, 1.0, 0.5, 10.0, np.zeros(3))
    fix.header.stamp = Time()
    node.on_input("gnss/fix", node.inputs.fix, fix)
    assert stamp_to_ns(fix.header.stamp) == bus.now_ns
    assert node.diag.counts["gnss/fix stamp unset (0): its arrival time used"] == 1
    # (and its latency is unknown: estimated from the start, as for stamps taken on arrival)
    assert "td" in node.navigator.space
    node.destroy_node()


@pytest.mark.parametrize("after_stamp_ms, on_arrival", [(0.5, True), (0.0, False), (60.0, False)])
def test_fixes_stamped_on_their_arrival_have_their_latency_estimated(ros_context, after_stamp_ms,
                                                                       on_arrival):
    """A fix arriving within the transport of its stamp was stamped on arrival, its latency
    unknown: the filter estimates it (nav/aiding.py, Aiding.arrival). One logged at its stamp
    (a recording written at its stamps) or its receiver's latency after it changes nothing."""
    from ins_gnss_ros.nodes.ekf_node import EkfNode

    bus = InProcessBus()
    bus.now_ns = int(T0 * 1e9) + round(after_stamp_ms * 1e6)
    node = EkfNode(context=ros_context, bus=bus)
    node.on_input("gnss/fix", node.inputs.fix, _fix_msg(0.0, 1.0, 0.5, 10.0, np.zeros(3)))
    assert ("td" in node.navigator.space) == on_arrival
    assert any(text.startswith("gnss/fix stamped on its arrival (0.5 ms before it)")
               for text in node.diag.counts) == on_arrival
    node.destroy_node()


@pytest.mark.parametrize("own_fix", [False, True], ids=["receiver_fix", "align_on_observations"])
def test_tight_coupling_with_three_satellites_through_the_nodes(ros_context, own_fix):
    """Raw GNSS from real orbits (the GNSS simulator): the ekf aligns on SPP fix + velocity, then
    with 3 satellites uses their pseudoranges and Dopplers. The strapdown's error stays at the
    metre level where free inertial navigation drifts away. With tight.align_on_observations
    the ekf forms that fix and velocity itself: the receiver's (here 50 m off, a reference in
    another datum) is no input."""
    from ins_gnss_ros.gnss import ephemeris_data
    from ins_gnss_ros.gnss.simulator import GnssSimulator, SimulatorConfig, solve_fix
    from ins_gnss_ros.nodes.ekf_node import EkfNode
    from ins_gnss_ros.gnss import gps_to_posix
    from ins_gnss_ros.nodes.gnss_messages import ephemeris_msg, observations_msg
    from ins_gnss_ros.nodes.strapdown_node import StrapdownNode
    from ins_gnss_ros.sim.scenarios import ShadingWindow

    rate, t_switch, duration = 50.0, 60.0, 110.0
    traj = car(duration=duration, seed=5, rate=rate, static=15.0).trajectory
    imu = simulate_imu(traj, ImuSpec(MEMS_ADIS16405, rate=rate), seed=5)
    broadcast = ephemeris_data.load(traj.lon[0])
    sim = GnssSimulator(broadcast, SimulatorConfig(
        lever_arms=(tuple(LEVER),), shading=(ShadingWindow(t_switch, duration, 3),)))
    epochs = [e[0] for e in sim.run(traj, 1.0)]
    t0 = gps_to_posix(sim.gps_time(0.0), 18)  # simulation time 0 on the UTC stamp axis

    bus = InProcessBus()
    strapdown = StrapdownNode(context=ros_context, bus=bus)
    ekf = EkfNode(context=ros_context, bus=bus, parameter_overrides=[
        Parameter("lever_arm", value=LEVER.tolist()), Parameter("layout", value="24"),
        Parameter("bias_model", value="rw"),
        Parameter("coupling", value="tight" if own_fix else "auto"),
        Parameter("tight.align_on_observations", value=own_fix),
        Parameter("auto.min_satellites", value=5),
        Parameter("tight.code_sigma_m", value=[0.3, 0.32]),
        Parameter("tight.doppler_sigma_hz", value=[0.02, 0.02]),
        Parameter("tight.klobuchar", value=[*broadcast.klobuchar[0], *broadcast.klobuchar[1]]),
        Parameter("init.position_sigma_m", value=3.0), Parameter("init.velocity_sigma_mps", value=0.2),
        Parameter("align.speed_mps", value=1.0)])
    states, statuses = [], []
    bus.subscribe("ins/state", states.append)
    bus.subscribe("nav/status", statuses.append)

    def send(topic, msg):
        bus.publish(topic, msg)
        bus.drain()

    stamp = sec_to_stamp(t0 + epochs[0].t)
    for eph in sim.ephemerides.values():
        send("gnss/ephemeris", ephemeris_msg(eph, stamp, 18))
    x0, i, sent_fixes = None, 0, []
    for ep in epochs:
        while i < len(imu.t) and imu.t[i] <= ep.t:
            delta = ImuDelta(dt=float(imu.dt))
            delta.header.stamp = sec_to_stamp(t0 + imu.t[i])
            delta.delta_angle, delta.delta_velocity = (to_vector3(imu.dtheta[i]),
                                                       to_vector3(imu.dv[i]))
            send("imu/delta", delta)
            i += 1
        stamp = sec_to_stamp(t0 + ep.t)
        send("gnss/observations", observations_msg(ep.raw, ep.antenna, stamp,
                                                   f"gnss_antenna_{ep.antenna}", ep.loss_of_lock))
        fix = solve_fix(ep, sim, x0)
        if fix is not None:  # an SPP needs 5 satellites (two systems): none after t_switch
            x0 = fix.xyz
            fmsg = _fix_msg(ep.t, fix.lat + own_fix * 50.0 / 6.4e6, fix.lon, fix.h, np.zeros(3))
            fmsg.header.stamp = stamp
            fmsg.position_covariance = np.asarray(fix.covariance_enu).flatten().tolist()
            vmsg = _vel_msg(ep.t, fix.vel_enu, np.zeros(3))
            vmsg.header.stamp = stamp
            send("gnss/fix", fmsg)
            sent_fixes.append(fmsg)
            send("gnss/vel", vmsg)
    strapdown.destroy_node()
    ekf.destroy_node()

    assert any(s.coupling == FilterStatus.COUPLING_TIGHT for s in statuses)
    # the datum is the first fix the filter used: the receiver's, or its own 50 m from it
    datum_to_fix = (ekf.aiding.datum[0] - np.radians(sent_fixes[0].latitude)) * 6.4e6
    assert abs(datum_to_fix) == (pytest.approx(50.0, abs=10.0) if own_fix
                                 else pytest.approx(0.0, abs=1e-6))
    ranges = [u for s in statuses for u in s.updates if u.name == "pseudorange"]
    assert ranges and all(len(u.innovation) == 3 for u in ranges if u.stamp.sec >= t0 + t_switch)
    assert sum(u.accepted for u in ranges) >= 0.9 * len(ranges)
    errors = []
    for msg in states:
        st = nav_state_from_msg(msg)
        k = int(round((st.t - t0) * rate))
        if st.t - t0 < t_switch + 5.0 or k >= len(traj.t):
            continue
        true = NavState(traj.lat[k], traj.lon[k], traj.h[k], traj.v_enu[k], traj.q_nb[k], st.t)
        dp = nav_error(st, true)[0]
        errors.append(np.hypot(dp[0], dp[1]))
    # (free inertial drifts far beyond this: test/gnss/test_ranges.py compares the two)
    assert max(errors) < 5.0


def test_imu_gap_is_bridged_and_a_long_one_restarts_the_alignment(ros_context):
    """At rest: a 0.5 s gap in imu/delta is bridged by holding the next increment's rates (no
    free fall: the solution stays at rest) with the velocity covariance widened; a 4 s gap loses
    the IMU: the filter starts again from ALIGNING and nav/fix waits for a new synchronisation."""
    from ins_gnss_ros.nav.earth import earth_rate_enu, normal_gravity
    from ins_gnss_ros.nodes.ekf_node import EkfNode

    lat, lon, h = np.radians(60.0), np.radians(30.0), 10.0
    node = EkfNode(context=ros_context, bus=InProcessBus())
    S = node.navigator.space

    def delta(t):
        msg = ImuDelta(dt=0.01)
        msg.header.stamp = sec_to_stamp(T0 + t)
        msg.delta_angle = to_vector3(earth_rate_enu(lat) * 0.01)  # body axes = ENU
        msg.delta_velocity = to_vector3([0.0, 0.0, normal_gravity(lat, h) * 0.01])
        return msg

    def run(t_from, t_to):
        for k in range(int(round(t_from * 100)), int(round(t_to * 100))):
            node.on_delta(_payload(delta(k / 100)))
            if k % 25 == 0:
                node.on_input("gnss/fix", node.inputs.fix,
                              _fix_msg(k / 100, lat, lon, h, np.zeros(3)))
                node.on_input("gnss/vel", node.inputs.velocity,
                              _vel_msg(k / 100, np.zeros(3), np.zeros(3)))

    run(0.01, 5.0)
    assert node.navigator.solution is not None
    sigma_v = np.sqrt(np.diag(node.navigator.covariance())[S["vel"]])
    node.on_delta(_payload(delta(5.5)))               # 0.49 s lost before 5.5 s
    node.on_delta(_payload(delta(5.51)))              # (the segment's end is known)
    assert node.diag.counts["gap in increments: bridged by holding the rates"] == 1
    # imu_gap.accel_sigma_mps2 (1 m/s^2) held over 0.49 s
    assert np.all(np.sqrt(np.diag(node.navigator.covariance())[S["vel"]]) > sigma_v + 0.4)
    run(5.52, 8.0)
    assert np.abs(node.navigator.solution.v_enu).max() < 0.1  # held gravity: no free fall
    sequence = node.sync.sequence
    run(12.0, 12.01)                                  # 4 s lost: the IMU was lost
    assert node.diag.counts["imu lost: gap in increments beyond max_imu_gap_s, aligning again"] == 1
    assert node.navigator.solution is None and node.sync.sequence == sequence + 1
    run(12.01, 15.0)
    assert node.navigator.solution is not None  # aligned again on the new data
    node.destroy_node()


def test_gnss_inside_a_bridged_imu_gap_is_applied_at_its_epochs(trial, ros_context):
    """2 s of imu/delta lost while driving, GNSS arriving throughout (fault class freeze): the
    gap is bridged in increments of the usual length, so the fixes of the gap are applied at
    their epochs (none refused as too old, none gated) against the process noise accrued so
    far, and the filter's position error stays within 5 sigma of its covariance."""
    from ins_gnss_ros.nodes.ekf_node import EkfNode

    traj, imu, gnss = trial
    bus = InProcessBus()
    ekf = EkfNode(context=ros_context, bus=bus, parameter_overrides=_ekf_params())
    statuses: list[FilterStatus] = []
    bus.subscribe("nav/status", statuses.append)
    S = ekf.navigator.space
    gap = (70.0, 72.0)
    ratios = []
    g = 0
    for k in range(len(imu.t)):
        t = imu.t[k]
        while g < len(gnss) and gnss[g][0] <= t:
            tg, lat, lon, h, v, npos, nvel = gnss[g]
            for topic, msg in (("gnss/fix", _fix_msg(tg, lat, lon, h, npos)),
                               ("gnss/vel", _vel_msg(tg, v, nvel))):
                bus.publish(topic, msg)
                bus.drain()
            g += 1
        if gap[0] < t <= gap[1]:
            continue
        delta = ImuDelta(dt=float(imu.dt))
        delta.header.stamp = sec_to_stamp(T0 + t)
        delta.delta_angle, delta.delta_velocity = to_vector3(imu.dtheta[k]), to_vector3(imu.dv[k])
        bus.publish("imu/delta", delta)
        bus.drain()
        nav = ekf.navigator.solution
        if gap[0] - 1.0 < t < gap[1] + 10.0:
            j = int(round((nav.t - T0 - traj.t[0]) / traj.dt))
            true = NavState(traj.lat[j], traj.lon[j], traj.h[j], traj.v_enu[j], traj.q_nb[j], nav.t)
            sigma = np.sqrt(np.diag(ekf.navigator.covariance())[S["pos"]])
            ratios.append(np.max(np.abs(nav_error(nav, true)[0]) / sigma))
    ekf.destroy_node()

    assert ekf.diag.counts["gap in increments: bridged by holding the rates"] == 1
    in_gap = [u for s in statuses for u in s.updates
              if gap[0] < stamp_to_sec(u.stamp) - T0 < gap[1]]
    assert len(in_gap) == 2 * 7  # fix and velocity at 4 Hz, 70.25 to 71.75 s
    assert all(u.accepted for u in in_gap)
    assert max(ratios) < 5.0


def test_diagnostics_say_what_the_filter_waits_for_and_nav_fix_is_valid_only_navigating(
        trial, ros_context):
    from ins_gnss_ros.nodes.ekf_node import EkfNode
    from ins_gnss_ros.nodes.strapdown_node import StrapdownNode

    traj, imu, gnss = trial
    bus = InProcessBus()
    strapdown = StrapdownNode(context=ros_context, bus=bus)
    ekf = EkfNode(context=ros_context, bus=bus, parameter_overrides=_ekf_params())
    fixes: list[NavSatFix] = []
    bus.subscribe("nav/fix", fixes.append)

    def feed(t_from, t_to, topics):
        g = next(i for i, m in enumerate(gnss) if m[0] >= t_from)
        for k in range(int(round(t_from / imu.dt)), int(round(t_to / imu.dt))):
            t = imu.t[k]
            while g < len(gnss) and gnss[g][0] <= t:
                tg, lat, lon, h, v, npos, nvel = gnss[g]
                if "gnss/fix" in topics:
                    bus.publish("gnss/fix", _fix_msg(tg, lat, lon, h, npos))
                if "gnss/vel" in topics:
                    bus.publish("gnss/vel", _vel_msg(tg, v, nvel))
                bus.drain()
                g += 1
            delta = ImuDelta(dt=float(imu.dt))
            delta.header.stamp = sec_to_stamp(T0 + t)
            delta.delta_angle, delta.delta_velocity = to_vector3(imu.dtheta[k]), to_vector3(imu.dv[k])
            bus.publish("imu/delta", delta)
            bus.drain()

    feed(0.0, 5.0, ())
    # no GNSS yet: nothing to align on, said so
    assert ekf.diag._state == (DiagnosticStatus.WARN, "aligning: no gnss/fix received yet")
    bus.publish("gnss/fix", _fix_msg(5.0, 1.0, 0.5, 2e5, np.zeros(3)))  # corrupt height
    bus.drain()
    feed(5.0, 15.0, ("gnss/fix", "gnss/vel"))  # at rest: levelled, no heading source yet
    assert ekf.diag._state[1].startswith("aligning: no heading source yet: waits for motion")
    fix_line = ekf.diag._values["gnss/fix"]  # e.g. "4.10 Hz, last 0.0 s ago, 41 received, 1 refused"
    assert 3.9 < float(fix_line.split()[0]) < 4.2 and fix_line.endswith("1 refused")
    # nothing is published as a fix while aligning (at most a NO_FIX position)
    assert all(f.status.status == NavSatStatus.STATUS_NO_FIX for f in fixes)
    feed(15.0, 60.0, ("gnss/fix", "gnss/vel"))
    assert ekf.diag._state == (DiagnosticStatus.OK, "navigating")
    assert fixes[-1].status.status == NavSatStatus.STATUS_FIX
    strapdown.destroy_node()
    ekf.destroy_node()


def test_diagnostics_say_when_the_antenna_lever_arm_is_assumed(ros_context):
    from ins_gnss_ros.nodes.ekf_node import EkfNode

    assumed = EkfNode(context=ros_context, bus=InProcessBus(), parameter_overrides=[
        Parameter("lever_arm_sigma_m", value=[0.2, 0.2, 1.0])])
    measured = EkfNode(context=ros_context, bus=InProcessBus(), parameter_overrides=_ekf_params())
    assert assumed.diag._values["GNSS antenna lever arm"] == (
        "[0.0, 0.0, 0.0] m FLU, not measured; within +-[0.2, 0.2, 1.0] m assumed "
        "(lever_arm_sigma_m)")
    assert {"lever_x", "lever_y", "lever_z"} <= set(assumed.navigator.config.extras)
    assert "GNSS antenna lever arm" not in measured.diag._values
    assumed.destroy_node()
    measured.destroy_node()


@pytest.mark.parametrize("urdf", [True, False])
def test_a_lever_arm_not_given_is_taken_from_a_urdf_until_the_filter_starts(trial, ros_context,
                                                                            urdf):
    """lever_arm left at zero, a URDF on /tf_static placing the IMU's frame (imu_link, off
    base_link's origin) and the receiver's (gps): the ekf takes the antenna's place less the
    IMU's as the lever arm before the filter starts (also when the URDF comes after the first
    fix), says so, and places its own gnss_0 there; once the filter runs, a moved transform
    changes nothing. Without a URDF it says that nothing placed the fixes' frame."""
    from sensor_msgs.msg import Imu
    from tf2_msgs.msg import TFMessage

    from ins_gnss_ros.nodes.ekf_node import EkfNode
    from ins_gnss_ros.nodes.tf_messages import static_tf

    traj, imu, gnss = trial
    imu_at = np.array([0.2, -0.1, 0.3])
    bus = InProcessBus()
    ekf = EkfNode(context=ros_context, bus=bus, parameter_overrides=[
        Parameter("lever_arm_sigma_m", value=[0.0, 0.0, 0.0])])
    static: list[TFMessage] = []
    bus.subscribe("/tf_static", static.append)

    def urdf_msg(antenna):
        return static_tf(sec_to_stamp(T0), "base_link", [
            ("imu_link", imu_at, np.eye(3)), ("gps", imu_at + antenna, np.eye(3))])

    def fix_msg(tg, lat, lon, h, noise):
        fix = _fix_msg(tg, lat, lon, h, noise)
        fix.header.frame_id = "gps"
        return fix

    raw = Imu()
    raw.header.frame_id = "imu_link"
    bus.publish("imu/data_raw", raw)
    g = 0
    for k in range(int(round(30.0 / imu.dt))):
        while g < len(gnss) and gnss[g][0] <= imu.t[k]:
            tg, lat, lon, h, v, npos, nvel = gnss[g]
            bus.publish("gnss/fix", fix_msg(tg, lat, lon, h, npos))
            bus.publish("gnss/vel", _vel_msg(tg, v, nvel))
            bus.drain()
            if g == 3 and urdf:  # the URDF after the first fixes, before the start
                assert not ekf.navigator.started and not ekf.navigator.lever_arm_b.any()
                bus.publish("/tf_static", urdf_msg(LEVER))
            g += 1
        delta = ImuDelta(dt=float(imu.dt))
        delta.header.stamp = sec_to_stamp(T0 + imu.t[k])
        delta.delta_angle, delta.delta_velocity = to_vector3(imu.dtheta[k]), to_vector3(imu.dv[k])
        bus.publish("imu/delta", delta)
        bus.drain()
    assert ekf.navigator.started
    placed = LEVER if urdf else np.zeros(3)
    np.testing.assert_allclose(ekf.navigator.lever_arm_b, placed, atol=1e-12)
    assert ekf.diag._values["GNSS antenna lever arm"] == (
        f"{LEVER.tolist()} m FLU, /tf_static's place of 'gps' less the IMU's 'imu_link' in "
        "'base_link'" if urdf else "[0.0, 0.0, 0.0] m FLU, not measured: /tf_static does not "
        "place gnss/fix's frame 'gps' in 'base_link'")
    gnss_0 = [tf.transform.translation for m in static for tf in m.transforms
              if tf.child_frame_id == "gnss_0"]
    assert [gnss_0[-1].x, gnss_0[-1].y, gnss_0[-1].z] == pytest.approx(placed.tolist())
    bus.publish("/tf_static", urdf_msg(2.0 * LEVER))
    bus.publish("gnss/fix", fix_msg(*gnss[g][:4], np.zeros(3)))
    bus.drain()
    np.testing.assert_allclose(ekf.navigator.lever_arm_b, placed, atol=1e-12)
    with pytest.raises(RuntimeError, match="the filter has started"):
        ekf.navigator.set_lever_arm(2.0 * LEVER)
    ekf.destroy_node()
