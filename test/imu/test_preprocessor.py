"""ImuPreprocessor without ROS: increments against the core coning/sculling, the filter's sensor
errors, gaps, time offset and clock jumps, magnetometer samples, settings that cannot work."""
import numpy as np
import pytest

from ins_gnss_ros.imu.calibration import ImuCalibration
from ins_gnss_ros.imu.preprocessor import ImuPreprocessor, SettingError, navigation_interval
from ins_gnss_ros.nav.coning import to_navigation_rate
from ins_gnss_ros.nav.increments import SensorErrors

NS = 1_000_000_000
T0 = 1_780_000_000 * NS
G_UP = (0.0, 0.0, 9.81)
CAL = ImuCalibration.from_dict({"gyro": {"bias": [0.02, -0.01, 0.015], "scale": [0.01, 0, 0]},
                                "accel": {"bias": [0.3, -0.2, 0.1]},
                                "mounting_rpy": [np.pi, 0.0, np.pi / 2]})


def _pre(rate=200.0, nav=100.0, method="two_sample", cal=None, **kw):
    kw.setdefault("max_identical_samples", 0)
    return ImuPreprocessor(cal or ImuCalibration(), rate, nav, method, gyro_range=30.0,
                           accel_range=150.0, **kw)


def _feed(pre, stamps_ns, gyro, accel):
    out = [o for t, g, a in zip(stamps_ns, gyro, accel)
           for o in pre.add(int(t), int(t), tuple(g), tuple(a))]
    return out, [inc for o in out for inc in o.increments]


