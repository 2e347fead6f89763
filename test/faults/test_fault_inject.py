"""Fault injector: every kind against what it must do to a synthetic stream (counts, offsets,
stamps), position jumps against pymap3d, determinism, untouched input, and a strapdown node on
the in-process bus surviving corrupted increments."""

from __future__ import annotations

import copy
import math

import numpy as np
import pymap3d
import pytest

from ins_gnss_ros.faults import FaultError, FaultInjector, inject, load_fault_spec
from ins_gnss_ros.io import msg_stamp_ns, ns_to_stamp

T0 = 1_700_000_000 * 10**9  # stream start, ns (any epoch works: windows are relative to it)
S = 10**9


def _imu(t):
    from sensor_msgs.msg import Imu

    m = Imu()
    m.header.stamp = ns_to_stamp(t)
    m.angular_velocity.z = 0.001
    m.linear_acceleration.z = 9.81
    return m


def _fix(t, lat=59.9, lon=30.3, h=20.0):
    from sensor_msgs.msg import NavSatFix

    m = NavSatFix(latitude=lat, longitude=lon, altitude=h)
    m.header.stamp = ns_to_stamp(t)
    return m


def _mag(t):
    from sensor_msgs.msg import MagneticField

    m = MagneticField()
    m.header.stamp = ns_to_stamp(t)
    m.magnetic_field.x, m.magnetic_field.y, m.magnetic_field.z = 15e-6, 0.0, -50e-6
    return m


SATS = [(0, 3), (0, 7), (0, 12), (2, 5), (2, 11), (6, 4)]


def _obs(t, antenna=0):
    from ins_gnss_msgs.msg import GnssObservations

    m = GnssObservations(antenna_id=antenna)
    m.header.stamp = ns_to_stamp(t)
    # Two signals for the first satellite: the arrays are per signal, not per satellite.
    sats = [SATS[0]] + SATS
    m.system = [s for s, _ in sats]
    m.prn = [p for _, p in sats]
    m.frequency_slot = [0] * len(sats)
    m.signal = [0] + [3] + [0] * (len(sats) - 2)
    m.pseudorange = [2.0e7 + 1000.0 * k for k in range(len(sats))]
    m.doppler = [100.0] * len(sats)
    m.carrier_phase = [1.0e8 + 10.0 * k for k in range(len(sats))]
    m.cn0 = [45.0] * len(sats)
    m.lock_time = [30.0] * len(sats)
    m.loss_of_lock = [True, False] + [False] * (len(sats) - 2)
    m.pseudorange_std = [0.5] * len(sats)
    m.carrier_phase_std = [0.01] * len(sats)
    return m


def stream(seconds=10.0, imu_hz=100, with_truth=False):
    """A time-ordered stream: IMU at imu_hz, fix/obs (two antennas)/mag at 1 Hz."""
    out = []
    for k in range(int(seconds * imu_hz)):
        t = T0 + k * S // imu_hz
        out.append((t, "/imu/data_raw", _imu(t)))
        if k % imu_hz == 0:
            out.append((t, "/gnss/fix", _fix(t)))
            out.append((t, "/gnss/observations", _obs(t, 0)))
            out.append((t, "/gnss/observations", _obs(t, 1)))
            out.append((t, "/imu/mag_raw", _mag(t)))
            if with_truth:
                out.append((t, "/truth/state", _fix(t)))
    return out


def run(spec_text, msgs=None):
    injector = FaultInjector(load_fault_spec(spec_text, text=True))
    out = list(injector(msgs if msgs is not None else stream()))
    times = [t for t, _, _ in out]
    assert times == sorted(times), "output must stay ordered by arrival time"
    return out, injector


def on(out, topic):
    return [(t, m) for t, top, m in out if top == topic]


def in_window(t, a, b):
    return T0 + a * S <= t < T0 + b * S


def test_drop_only_the_matching_topic_inside_the_window():
    msgs = stream()
    out, inj = run("faults: [{kind: drop, topic: imu/data_raw, start: 2, duration: 1.5}]", msgs)
    imu = on(out, "/imu/data_raw")
    assert len(imu) == 1000 - 150
    assert not any(in_window(t, 2, 3.5) for t, _ in imu)
    assert len(on(out, "/gnss/fix")) == 10
    rec = inj.records[0]
    assert rec.affected == 150 and rec.start_ns == T0 + 2 * S and rec.end_ns == T0 + 3.5 * S


