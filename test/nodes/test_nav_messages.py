"""REP conventions of the published fixes: nav/fix status from the mode and the input's
augmentation, and the driver's RTK float/fixed split (NMEA 0183 v4.11 GGA quality 4 fixed,
5 float; NavSatStatus GBAS_FIX for RTK fixed only)."""
from sensor_msgs.msg import NavSatStatus

from ins_gnss_ros.gnss.observations import NmeaFix
from ins_gnss_ros.nodes.gnss_messages import fix_from_gga
from ins_gnss_ros.nodes.nav_messages import OutputSchedule, fix_status

S = NavSatStatus


def test_nav_fix_status_from_mode_and_input():
    assert fix_status(False, S.STATUS_GBAS_FIX) == S.STATUS_NO_FIX
    assert fix_status(True, S.STATUS_GBAS_FIX) == S.STATUS_GBAS_FIX
    assert fix_status(True, S.STATUS_SBAS_FIX) == S.STATUS_SBAS_FIX
    assert fix_status(True, S.STATUS_FIX) == S.STATUS_FIX
    assert fix_status(True, S.STATUS_NO_FIX) == S.STATUS_FIX  # navigating on pseudoranges


def test_gga_rtk_fixed_is_gbas_and_float_is_not():
    def status(quality):
        gga = NmeaFix("GN", None, 1.0, 0.5, 10.0, 15.0, quality, 12, 0.8, 1.0)
        return fix_from_gga(gga, None, None, "gnss", S.SERVICE_GPS, 5.0).status.status

    assert [status(q) for q in (0, 1, 2, 4, 5)] == [S.STATUS_NO_FIX, S.STATUS_FIX,
                                                     S.STATUS_SBAS_FIX, S.STATUS_GBAS_FIX,
                                                     S.STATUS_SBAS_FIX]


def _published(stamps, rate_hz=10.0, skip=()):
    """The stamps an OutputSchedule publishes of these states (those in ``skip`` cannot be)."""
    schedule, out = OutputSchedule(rate_hz), []
    for t in stamps:
        if schedule.due(t) and t not in skip:
            schedule.published(t)
            out.append(t)
    return out


def test_the_solution_keeps_its_rate_from_jittered_states_at_any_imu_rate():
    """A 10 Hz output from states whose stamps scatter 0.1 ms (drivers' stamps): every state
    of a 10 Hz IMU (a strict "a period since the last" took every other one), every tenth of a
    100 Hz one, every third of a 30 Hz one; once the due state cannot be published (not yet
    corrected) the next one is, and the output goes on a period from it."""
    import numpy as np

    rng = np.random.default_rng(1)
    for rate, every in ((10, 1), (30, 3), (100, 10), (1000, 100)):
        stamps = (np.arange(20 * rate) / rate + rng.uniform(-1e-4, 1e-4, 20 * rate)).tolist()
        intervals = np.diff(_published(stamps))
        assert np.allclose(intervals, every / rate, atol=3e-4), rate
    stamps = (np.arange(100) / 20).tolist()
    assert np.allclose(np.diff(_published(stamps, skip={stamps[10]})),
                       [0.1] * 4 + [0.15] + [0.1] * 44)
    # a looped bag starts the output again
    assert _published([0.0, 0.1, 0.2, 0.0, 0.1]) == [0.0, 0.1, 0.2, 0.0, 0.1]


def _epochs(k, seed=0):
    """k random epochs near a datum: lat, lon, h, v_enu, q_nb, P (15 states)."""
    import numpy as np

    rng = np.random.default_rng(seed)
    q = rng.normal(size=(k, 4))
    q /= np.linalg.norm(q, axis=1)[:, None]
    a = rng.normal(size=(k, 15, 15))
    return (0.7 + rng.normal(size=k) * 1e-3, 0.2 + rng.normal(size=k) * 1e-3,
            rng.uniform(0, 3000, k), rng.normal(size=(k, 3)) * 100, q,
            a @ a.transpose(0, 2, 1))


