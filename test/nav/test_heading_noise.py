"""A heading source's time-correlated errors: measured from the readings, and the variance
they are fused with (nav/heading_noise.py, Aiding.heading)."""
from __future__ import annotations

import math

import numpy as np
import pytest

from ins_gnss_ros.nav.aiding import Aiding, AidingPolicy
from ins_gnss_ros.nav.heading_noise import HeadingNoise
from ins_gnss_ros.nav.measurement_types import HeadingFix

from fake_navigator import RecordingNavigator


R = math.radians(0.5) ** 2  # the readings' reported variance, rad^2
DT = 0.02  # 50 Hz


def _errors(n, correlation_time, rng):
    """Heading errors of variance R: white, or first-order Gauss-Markov with that time, s."""
    if correlation_time is None:
        return math.sqrt(R) * rng.standard_normal(n)
    a = math.exp(-DT / correlation_time)
    drive = math.sqrt(R * (1.0 - a * a)) * rng.standard_normal(n)
    e = np.empty(n)
    e[0] = math.sqrt(R) * rng.standard_normal()
    for k in range(1, n):
        e[k] = a * e[k - 1] + drive[k]
    return e


@pytest.mark.parametrize("correlation_time", [None, 1.0])
def test_readings_count_as_the_independent_information_they_carry(correlation_time):
    # 50 Hz readings reported with R. White ones keep R (within the statistic's scatter). With
    # errors correlated over T, N readings within 2T are worth one: the variance of a mean of
    # such readings over a long span is 2 T R / span, so each should be fused with about
    # R * 2 T / DT = 100 R, not R (which would make the filter 100 x too sure of the heading).
    # A constant drift (an uncompensated gyro bias, 0.1 deg/s) and an offset (the bias state's)
    # do not count.
    rng = np.random.default_rng(7)
    n = int(600.0 / DT)
    e = _errors(n, correlation_time, rng) + 0.3 + math.radians(0.1) * DT * np.arange(n)
    noise = HeadingNoise()
    fused = []
    for k in range(n):
        noise.add(k * DT, float(e[k]))
        fused.append(noise.variance(k * DT, R))
    assert fused[0] == R  # nothing measured yet: as reported
    expected = 1.0 if correlation_time is None else 2.0 * correlation_time / DT
    assert 0.8 * expected <= fused[-1] / R <= 1.6 * expected
    # before the long averaging times are measured the readings are not assumed to average
    # down further than shown: never less than the end's
    assert min(fused[int(30.0 / DT):]) >= 0.7 * fused[-1]


def test_the_front_end_differences_the_readings_against_the_gyros():
    # A car turning at 10 deg/s with a compass whose errors are correlated over 1 s: the turn
    # is taken out by the gyros' azimuth (it is not an error), the correlation raises the
    # variance the compass is fused with; a source without a bias block (a true heading) and
    # the reading that aligns the heading keep their reported variance.
    nav = RecordingNavigator(heading_known=False)
    front = Aiding(nav, AidingPolicy(), lambda text, log=True: None)
    front.velocity(0.0, np.zeros(3), np.eye(3) * 0.01)  # a receiver with velocity: no rest test
    rate = math.radians(10.0)  # counter-clockwise: the azimuth falls
    imu_dt, t_end = 0.01, 400.0
    rng = np.random.default_rng(3)
    errors = {"mag/heading": _errors(int(t_end / DT) + 1, 1.0, rng),
              "gnss/heading": _errors(int(t_end / DT) + 1, None, rng)}
    k_mag = 0
    for i in range(1, int(t_end / imu_dt) + 1):
        t = i * imu_dt
        front.increment(t, np.array([0.0, 0.0, rate * imu_dt]), np.zeros(3), imu_dt)
        if i % 2 == 0:
            k_mag += 1
            for source, e in errors.items():
                assert front.heading(t, (1.0 - rate * t + e[k_mag]) % (2 * math.pi), R, None,
                                     source)
            if k_mag == 1:
                first = nav.measurements[-2]
                nav.heading_known = True
    assert isinstance(first, HeadingFix) and first.variance == R
    mag, true = nav.measurements[-2], nav.measurements[-1]
    assert mag.bias == "mag" and true.bias is None
    assert true.variance == R
    assert 70.0 <= mag.variance / R <= 160.0  # 2 T / DT = 100
    assert "mag/heading" in front.heading_noise and "gnss/heading" not in front.heading_noise
    # what /diagnostics says of it (EkfNode): the measured rungs and S
    summary = front.heading_noise["mag/heading"].summary()
    assert summary.startswith("tau*H(tau) rad^2 s: 0.05 s ") and "; S " in summary
