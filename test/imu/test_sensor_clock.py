"""Sample rate from the first stamps and the causal sensor-clock fit: jittered driver stamps with
lost samples against the true sampling instants."""
import numpy as np
import pytest

from ins_gnss_ros.imu.sensor_clock import SensorClock, fit_stamps

NS = 1_000_000_000
T0 = 1_780_000_000 * NS


def _stream(rate, duration, jitter, lost, seed=1, drift=250e-6):
    """True instants of a crystal ``drift`` fast, driver stamps with uniform jitter of full width
    ``jitter`` (s), and the ``lost`` samples (indices) missing."""
    rng = np.random.default_rng(seed)
    k = np.arange(int(duration * rate))
    truth = T0 + k * (NS / rate / (1 + drift))
    stamps = np.round(truth + rng.uniform(-jitter / 2, jitter / 2, len(k)) * NS).astype(np.int64)
    keep = ~np.isin(k, lost)
    return truth[keep], stamps[keep]


@pytest.mark.parametrize("rate", [10.0, 30.0, 100.0, 200.0, 1000.0])
def test_rate_from_the_first_stamps_despite_jitter_and_a_lost_sample(rate):
    truth, stamps = _stream(rate, 1.0 + 41 / rate, 2e-3, lost=[5])
    n = max(41, int(0.5 * rate))
    assert fit_stamps(stamps[:n]).rate_hz == pytest.approx(rate * (1 + 250e-6), rel=5e-3)


@pytest.mark.parametrize("rate", [100.0, 200.0])
def test_two_ms_jitter_gives_stamps_within_0_1_ms_and_lost_samples_stay_lost(rate):
    lost = [500, 900, 901, 1500]
    truth, stamps = _stream(rate, 30.0, 2e-3, lost)
    clock = SensorClock(fit_stamps(stamps[:41]).rate_hz)
    clean = np.array([clock.stamp(int(s)) for s in stamps])
    err = (clean - truth) / NS
    late = truth - T0 > 5 * NS
    print(f"\n{rate:.0f} Hz, 2 ms uniform jitter (raw RMS {np.std((stamps - truth) / NS) * 1e3:.2f}"
          f" ms): after 5 s max |clean - true| {abs(err[late]).max() * 1e3:.3f} ms, RMS "
          f"{np.sqrt(np.mean(err[late] ** 2)) * 1e3:.3f} ms")
    assert abs(err[late]).max() < 1e-4
    # Every step is a whole number of periods: one, except two and three over the losses.
    steps = np.round(np.diff(clean) / clock.period_ns).astype(int)
    assert sorted(steps[steps != 1].tolist()) == [2, 2, 3]
    assert clock.period_ns == pytest.approx(NS / rate / (1 + 250e-6), rel=1e-5)  # of 250 ppm
    assert clock.resets == 1


def test_duplicate_and_backwards_stamps_keep_their_place():
    clock = SensorClock(100.0)
    for k in range(50):
        clock.stamp(T0 + k * NS // 100)
    last = T0 + 49 * NS // 100
    assert clock.stamp(last) == last                       # a duplicate: same instant
    assert clock.stamp(last - 3 * NS // 100) < last        # backwards: an earlier one
    assert clock.stamp(last + NS // 100) == last + NS // 100


def test_a_step_of_the_driver_clock_restarts_the_fit():
    """A 3.3 ms step (not whole periods) on jitter-free stamps: after ``reset_after`` samples the
    fit restarts there, and the stamps are exact again."""
    clock = SensorClock(100.0, jitter_s=1e-4)
    stamps = [T0 + k * NS // 100 + (3_300_000 if k >= 100 else 0) for k in range(200)]
    clean = [clock.stamp(s) for s in stamps]
    assert clock.resets == 2
    assert clean[110:] == stamps[110:] and clean[:100] == stamps[:100]


def test_samples_stamped_per_usb_frame_are_measured_and_put_back_one_period_apart():
    """A 100 Hz IMU whose driver stamps each 20 ms USB frame's samples together when the frame
    arrives (1-3 ms after it ends): the first 2 s give the rate to 0.1 % and the stamps' scatter
    (5.2 ms RMS), and the fit with that scatter puts the samples 10 +- 0.2 ms apart at a constant
    latency (the frame's mean delay, not observable from the stamps), where the stamps jump by
    0 or 20 ms."""
    rng = np.random.default_rng(1)
    rate, drift, frame = 100.0, 250e-6, 20_000_000
    truth = T0 + np.arange(3000) * (NS / rate / (1 + drift))
    stamps = (truth.astype(np.int64) // frame + 1) * frame \
        + rng.uniform(1e6, 3e6, len(truth)).astype(np.int64)
    fit = fit_stamps(stamps[:200])
    assert fit.rate_hz == pytest.approx(rate * (1 + drift), rel=1e-3) and fit.rate_sigma < 1e-3
    assert 0.004 < fit.scatter_s < 0.007
    clock = SensorClock(fit.rate_hz, fit.scatter_s)
    clean = np.array([clock.stamp(int(s)) for s in stamps])
    late = truth - T0 > 10 * NS
    err = (clean - truth)[late] / NS
    assert np.ptp(err) < 5e-3 and clock.resets == 1
    steps = np.diff(clean[late]) / NS
    assert np.all(np.abs(steps - 1.0 / rate) < 2e-4)