def test_drop_with_probability_is_seeded_and_roughly_that_fraction():
    text = "seed: {}\nfaults: [{{kind: drop, topic: 'imu/*', start: 0, probability: 0.3}}]"
    a, _ = run(text.format(1))
    b, _ = run(text.format(1))
    c, _ = run(text.format(2))
    stamps = [[msg_stamp_ns(m) for _, m in on(x, "/imu/data_raw")] for x in (a, b, c)]
    assert stamps[0] == stamps[1] != stamps[2]
    assert abs((1000 - len(stamps[0])) / 1000 - 0.3) < 0.05  # binomial sd 0.015


def test_delay_moves_arrival_not_stamps():
    out, _ = run("faults: [{kind: delay, topic: gnss/fix, start: 3, duration: 2, delay_s: 0.25}]")
    for t, m in on(out, "/gnss/fix"):
        delay = t - msg_stamp_ns(m)
        assert delay == (S // 4 if in_window(msg_stamp_ns(m), 3, 5) else 0)


def test_duplicate_copies_are_equal_but_distinct_objects():
    out, _ = run("faults: [{kind: duplicate, topic: gnss/fix, start: 0, duration: 3.5, "
                 "copies: 2}]")
    fixes = on(out, "/gnss/fix")
    assert len(fixes) == 10 + 2 * 4
    first3 = [m for _, m in fixes[:3]]
    assert len({id(m) for m in first3}) == 3
    assert first3[0] == first3[1] == first3[2]


def test_reorder_permutes_stamps_within_blocks():
    out, inj = run("seed: 5\nfaults: [{kind: reorder, topic: imu/data_raw, start: 1, "
                   "duration: 1, window: 10}]")
    stamps = [msg_stamp_ns(m) for _, m in on(out, "/imu/data_raw")]
    assert sorted(stamps) == [T0 + k * S // 100 for k in range(1000)]  # nothing lost or added
    assert stamps != sorted(stamps)
    inside = stamps[100:200]
    for b in range(10):  # each block of 10 is a permutation of its own stamps
        block = inside[10 * b:10 * b + 10]
        assert sorted(block) == [T0 + S + (10 * b + k) * S // 100 for k in range(10)]
    assert stamps[:100] == sorted(stamps[:100]) and stamps[200:] == sorted(stamps[200:])


def test_freeze_repeats_last_content_with_new_stamps():
    msgs = stream()
    msgs = [(t, top, m) for t, top, m in msgs]
    for k, (t, top, m) in enumerate(msgs):
        if top == "/imu/data_raw":
            m.angular_velocity.z = float(k)  # content changes with time
    out, _ = run("faults: [{kind: freeze, topic: imu/data_raw, start: 4, duration: 1}]", msgs)
    imu = on(out, "/imu/data_raw")
    before = imu[399][1].angular_velocity.z
    for t, m in imu[400:500]:
        assert m.angular_velocity.z == before and msg_stamp_ns(m) == t
    assert imu[500][1].angular_velocity.z != before


def test_step_and_ramp_of_a_field():
    out, _ = run("faults: [{kind: step, topic: imu/data_raw, start: 2, duration: 1, "
                 "field: angular_velocity.z, value: 0.5}]")
    for t, m in on(out, "/imu/data_raw"):
        assert m.angular_velocity.z == pytest.approx(0.001 + (0.5 if in_window(t, 2, 3) else 0))
    out, _ = run("faults: [{kind: ramp, topic: imu/data_raw, start: 2, duration: 2, "
                 "field: linear_acceleration.z, rate: 0.1}]")
    for t, m in on(out, "/imu/data_raw"):
        expected = 9.81 + (0.1 * (t - T0 - 2 * S) / S if in_window(t, 2, 4) else 0.0)
        assert m.linear_acceleration.z == pytest.approx(expected, abs=1e-12)


def test_nan_inf_absurd_values_and_arrays():
    out, _ = run("""faults:
      - {kind: nan, topic: gnss/fix, start: 1, duration: 1, field: latitude}
      - {kind: inf, topic: gnss/fix, start: 3, duration: 1, field: altitude, negative: true}
      - {kind: absurd, topic: imu/data_raw, start: 5, duration: 1, field: angular_velocity.x,
         value: 1.0e+9}
      - {kind: nan, topic: gnss/observations, start: 7, duration: 1, field: pseudorange}""")
    fixes = {msg_stamp_ns(m): m for _, m in on(out, "/gnss/fix")}
    assert math.isnan(fixes[T0 + S].latitude) and fixes[T0 + 2 * S].latitude == 59.9
    assert fixes[T0 + 3 * S].altitude == -math.inf
    imu = [m for t, m in on(out, "/imu/data_raw") if in_window(t, 5, 6)]
    assert len(imu) == 100 and all(m.angular_velocity.x == 1e9 for m in imu)
    obs = [m for t, m in on(out, "/gnss/observations") if in_window(t, 7, 8)]
    assert len(obs) == 2 and all(np.all(np.isnan(m.pseudorange)) for m in obs)


def test_integer_or_missing_field_is_a_clear_error():
    with pytest.raises(FaultError, match="no field 'angular_velocity.w'"):
        run("faults: [{kind: step, topic: imu/data_raw, start: 0, field: angular_velocity.w, "
            "value: 1}]")
    with pytest.raises(FaultError, match="not a float"):
        run("faults: [{kind: nan, topic: gnss/observations, start: 0, field: prn}]")


def test_clock_jump_shifts_stamps_from_start_on():
    out, _ = run("faults: [{kind: clock_jump, topic: 'imu/*', start: 5, offset_s: -2.5}]")
    for t, m in on(out, "/imu/data_raw"):
        assert msg_stamp_ns(m) - t == (-5 * S // 2 if t >= T0 + 5 * S else 0)
    assert all(msg_stamp_ns(m) == t for t, m in on(out, "/gnss/fix"))


def test_clock_drift_stretches_stamps_from_the_window_on():
    out, _ = run("faults: [{kind: clock_drift, topic: 'imu/*', start: 5, ppm: 200}]")
    first = T0 + 5 * S  # the window's first stamp
    for t, m in on(out, "/imu/data_raw"):  # arrival times stay
        assert msg_stamp_ns(m) - t == (round((t - first) * 200e-6) if t >= first else 0)
    assert all(msg_stamp_ns(m) == t for t, m in on(out, "/gnss/fix"))


def test_loop_plays_the_beginning_again_with_old_stamps():
    out, inj = run("faults: [{kind: loop, topic: '*', start: 6, duration: 3}]")
    imu = on(out, "/imu/data_raw")
    assert len(imu) == 1000  # 300 originals withheld, 300 copies of the first 3 s
    stamps = np.array([msg_stamp_ns(m) for _, m in imu])
    jumps = np.flatnonzero(np.diff(stamps) < 0)
    assert len(jumps) == 1 and stamps[jumps[0]] == T0 + 599 * S // 100
    assert stamps[jumps[0] + 1] == T0  # back to the stream's first stamp
    assert [t for t, _ in imu[600:900]] == [T0 + (600 + k) * S // 100 for k in range(300)]
    assert list(stamps[600:900]) == [T0 + k * S // 100 for k in range(300)]
    assert list(stamps[900:]) == [T0 + (900 + k) * S // 100 for k in range(100)]
    assert len(on(out, "/gnss/observations")) == 20


def test_gnss_outage_withholds_every_gnss_topic_and_keeps_truth():
    out, inj = run("faults: [{kind: gnss_outage, start: 2, duration: 4}]", stream(with_truth=True))
    gnss = [t for t, top, _ in out if top.startswith("/gnss/")]
    assert len(gnss) == 3 * (10 - 4) and not any(in_window(t, 2, 6) for t in gnss)
    assert len(on(out, "/truth/state")) == 10 and len(on(out, "/imu/data_raw")) == 1000
    assert inj.records[0].affected == 3 * 4


def test_patterns_never_touch_truth():
    out, _ = run("faults: [{kind: drop, topic: '*', start: 0}]", stream(with_truth=True))
    assert [top for _, top, _ in out] == ["/truth/state"] * 10


def test_satellites_disappear_down_to_zero():
    out, _ = run("faults: [{kind: satellite_loss, start: 2, duration: 6, ramp_s: 4}]")
    for antenna in (0, 1):
        counts = []
        kept_sets = []
        for t, m in on(out, "/gnss/observations"):
            if m.antenna_id != antenna:
                continue
            n = len(m.system)
            assert all(len(getattr(m, f)) == n for f in ("prn", "pseudorange", "carrier_phase",
                                                           "cn0", "loss_of_lock", "signal"))
            sats = set(zip(m.system, m.prn))
            counts.append(len(sats))
            kept_sets.append(sats)
            ref = _obs(0)
            rows = {key: pr for key, pr in zip(zip(ref.system, ref.prn, ref.signal),
                                                ref.pseudorange)}
            for key, pr in zip(zip(m.system, m.prn, m.signal), m.pseudorange):
                assert pr == rows[key]  # the rows of all arrays stay aligned
        # 6 satellites; 0/4, 1/4 ... 4/4 of the ramp at t = 2..6 s, none until 8 s, all again.
        assert counts == [6, 6, 6, round(6 * 0.75), 3, round(6 * 0.25), 0, 0, 6, 6]
        # Once gone, a satellite stays gone while the ramp goes on (a stable choice).
        assert kept_sets[3] >= kept_sets[4] >= kept_sets[5]


def test_position_jump_matches_pymap3d_enu():
    out, _ = run("faults: [{kind: position_jump, start: 3, duration: 4, north_m: 120.0, "
                 "east_m: -35.0, up_m: 8.0, ramp_s: 2}]")
    for t, m in on(out, "/gnss/fix"):
        e, n, u = pymap3d.geodetic2enu(m.latitude, m.longitude, m.altitude, 59.9, 30.3, 20.0)
        k = min(1.0, (t - T0 - 3 * S) / (2 * S)) if in_window(t, 3, 7) else 0.0
        # First-order metres-to-degrees conversion: 1e-5 relative over 120 m.
        assert e == pytest.approx(-35.0 * k, abs=2e-3)
        assert n == pytest.approx(120.0 * k, abs=2e-3)
        assert u == pytest.approx(8.0 * k, abs=2e-3)


def test_magnetic_disturbance_adds_the_field():
    out, _ = run("faults: [{kind: magnetic_disturbance, start: 4, duration: 2, "
                 "field_t: [2.0e-6, -1.0e-6, 5.0e-7]}]")
    for t, m in on(out, "/imu/mag_raw"):
        d = np.array([2e-6, -1e-6, 5e-7]) if in_window(t, 4, 6) else np.zeros(3)
        got = np.array([m.magnetic_field.x, m.magnetic_field.y, m.magnetic_field.z])
        np.testing.assert_allclose(got, np.array([15e-6, 0.0, -50e-6]) + d, atol=1e-15)


def test_cycle_slips_on_every_antenna_are_unflagged():
    out, inj = run("faults: [{kind: cycle_slip, start: 5, cycles: -7}]")
    ref = _obs(0)
    for t, m in on(out, "/gnss/observations"):
        slipped = t >= T0 + 5 * S
        np.testing.assert_array_equal(np.array(m.carrier_phase),
                                      np.array(ref.carrier_phase) - (7 if slipped else 0))
        assert list(m.pseudorange) == list(ref.pseudorange)
        assert list(m.loss_of_lock) == ([False] * len(ref.prn) if slipped else ref.loss_of_lock)
    assert inj.records[0].affected == 2 * 5  # both antennas, 5 epochs


def test_input_is_never_modified_and_runs_are_identical():
    msgs = stream(5.0)
    before = [copy.deepcopy(m) for _, _, m in msgs]
    text = """seed: 11
faults:
  - {kind: step, topic: imu/data_raw, start: 1, duration: 1, field: angular_velocity.z, value: 1}
  - {kind: reorder, topic: imu/data_raw, start: 2, duration: 1, window: 7}
  - {kind: cycle_slip, start: 2, cycles: 3, fraction: 0.5}
  - {kind: freeze, topic: imu/mag_raw, start: 3}
  - {kind: drop, topic: 'gnss/*', start: 0, probability: 0.5}"""
    a, _ = run(text, msgs)
    b, _ = run(text, msgs)
    # Message equality, not serialised bytes: CDR padding bytes are not initialised.
    assert [m for _, _, m in msgs] == before
    assert a == b


def test_faults_compose_in_order():
    # Delay first, then a drop whose window only the delayed message arrival does not change:
    # windows are on the input arrival time, so the drop removes exactly the window's messages.
    out, inj = run("""faults:
      - {kind: delay, topic: gnss/fix, start: 0, delay_s: 0.5}
      - {kind: drop, topic: gnss/fix, start: 4, duration: 2}""")
    fixes = on(out, "/gnss/fix")
    assert [msg_stamp_ns(m) for _, m in fixes] == [T0 + k * S for k in (0, 1, 2, 3, 6, 7, 8, 9)]
    assert all(t - msg_stamp_ns(m) == S // 2 for t, m in fixes)
    assert [r.affected for r in inj.records] == [10, 2]


def test_unordered_input_is_refused():
    msgs = stream(1.0)
    with pytest.raises(ValueError, match="not ordered"):
        list(inject(reversed(msgs), load_fault_spec("faults: []", text=True)))


def test_summary_is_plain_data():
    import json

    _, inj = run("faults: [{kind: gnss_outage, start: 2, duration: 3, name: outage A}]")
    (rec,) = inj.summary()
    assert json.loads(json.dumps(rec)) == rec
    assert rec["name"] == "outage A" and rec["first_ns"] == T0 + 2 * S
    assert rec["last_ns"] == T0 + 4 * S


def _stationary_deltas():
    """2 s of 100 Hz imu/delta at rest (gravity only, no rotation), from T0."""
    from ins_gnss_msgs.msg import ImuDelta

    for k in range(1, 201):
        t = T0 + k * S // 100
        m = ImuDelta(dt=0.01)
        m.header.stamp = ns_to_stamp(t)
        m.delta_velocity.z = 9.819 * 0.01
        yield t, "/imu/delta", m


def test_strapdown_node_survives_corrupted_increments(ros_context):
    """Through the in-process bus: NaN increments are counted and skipped, the state stays finite,
    and the gap they leave is bridged by holding the rates of the next increment: on this
    stationary stream (constant increments) that is exact, so nothing is lost. Integrating the
    one increment after the gap over the whole gap instead would lose the reaction to gravity
    of the skipped 0.3 s: free fall, g * 0.3 s of vertical velocity."""

    from ins_gnss_ros.nodes.base import InProcessBus
    from ins_gnss_ros.nodes.strapdown_node import StrapdownNode

    spec = load_fault_spec("faults: [{kind: nan, topic: imu/delta, start: 0.5, duration: 0.3, "
                           "field: delta_angle.x}]", text=True)
    results = []
    for faults in (None, spec):
        bus = InProcessBus()
        node = StrapdownNode(bus=bus, context=ros_context, start_parameter_services=False)
        states = []
        bus.subscribe("/ins/state", states.append)
        src = _stationary_deltas() if faults is None else inject(_stationary_deltas(), faults)
        for t, topic, msg in src:
            bus.now_ns = t
            bus.publish(topic, msg)
            bus.drain()
        results.append((states[-1], dict(node.diag.counts)))
        node.destroy_node()
    (clean, _), (faulty, counts) = results
    assert counts["non-finite or non-positive increment dropped"] == 30
    assert counts["gap in increments: bridged by holding the rates"] == 1
    assert np.isfinite([faulty.latitude, faulty.longitude, faulty.altitude]).all()
    assert faulty.latitude == pytest.approx(clean.latitude, abs=1e-9)
    assert faulty.velocity.z == pytest.approx(clean.velocity.z, abs=1e-6)
    assert faulty.altitude == pytest.approx(clean.altitude, abs=1e-6)
    assert faulty.mode == clean.mode


@pytest.mark.parametrize("node_name", ["strapdown", "ekf"])
def test_absurd_increments_fed_directly_are_dropped(ros_context, node_name):
    """Without the imu_preprocessor's range checks in front of them, the strapdown and the ekf
    still refuse increments beyond any IMU (here 1e12 rad per 10 ms) and count them."""

    from ins_gnss_ros.nodes.base import InProcessBus
    from ins_gnss_ros.nodes.registry import node_class

    spec = load_fault_spec("faults: [{kind: absurd, topic: imu/delta, start: 0.5, duration: 0.3, "
                           "field: delta_angle.x}]", text=True)  # value: 1e12 rad
    bus = InProcessBus()
    node = node_class(node_name)(bus=bus, context=ros_context, start_parameter_services=False)


    for t, topic, msg in inject(_stationary_deltas(), spec):
        bus.now_ns = t
        bus.publish(topic, msg)
        bus.drain()
    assert node.diag.counts["implausible increment dropped"] == 30
    node.destroy_node()
