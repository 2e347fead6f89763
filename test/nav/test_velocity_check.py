"""nav/velocity_check.py: a receiver velocity in NED or in the vehicle's axes disagrees with the
receiver's own fixes; one in ENU agrees, with single-point fix noise."""
import math

import numpy as np
import pytest

from ins_gnss_ros.nav.velocity_check import VelocityAgreement


def drive(frame, fix_sigma=3.0, seconds=60.0, rate=5.0, seed=1):
    """A car at 12 m/s turning slowly (heading 30 deg + 40 deg over the drive), fixes with
    ``fix_sigma`` m of white noise, its velocity as a receiver in ``frame`` would publish it
    (ENU east-north, "ned" north-east, "body" forward-left). Returns the check."""
    rng = np.random.default_rng(seed)
    check = VelocityAgreement()
    position = np.zeros(2)
    for k in range(int(seconds * rate) + 1):
        t = k / rate
        heading = math.radians(30.0 + 40.0 * t / seconds)  # from east, counter-clockwise
        v = 12.0 * np.array([math.cos(heading), math.sin(heading)])
        if k:
            position += v / rate  # (the turn is slow: the chord is the arc)
        published = {"enu": v, "ned": v[::-1], "body": np.array([12.0, 0.0])}[frame]
        check.velocity(t, *(published + rng.normal(0.0, 0.05, 2)))
        check.fix(t, *(position + rng.normal(0.0, fix_sigma, 2)), fix_sigma)
    return check


def test_an_enu_velocity_agrees_with_noisy_fixes():
    for seed in range(5):
        check = drive("enu", seed=seed)
        assert not check.disagrees and check.problem() is None


@pytest.mark.parametrize("frame, says", [("ned", "published in NED?"),
                                         ("body", "not ENU (the vehicle's axes? NED?)")])
def test_a_velocity_in_another_frame_disagrees_and_says_which(frame, says):
    check = drive(frame)
    assert check.disagrees
    assert check.problem().startswith("integrated over 5 s misses the fixes' displacement by")
    assert check.problem().endswith(says) or says in check.problem()


def test_too_short_a_drive_gives_no_verdict():
    check = drive("ned", seconds=12.0)  # two windows
    assert not check.disagrees


def test_a_window_with_a_gap_in_the_velocities_is_not_judged():
    check = VelocityAgreement()
    for k in range(0, 101):  # 20 s at 5 Hz, NED, velocities missing from 2 to 4 s of each 5 s
        t = 0.2 * k
        if not 2.0 < t % 5.0 < 4.0:
            check.velocity(t, 0.0, 12.0)
        check.fix(t, 12.0 * t, 0.0, 1.0)
    assert not check.disagrees