def test_column_payloads_are_the_messages_of_each_epoch():
    """fix_payloads and odom_payloads (many epochs at once) are the bytes fix_payload and
    odom_payload pack for each epoch alone; ins_state_payloads and ins_state_payload decode,
    by rclpy's own deserializer, into the message fill_ins_state builds."""
    import numpy as np
    from ins_gnss_msgs.msg import InsState
    from rclpy.serialization import deserialize_message

    from ins_gnss_ros.io import messages_equal, ns_to_stamp
    from ins_gnss_ros.nav.ekf import StateSpace
    from ins_gnss_ros.nav.error_model import make_layout
    from ins_gnss_ros.nav.increments import SensorErrors
    from ins_gnss_ros.nav.strapdown import NavState
    from ins_gnss_ros.nodes.convert import fill_ins_state, ins_state_payload, ins_state_payloads
    from ins_gnss_ros.nodes.nav_messages import fix_payload, fix_payloads, odom_payload, \
        odom_payloads

    k = 50
    lat, lon, h, v, q, P = _epochs(k)
    space = StateSpace(make_layout("15"))
    datum = (0.7, 0.2, 100.0)
    stamps = 1_767_225_600_000_000_000 + np.arange(k) * 76_923_077
    status = np.arange(k) % 2
    fixes = fix_payloads(stamps, lat, lon, h, P[:, space["pos"], space["pos"]], status,
                         "base_link")
    odoms = odom_payloads(stamps, lat, lon, h, v, q, P, space, datum, 1e-6, ("map", "base_link"))
    states = ins_state_payloads(stamps, lat, lon, h, v, q, InsState.MODE_NAVIGATING)
    for i in range(k):
        st = NavState(lat[i], lon[i], h[i], v[i], q[i], int(stamps[i]) * 1e-9)
        stamp = ns_to_stamp(stamps[i])
        assert fixes[i] == fix_payload(int(stamps[i]), st, P[i][space["pos"], space["pos"]],
                                       int(status[i]), frame_id="base_link")
        assert odoms[i] == odom_payload(int(stamps[i]), st, P[i], space, datum, (0.0,) * 3,
                                        1e-6, ("map", "base_link"))
        state = InsState()
        fill_ins_state(state, st)   # stamped from st.t (s)
        state.header.frame_id = "map"
        state.mode, state.correction_sequence = InsState.MODE_NAVIGATING, 1
        assert messages_equal(deserialize_message(ins_state_payload(
            st, np.zeros(3), np.zeros(3), SensorErrors(), InsState.MODE_NAVIGATING, 1),
            InsState), state)
        state.header.stamp = stamp
        assert messages_equal(deserialize_message(states[i], InsState), state)


def test_odom_twist_is_the_velocity_in_base_link():
    """nav/odom's twist rotated back into ENU by the orientation is the solution's velocity,
    and the datum itself is the map origin."""
    import numpy as np
    from nav_msgs.msg import Odometry
    from rclpy.serialization import deserialize_message

    from ins_gnss_ros.nav.ekf import StateSpace
    from ins_gnss_ros.nav.error_model import make_layout
    from ins_gnss_ros.nav.rotations import quat_to_dcm
    from ins_gnss_ros.nodes.nav_messages import odom_payloads

    lat, lon, h, v, q, P = _epochs(20, seed=1)
    lat[0], lon[0], h[0] = 0.7, 0.2, 100.0
    odoms = [deserialize_message(d, Odometry) for d in odom_payloads(
        np.arange(20), lat, lon, h, v, q, P, StateSpace(make_layout("15")), (0.7, 0.2, 100.0),
        0.0)]
    for i, odom in enumerate(odoms):
        tw = odom.twist.twist.linear
        assert np.allclose(quat_to_dcm(q[i]) @ [tw.x, tw.y, tw.z], v[i], atol=1e-9)
    p = odoms[0].pose.pose.position
    assert np.allclose([p.x, p.y, p.z], 0.0, atol=1e-6)
