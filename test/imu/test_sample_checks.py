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
