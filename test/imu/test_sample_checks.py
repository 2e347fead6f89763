"""Raw IMU sample checks: a stream with every kind of fault injected at known places, and the
recorded car IMU stream with rows deleted."""
from pathlib import Path

import numpy as np
import pytest

from ins_gnss_ros.imu.sample_checks import SampleChecker

DEG = np.pi / 180
RATE = 200.0  # ISON-2 sensing block, seed 004 §1.3c


def _checker(rate=RATE, **kw):
    return SampleChecker(rate, gyro_range=150 * DEG, accel_range=30.0, **kw)


def test_classifies_injected_faults():
    chk = _checker(max_bridge=3, max_identical=0)  # constant readings (frozen: tested below)
    g, a = np.array([0.1, 0.0, 0.0]), np.array([0.0, 0.0, 9.8])
    dt = 1 / RATE
    seq = [  # (stamp, gyro, accel, expected reason, expected ok)
        (0 * dt, g, a, "ok", True),
        (1 * dt, g, a, "ok", True),
        (2 * dt, [np.nan, 0, 0], a, "non_finite", False),
        (3 * dt, g, [0, 0, 30.0], "saturated", False),          # at the ±30 m/s² limit
        (4 * dt, [160 * DEG, 0, 0], a, "saturated", False),     # above ±150 deg/s
        (5 * dt, g, a, "gap_bridged", True),                    # 3 rejected samples bridged
        (5 * dt, g, a, "duplicate_stamp", False),
        (4.5 * dt, g, a, "backwards_stamp", False),
        (6.2 * dt, g, a, "ok", True),                           # jitter below 1.5 dt is fine
        (16 * dt, g, a, "gap", True),                           # 9 missing > max_bridge
        (np.inf, g, a, "non_finite", False),
        (17 * dt, g, a, "ok", True),
    ]
    for stamp, gy, ac, reason, ok in seq:
        r = chk.check(stamp, gy, ac)
        assert (r.reason, r.ok) == (reason, ok), stamp / dt
    expected = {"ok": 4, "non_finite": 2, "saturated": 2, "duplicate_stamp": 1,
                "backwards_stamp": 1, "frozen": 0, "gap_bridged": 1, "gap": 1}
    assert dict(chk.counts) == expected


def test_frozen_sensor_is_rejected_until_its_readings_change():
    """White noise changes every channel between samples: 5 bit-identical samples in a row (new
    stamps) are a stuck sensor; the 5th and later ones are rejected, and the first sample that
    differs is accepted again, after a gap the caller sees."""
    rng = np.random.default_rng(1)
    dt = 1 / RATE
    chk = _checker(max_bridge=3)
    noisy = [(0.01 * rng.standard_normal(3), [0, 0, 9.8] + 0.01 * rng.standard_normal(3))
             for _ in range(20)]
    reasons = [chk.check(k * dt, *noisy[k]).reason for k in range(10)]
    stuck = noisy[9]
    reasons += [chk.check(k * dt, *stuck).reason for k in range(10, 30)]   # 20 more repeats
    reasons += [chk.check(k * dt, *noisy[k - 30]).reason for k in range(30, 33)]
    assert reasons[:13] == ["ok"] * 13          # 1 original + 3 repeats pass
    assert reasons[13:30] == ["frozen"] * 17
    assert reasons[30:] == ["gap", "ok", "ok"]  # 17 samples missing > max_bridge
    assert chk.counts["frozen"] == 17
    # Off, or noise that never repeats: nothing is frozen; 1 would reject every repeat.
    off = _checker(max_identical=0)
    assert all(off.check(k * dt, *stuck).reason == "ok" for k in range(20))
    with pytest.raises(ValueError, match="max_identical"):
        _checker(max_identical=1)


@pytest.mark.parametrize("mode", ["interpolate", "hold"])
def test_bridging_values(mode):
    chk = _checker(max_bridge=5, bridge=mode)
    dt = 1 / RATE
    chk.check(0.0, [0.0, 0, 0], [0, 0, 9.0])
    r = chk.check(4 * dt, [0.3, 0, 0], [0, 0, 9.3])  # samples 1, 2, 3 lost
    assert r.reason == "gap_bridged"
    np.testing.assert_allclose(r.fill_stamps, [dt, 2 * dt, 3 * dt])
    if mode == "interpolate":
        np.testing.assert_allclose(r.fill_gyro[:, 0], [0.075, 0.15, 0.225])
        np.testing.assert_allclose(r.fill_accel[:, 2], [9.075, 9.15, 9.225])
    else:
        np.testing.assert_allclose(r.fill_gyro[:, 0], 0.0)
        np.testing.assert_allclose(r.fill_accel[:, 2], 9.0)


