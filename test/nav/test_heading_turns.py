"""nav/heading_turns.py: a heading source's turns against the gyros', on analytic drives."""
from __future__ import annotations

import math

import numpy as np
import pytest

from ins_gnss_ros.nav.heading_turns import SPAN_S, TURN_EVIDENCE, HeadingTurns


def drive(duration=120.0, rate=5.0):
    """Stamps and the true azimuth of a car that stands 20 s, then drives with a 90 deg turn to
    the right every 20 s (over 6 s each), rad clockwise from north."""
    t = np.arange(0.0, duration, 1.0 / rate)
    turning = (t > 20.0) & ((t - 20.0) % 20.0 > 14.0)
    return t, 1.0 + np.cumsum(turning * np.radians(15.0) / rate)


def feed(turns, t, source, gyro):
    """The readings in turn; the stamp of the verdict (nan: none)."""
    for ti, a, g in zip(t, source, gyro):
        if turns.add(ti, float(a) % (2.0 * math.pi), float(g)):
            return ti
    return math.nan


def test_a_heading_of_the_body_turns_once_per_gyro_turn():
    """An AHRS's heading with an offset (its bias, the declination) and 1 deg of white noise,
    against gyros with a 0.5 deg/s bias and 1 % scale error: k near 1, no verdict."""
    rng = np.random.default_rng(1)
    t, azimuth = drive()
    source = azimuth + 0.3 + np.radians(1.0) * rng.standard_normal(len(t))
    gyro = 1.01 * azimuth - np.radians(0.5) * t
    turns = HeadingTurns()
    assert np.isnan(feed(turns, t, source, gyro)) and not turns.against
    k, sigma = turns.scale()
    assert k == pytest.approx(1.0 / 1.01, abs=3.0 * sigma) and sigma < 0.05
    assert turns.summary().startswith("turns +0.9")


def test_a_mirrored_heading_is_told_at_the_first_corner():
    """The same heading published in NED and read as ENU (pi/2 - azimuth): k = -1 once the
    first corner has turned the gyros by TURN_EVIDENCE beyond their drift."""
    rng = np.random.default_rng(2)
    t, azimuth = drive()
    source = math.pi / 2.0 - azimuth + np.radians(1.0) * rng.standard_normal(len(t))
    turns = HeadingTurns()
    verdict = feed(turns, t, source, azimuth - np.radians(0.5) * t)
    assert 20.0 + 14.0 < verdict < 40.0 and turns.against
    assert turns.scale()[0] == pytest.approx(-1.0, abs=0.1)
    assert turns.evidence() >= TURN_EVIDENCE
    assert "against the body's turns" in turns.summary()


def test_a_standstill_or_gyros_in_degrees_bring_no_verdict():
    """A gyro bias alone (a car standing) is no turn, and gyros 57 x too large (rates in deg/s,
    the IMU timing check's to tell) give a k near zero, not below it."""
    t = np.arange(0.0, 300.0, 0.2)
    turns = HeadingTurns()
    assert np.isnan(feed(turns, t, np.full(len(t), 2.0), np.radians(3.0) * t))
    assert turns.evidence() < 1e-9
    t, azimuth = drive()
    turns = HeadingTurns()
    assert np.isnan(feed(turns, t, azimuth, np.degrees(azimuth)))
    assert 0.0 < turns.scale()[0] < 0.05


def test_no_change_is_taken_across_a_restart_or_within_a_span():
    turns = HeadingTurns()
    turns.add(0.0, 0.0, 0.0)
    assert not turns.add(0.5 * SPAN_S, 1.0, -1.0)  # within a span: not a change
    turns.restart()
    turns.add(10.0, 3.0, 50.0)  # a new anchor: the jump of the gyros' azimuth is not a turn
    turns.add(10.0 + SPAN_S, 3.0, 50.0)
    assert turns.evidence() == 0.0 and turns.summary().startswith("not measured yet")
