"""Allan-variance fit on simulated noise with known coefficients (IEEE 952 definitions).

The noise is generated at 10 Hz: the white density N and the flicker level B are defined
per √Hz and per PSD, so a lower rate with the same PSD gives the same Allan curve above τ = 0.1 s
and keeps the test fast.
"""
import numpy as np
import pytest

from ins_gnss_ros.imu.allan import allan_deviation, characterise, fit_noise, noise_section

RATE = 10.0
DEG = np.pi / 180


def _flicker(n, b, rng):
    """Flicker (1/f) rate noise with IEEE 952 two-sided PSD B²/(2π f), i.e. one-sided B²/(π f).

    White Gaussian noise is shaped in the frequency domain: y = irfft(W sqrt(S fs / 2)) has
    one-sided PSD S for a unit-variance white input W.
    """
    f = np.fft.rfftfreq(n, 1 / RATE)
    s = np.zeros_like(f)
    s[1:] = b ** 2 / (np.pi * f[1:])
    w = np.fft.rfft(rng.standard_normal(n))
    return np.fft.irfft(w * np.sqrt(s * RATE / 2), n)


def test_white_plus_flicker_within_10_percent():
    rng = np.random.default_rng(7)
    n = int(4 * 3600 * RATE)
    arw = 0.005 * DEG             # rad/s/√Hz (0.3 deg/√h)
    bi = 0.0015 * DEG             # rad/s (5.4 deg/h)
    y = arw * np.sqrt(RATE) * rng.standard_normal(n) + _flicker(n, bi, rng)
    c, = characterise(y, RATE)
    print(f"\nARW {c.white / DEG * 60:.4f} deg/sqrt(h) (true {arw / DEG * 60:.4f}), "
          f"BI {c.bias_instability / DEG * 3600:.3f} deg/h (true {bi / DEG * 3600:.3f})")
    assert c.white == pytest.approx(arw, rel=0.10)
    assert c.bias_instability == pytest.approx(bi, rel=0.10)
    # The curve itself where white noise dominates: σ² = N²/τ + (0.664 B)².
    tau, adev, _, _ = allan_deviation(y, RATE)
    for i in np.flatnonzero(tau < 3.0):
        assert adev[i] == pytest.approx(np.hypot(arw / np.sqrt(tau[i]), 0.664 * bi), rel=0.03)


def test_white_plus_random_walk():
    rng = np.random.default_rng(3)
    n = int(3 * 3600 * RATE)
    vrw = 1e-3                    # m/s²/√Hz (accelerometer, about 100 µg/√Hz)
    k = 2e-5                      # m/s²/√s
    y = vrw * np.sqrt(RATE) * rng.standard_normal(n) + np.cumsum(k / np.sqrt(RATE) * rng.standard_normal(n))
    c, = characterise(y, RATE)
    print(f"\nVRW {c.white:.3e} (true {vrw:.1e}), K {c.random_walk:.3e} (true {k:.1e})")
    assert c.white == pytest.approx(vrw, rel=0.10)
    assert c.random_walk == pytest.approx(k, rel=0.25)


def test_noise_section_layout():
    c = fit_noise(np.array([0.1, 1.0, 10.0]), 0.1 / np.sqrt(np.array([0.1, 1.0, 10.0])), 1000.0)
    assert c.white == pytest.approx(0.1, rel=1e-3)  # pure white noise: σ(1 s) = N
    sec = noise_section([c] * 3, [c] * 3)["imu_noise"]
    assert set(sec) == {f"{s}_{k}" for s in ("gyro", "accel")
                        for k in ("noise_density", "bias_instability", "random_walk", "correlation_time")}
    assert len(sec["gyro_noise_density"]) == 3