@pytest.mark.parametrize("mode", ["interpolate", "hold"])
def test_what_a_bridge_may_miss_is_measured_on_the_stream(mode):
    # White noise of sigma on a slow sine: an interpolated sample misses the true one by the
    # noise of the sample and of the mean of its two neighbours, sqrt(1.5) sigma; a held one by
    # that of two samples, sqrt(2) sigma (the sine's share is far below).
    sigma_w, sigma_f, dt = 0.01, 0.05, 1 / RATE
    rng = np.random.default_rng(4)
    chk = _checker(max_bridge=5, bridge=mode)
    n = 20_000
    t = np.arange(n) * dt
    gyro = 0.1 * np.sin(0.5 * t)[:, None] + sigma_w * rng.standard_normal((n, 3))
    accel = np.array([0.0, 0.0, 9.8]) + sigma_f * rng.standard_normal((n, 3))
    for k in range(n - 1):
        assert chk.check(t[k], gyro[k], accel[k]).reason == "ok"
    factor = np.sqrt(1.5 if mode == "interpolate" else 2.0)
    w, f = chk.miss.sigma(1)
    assert w == pytest.approx(factor * sigma_w, rel=0.05)
    assert f == pytest.approx(factor * sigma_f, rel=0.05)
    # a gap of two samples: the same bridge over a span twice as long (interpolating at the
    # middle of 2 x 2 samples, holding over 2): the noise share is the same
    assert chk.miss.sigma(2)[0] == pytest.approx(factor * sigma_w, rel=0.05)
    expected = chk.miss.sigma(1)
    r = chk.check(t[-2] + 2 * dt, gyro[-1], accel[-1])  # one sample lost
    assert r.reason == "gap_bridged" and r.fill_miss == expected
    assert _checker().check(0.0, gyro[0], accel[0]).fill_miss == (0.0, 0.0)  # nothing bridged


def test_results_without_fill_samples_are_shared_and_immutable():
    """Results that bring no fill samples are one shared object per reason: frozen, with
    read-only empty arrays, so that no caller can change what the next sample gets."""
    import dataclasses

    chk = _checker(max_identical=0)
    dt = 1 / RATE
    first, second = chk.check(0.0, (0.1, 0, 0), (0, 0, 9.8)), chk.check(dt, [0.1, 0, 0], [0, 0, 9.8])
    assert first is second and first.reason == "ok"
    rejected = [chk.check(dt, (0.1, 0, 0), (0, 0, 9.8)), chk.check(dt, (0.1, 0, 0), (0, 0, 9.8))]
    assert rejected[0] is rejected[1] and rejected[0].reason == "duplicate_stamp"
    with pytest.raises(dataclasses.FrozenInstanceError):
        first.reason = "gap"
    for a in (first.fill_stamps, first.fill_gyro, first.fill_accel):
        assert a.size == 0 and not a.flags.writeable
    bridged = chk.check(4 * dt, (0.1, 0, 0), (0, 0, 9.8))
    assert bridged.reason == "gap_bridged" and bridged.fill_gyro.shape == (2, 3)
    with pytest.raises(ValueError):  # a reading must have exactly three channels
        chk.check(5 * dt, (0.1, 0), (0, 0, 9.8))


def test_bad_configuration():
    with pytest.raises(ValueError, match="bridge"):
        _checker(bridge="spline")
    with pytest.raises(ValueError):
        SampleChecker(0.0, 1.0, 1.0)


SHARED = Path(__file__).resolve().parents[2] / ".." / "shared"
CAR_IMU = SHARED / "data" / "car_drive_0708" / "imu_1934.csv"


@pytest.mark.skipif(not CAR_IMU.exists(), reason="shared recorded data not available")
def test_recorded_car_stream():
    """The real 100 Hz car IMU (ax,ay,az in g, gx,gy,gz in deg/s, t in ms; see the data README):
    its stamps jitter by 8-11 ms, which must pass; deleting 3 and 30 rows must show up as one
    bridged gap and one reported gap."""
    rows = []
    for line in CAR_IMU.read_text().splitlines():
        parts = line.split(",")
        try:
            rows.append([float(p) for p in parts])
        except ValueError:
            continue  # header line or the truncated last line
    data = np.array([r for r in rows if len(r) == 7])[:15000]
    data = np.delete(data, np.r_[5000:5003, 10000:10030], axis=0)
    chk = _checker(rate=100.0, max_bridge=5)
    for ax, ay, az, gx, gy, gz, t in data:
        chk.check(t / 1000.0, np.radians([gx, gy, gz]), 9.80665 * np.array([ax, ay, az]))
    assert chk.counts["gap_bridged"] == 1 and chk.counts["gap"] == 1
    assert chk.counts["ok"] == len(data) - 2


def test_the_sensor_clock_drift_against_the_arrival_clock_is_measured_under_load():
    """100 Hz samples stamped by a clock 150 ppm fast, arriving after 1 ms of transport plus a
    scheduling delay of up to tens of ms (exponential, 5 ms mean: most samples are late, a few
    in each 30 s block find the way free): the floors' trend is the clocks' drift."""
    from ins_gnss_ros.imu.sample_checks import ArrivalDrift
    rng = np.random.default_rng(4)
    t = np.arange(0, 600.0, 0.01)
    # (in order: a queue delivers them first in, first out)
    arrival = np.maximum.accumulate(((t + 0.001 + rng.exponential(0.005, t.size)) * 1e9)
                                    .astype(np.int64))

    def measured(stamps):
        drift = ArrivalDrift()
        for stamp, arrived in zip(stamps.tolist(), arrival.tolist()):
            drift.add(stamp, arrived)
        return drift.rate()

    rate, sigma, span = measured((t * (1 + 150e-6) * 1e9).astype(np.int64))
    assert rate == pytest.approx(150e-6, abs=2e-6) and sigma < 2e-6 and span > 500
    rate, sigma, _ = measured((t * 1e9).astype(np.int64))
    assert abs(rate) < 2e-6
    # arrivals not paced by the samples (a replay twice as fast as real time): no clock's rate
    fast = ArrivalDrift()
    for stamp, arrived in zip((t * 1e9).astype(np.int64).tolist(), (arrival // 2).tolist()):
        fast.add(stamp, arrived)
    assert fast.rate() is None