@pytest.mark.parametrize("method", ["one_sample", "two_sample"])
def test_increments_are_the_cores_coning_sculling_of_the_calibrated_rates(method):
    rng = np.random.default_rng(4)
    n, n_sub, rate = 120, 4, 400.0
    w_b, f_b = rng.normal(0, 0.5, (n, 3)), rng.normal(0, 5.0, (n, 3))
    gyro, accel = CAL.simulate_raw(w_b, f_b)
    stamps = T0 + np.arange(1, n + 1) * (NS // 400)
    out, incs = _feed(_pre(rate, 100.0, method, CAL), stamps, gyro, accel)
    assert [o.reason for o in out] == ["ok"] * n
    rates = np.array([o.rates[0] for o in out])
    np.testing.assert_allclose(rates, w_b, rtol=0, atol=1e-13)
    dt = np.full(n, 1 / rate)
    phi, dv = to_navigation_rate(rates * dt[:, None], np.array([o.rates[1] for o in out])
                                 * dt[:, None], n_sub, method)
    assert len(incs) == n // n_sub
    np.testing.assert_allclose([i.dtheta for i in incs], phi, rtol=0, atol=1e-15)
    np.testing.assert_allclose([i.dv for i in incs], dv, rtol=0, atol=1e-14)
    assert [i.t_ns for i in incs] == stamps[n_sub - 1::n_sub].tolist()
    np.testing.assert_allclose([i.dt for i in incs], n_sub / rate, rtol=1e-12)


def test_sensor_errors_of_the_filter_add_up_and_non_finite_ones_are_refused():
    pre = _pre()
    step = SensorErrors(gyro_bias=np.array([0, 0, 0.01]), accel_bias=np.zeros(3),
                        gyro_scale=np.zeros(3), accel_scale=np.array([0, 0, 0.01]))
    assert pre.add_sensor_errors(step) and pre.add_sensor_errors(step)
    bad = SensorErrors(gyro_bias=np.array([np.nan, 0, 0]))
    assert not pre.add_sensor_errors(bad)
    w, f = pre.add(T0, T0, (0.0, 0.0, 0.05), G_UP)[0].rates
    # measured = (1 + s) true + b with the two increments summed: b = 0.02, s = 0.02.
    assert w[2] == pytest.approx(0.05 - 0.02, abs=1e-16)
    assert f[2] == pytest.approx(9.81 / 1.02, abs=1e-14)


def test_short_gap_bridged_long_gap_restarts_the_integration():
    pre = _pre(max_bridge=2)
    step = NS // 200
    stamps = [T0 + k * step for k in (1, 2, 3, 4, 7, 8, 9, 40, 41, 42)]
    out, incs = _feed(pre, stamps, [(0.0, 0.0, 0.1)] * 10, [G_UP] * 10)
    assert [o.reason for o in out] == ["ok"] * 4 + ["gap_bridged"] + ["ok"] * 2 + ["gap"] \
        + ["ok"] * 2
    assert pre.synthesised == 2
    # Increments of two samples each, never across the long gap, each at the true rate.
    assert [i.t_ns for i in incs] == [T0 + k * step for k in (2, 4, 6, 8, 41)]
    np.testing.assert_allclose([i.dtheta[2] for i in incs], 0.1 * 0.01, rtol=1e-9)


def test_increments_with_bridged_samples_carry_what_the_bridge_may_miss():
    # Noisy rates at 200 Hz, two samples an increment; after 20 s one sample lost: the
    # increment holding it carries (sigma dt)^2 of the miss the checker measured, and no other
    # increment carries anything.
    pre = _pre(max_bridge=2)
    step, n = NS // 200, 4000
    rng = np.random.default_rng(2)
    gyro = 0.01 * rng.standard_normal((n, 3))
    accel = np.array(G_UP) + 0.05 * rng.standard_normal((n, 3))
    stamps = [T0 + k * step for k in range(n)]
    _, before = _feed(pre, stamps[:-3], gyro[:-3], accel[:-3])
    sigma_w, sigma_f = pre.checker.miss.sigma(1)
    out, after = _feed(pre, stamps[-2:], gyro[-2:], accel[-2:])  # stamps[-3] lost
    assert out[0].reason == "gap_bridged"
    assert all(i.angle_var == i.velocity_var == 0.0 for i in before)
    bridged = [i for i in after if i.angle_var > 0.0]
    assert len(bridged) == 1
    assert bridged[0].angle_var == pytest.approx((sigma_w * step / NS) ** 2)
    assert bridged[0].velocity_var == pytest.approx((sigma_f * step / NS) ** 2)
    assert sigma_w == pytest.approx(np.sqrt(1.5) * 0.01, rel=0.1)


def test_rejected_sample_gives_no_rates():
    pre = _pre()
    assert pre.add(T0, T0, (np.nan, 0.0, 0.0), G_UP, "msg") == (
        (T0, "non_finite", None, (), (), "msg"),)
    assert pre.add(T0, T0, (0.0, 0.0, 40.0), G_UP)[0].reason == "saturated"


def test_time_offset_and_clock_jump_move_the_stamps():
    pre = _pre(time_offset_ns=-125_000_000)
    step = NS // 200
    jumped = []
    for k in range(1, 40):
        (o,) = pre.add(T0 + k * step + (NS // 2 if k >= 20 else 0), T0 + k * step, (0.0,) * 3,
                       G_UP)
        assert o.t_ns == T0 + k * step - 125_000_000
        jumped.append("clock_jump" in o.events)
    assert jumped.index(True) == 19 and sum(jumped) == 1


def test_magnetometer_rotated_offset_and_bad_samples_refused():
    pre = _pre(cal=ImuCalibration(mounting_rpy=np.array([np.pi, 0.0, np.pi / 2])),
               time_offset_ns=-5)
    t, m = pre.add_magnetic(T0, [10e-6, -5e-6, 40e-6])
    assert t == T0 - 5
    # Rx(180) then Rz(90): sensor (x, y, z) is base_link (-y, x, -z).
    np.testing.assert_allclose(m, [-5e-6, 10e-6, -40e-6], atol=1e-18)
    assert pre.add_magnetic(T0 + 1, [np.nan, 0, 0]) == "non_finite"
    assert pre.add_magnetic(T0, [0, 0, 1e-5]) == "stamp not after the previous one"


@pytest.mark.parametrize("rate, nav, method, expected", [
    (200.0, 100.0, "auto", (2, "two_sample")),
    (300.0, 100.0, "auto", (3, "one_sample")),
    (100.0, 100.0, "auto", (1, "one_sample")),
    (30.0, 100.0, "auto", (1, "one_sample")),      # an increment per sample: 30 Hz
    (1000.0, 300.0, "auto", (3, "one_sample")),    # 333.3 Hz, the nearest to 300
    (400.0, 150.0, "one_sample", (3, "one_sample")),
])
def test_navigation_interval_is_the_nearest_whole_number_of_samples(rate, nav, method, expected):
    assert navigation_interval(rate, nav, method) == expected


@pytest.mark.parametrize("rate, nav, method, name", [
    (300.0, 100.0, "two_sample", "coning_method"),
    (200.0, 100.0, "three_sample", "coning_method"),
])
def test_settings_that_cannot_work_name_themselves(rate, nav, method, name):
    with pytest.raises(SettingError) as err:
        navigation_interval(rate, nav, method)
    assert err.value.name == name
    with pytest.raises(SettingError, match="expected 0 .off. or >= 2") as err:
        _pre(max_identical_samples=1)
    assert err.value.name == "max_identical_samples"
    with pytest.raises(SettingError) as err:
        _pre(rate=0.0, method="three_sample")
    assert err.value.name == "coning_method"


def test_measured_rate_holds_the_first_samples_then_processes_them_all():
    """rate_hz 0: a 30 Hz IMU (the case that restarted the integration on every sample at the
    200 Hz default) with a lost sample in the window is measured, its held samples come out in
    order, and with nav_rate 100 Hz every sample is an increment (one_sample coning)."""
    pre = _pre(rate=0.0, nav=100.0, method="auto")
    period = NS / 30
    ks = [k for k in range(1, 61) if k != 7]
    outs = [pre.add(T0 + round(k * period), 0, (0.0, 0.0, 0.1), G_UP, k) for k in ks]
    first = next(k for k, o in enumerate(outs) if o)
    assert all(o == () for o in outs[:first]) and len(outs[first]) == first + 1
    flat = [p for o in outs for p in o]
    assert [p.tag for p in flat] == ks
    assert flat[0].events == ("rate_measured",)
    assert pre.rate_hz == pytest.approx(30.0, rel=1e-6) and pre.nav_rate_hz == pre.rate_hz
    assert pre.coning_method == "one_sample"
    assert [p.reason for p in flat].count("gap_bridged") == 1
    incs = [i for p in flat for i in p.increments]
    assert len(incs) == len(ks) + 1                      # the lost sample bridged
    np.testing.assert_allclose([i.dt for i in incs[1:]], 1 / 30, rtol=1e-6)


def test_samples_stamped_per_usb_frame_are_measured_over_a_longer_span_and_integrated():
    """rate_hz 0, a 100 Hz IMU stamped per 20 ms USB frame (two samples, one stamp 1-3 ms
    after the frame): half a second of such stamps gave 97.9 Hz and the 1 ms default jitter
    restarted and rejected samples throughout (the car drive so stamped: 12.5 m per outage
    instead of 3.4). Now the rate waits for a span that measures it to 0.1 %, the sensor clock
    takes the stamps' scatter, and the increments come one period apart."""
    rng = np.random.default_rng(2)
    frame, period = 20_000_000, NS / 100.0
    true = T0 + np.round(np.arange(1, 1500) * period).astype(np.int64)
    stamps = (true // frame + 1) * frame + rng.uniform(1e6, 3e6, len(true)).astype(np.int64)
    pre = _pre(rate=0.0, nav=100.0, method="auto", sensor_clock=(1e-3, 30.0))
    out, incs = _feed(pre, stamps, np.zeros((len(true), 3)), np.tile(G_UP, (len(true), 1)))
    assert out[0].events == ("rate_measured",) and len(out) == len(true)
    assert pre.rate_hz == pytest.approx(100.0, rel=1e-3) and 0.004 < pre.stamp_scatter_s < 0.007
    assert [o.reason for o in out[1:]].count("ok") >= len(true) - 2
    dt = np.array([i.dt for i in incs[500:]])
    np.testing.assert_allclose(dt, 0.01, atol=3e-4)


def test_measured_rate_falls_back_to_one_sample_when_two_sample_cannot_work():
    pre = _pre(rate=0.0, nav=100.0, method="two_sample")
    outs = [p for k in range(1, 200) for p in pre.add(T0 + k * NS // 300, 0, (0.0,) * 3, G_UP)]
    assert outs[0].events == ("rate_measured", "coning_fallback")
    assert (pre.rate_hz, pre.coning_method) == (pytest.approx(300.0), "one_sample")
