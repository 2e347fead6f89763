"""Evaluation metrics on synthetic trajectories with known injected errors.

Offsets are applied with pymap3d (an independent geodesy implementation), attitudes are built
from Euler angles with scipy, so the expected errors are known without using the code under test.
"""
import json

import numpy as np
import pymap3d
import pytest
from scipy.spatial.transform import Rotation

from ins_gnss_ros.trial.evaluate import (Trajectory, euler_error_jacobian, evaluate, interpolate,
                                         markdown_table)

LAT0, LON0, H0 = np.radians(45.0), np.radians(10.0), 100.0


def _quat(roll, pitch, yaw):
    """q_nb [w, x, y, z] for C = Rz(yaw) Ry(pitch) Rx(roll) via scipy (scalar-last internally)."""
    xyzw = Rotation.from_euler("ZYX", np.column_stack([yaw, pitch, roll])).as_quat()
    return xyzw[:, [3, 0, 1, 2]]


def _circle(t, radius=200.0, period=120.0, yaw_offset=0.0):
    """Truth: a level circle driven counter-clockwise, yaw along the track."""
    w = 2 * np.pi / period
    east, north = radius * np.cos(w * t), radius * np.sin(w * t)
    lat, lon, h = pymap3d.enu2geodetic(east, north, 0.0 * t, LAT0, LON0, H0, deg=False)
    vel = np.column_stack([-radius * w * np.sin(w * t), radius * w * np.cos(w * t), 0 * t])
    yaw = w * t + np.pi / 2 + yaw_offset
    return Trajectory(time=t, lat=lat, lon=lon, height=h, vel_enu=vel,
                      q_nb=_quat(0 * t, 0 * t, yaw))


def _shift(trajectory, east=0.0, north=0.0, up=0.0):
    """The trajectory moved by a local ENU offset at every epoch (pymap3d)."""
    lat, lon, h = pymap3d.enu2geodetic(east, north, up, trajectory.lat, trajectory.lon,
                                       trajectory.height, deg=False)
    return Trajectory(**{**vars(trajectory), "lat": lat, "lon": lon, "height": h})


def test_constant_east_offset():
    truth = _circle(np.arange(0.0, 60.0, 0.25))
    result = evaluate(_shift(truth, east=1.0), truth)
    assert result.stats["horizontal_m"].rms == pytest.approx(1.0, abs=1e-6)
    assert result.stats["horizontal_m"].max == pytest.approx(1.0, abs=1e-6)
    assert result.stats["vertical_m"].max < 1e-6
    assert np.allclose(result.errors.pos_enu, [1.0, 0.0, 0.0], atol=1e-6)
    assert result.stats["heading_deg"].max < 1e-9
    up = evaluate(_shift(truth, up=-2.0, north=3.0), truth)
    assert up.stats["vertical_m"].rms == pytest.approx(2.0, abs=1e-6)
    assert up.stats["horizontal_m"].p95 == pytest.approx(3.0, abs=1e-6)


def test_heading_offset_across_north():
    t = np.arange(0.0, 20.0, 0.1)
    # Azimuth 359.8 deg true (yaw = 90.2 deg), 0.3 deg estimated: +0.5 deg across the wrap.
    yaw_true = np.full_like(t, np.radians(90.2))
    truth = Trajectory(time=t, lat=np.full_like(t, LAT0), lon=np.full_like(t, LON0),
                       height=np.full_like(t, H0), q_nb=_quat(0 * t, 0 * t, yaw_true))
    est = Trajectory(**{**vars(truth), "q_nb": _quat(0 * t, 0 * t, yaw_true - np.radians(0.5))})
    result = evaluate(est, truth)
    assert np.allclose(np.degrees(result.errors.euler[:, 2]), 0.5, atol=1e-9)
    assert result.stats["heading_deg"].rms == pytest.approx(0.5, abs=1e-9)
    assert result.stats["roll_deg"].max < 1e-9 and result.stats["pitch_deg"].max < 1e-9
    # The rotation vector of q_est q_true* is -0.5 deg about up (clockwise turn).
    assert np.allclose(np.degrees(result.errors.att_rotvec), [0, 0, -0.5], atol=1e-9)


def test_roll_pitch_offsets():
    truth = _circle(np.arange(0.0, 30.0, 0.2))
    roll, pitch, yaw = Rotation.from_quat(truth.q_nb[:, [1, 2, 3, 0]]).as_euler("ZYX").T[::-1]
    est = Trajectory(**{**vars(truth), "q_nb": _quat(roll + np.radians(2.0),
                                                     pitch - np.radians(1.0), yaw)})
    result = evaluate(est, truth)
    assert result.stats["roll_deg"].rms == pytest.approx(2.0, abs=1e-6)
    assert result.stats["pitch_deg"].rms == pytest.approx(1.0, abs=1e-6)
    assert np.allclose(np.degrees(result.errors.euler[:, 1]), -1.0, atol=1e-6)
    assert result.stats["heading_deg"].max < 1e-6


def test_interpolation_in_time():
    # Estimate sampled at other instants than truth; motion on the circle is smooth, so linear
    # position and slerp attitude interpolation errors are second order in the step.
    truth = _circle(np.arange(0.0, 40.0, 0.25))
    est = _circle(np.arange(-0.013, 41.0, 0.01))
    result = evaluate(est, truth)
    assert result.stats["horizontal_m"].max < 1e-3   # r (w dt)^2 / 8 ~ 5e-5 m
    assert result.stats["heading_deg"].max < 1e-9    # slerp is exact for a constant rate
    assert result.stats["velocity_horizontal_mps"].max < 1e-3
    sampled = interpolate(est, np.array([10.0]))
    assert np.allclose(sampled.q_nb, truth.q_nb[40], atol=1e-12) or np.allclose(
        sampled.q_nb, -truth.q_nb[40], atol=1e-12)


def test_gaps_and_span():
    truth = _circle(np.arange(0.0, 30.0, 0.25))
    t = np.concatenate([np.arange(5.0, 10.0, 0.1), np.arange(15.0, 20.0, 0.1)])
    result = evaluate(_circle(t), truth)
    evaluated = result.errors.time
    assert evaluated.min() >= 5.0 and evaluated.max() <= 19.9 + 1e-9
    assert not np.any((evaluated > 9.9 + 1e-9) & (evaluated < 15.0))
    with pytest.raises(ValueError, match="span"):
        evaluate(_circle(np.arange(100.0, 110.0, 0.1)), truth)


def test_outage_drift():
    t = np.arange(0.0, 100.0, 0.25)
    truth = _circle(t)
    windows = np.array([[10.0, 25.0], [55.0, 70.0]])
    # Error grows as 0.02 (t - start)^2 east inside each window, zero outside.
    growth = np.zeros_like(t)
    for start, end in windows:
        inside = (t >= start) & (t < end)
        growth[inside] = 0.02 * (t[inside] - start) ** 2 * (1 if start < 50 else 2)
    result = evaluate(_shift(truth, east=growth), truth, windows=windows)
    last = 0.02 * (15.0 - 0.25) ** 2
    assert [o.max_horizontal_m for o in result.outages] == pytest.approx([last, 2 * last], abs=1e-6)
    assert [o.end_horizontal_m for o in result.outages] == pytest.approx([last, 2 * last], abs=1e-6)
    out = result.to_json()
    assert out["outage_drift_max_m"] == pytest.approx(2 * last, abs=1e-6)
    assert out["outage_drift_rms_m"] == pytest.approx(np.sqrt((last ** 2 + 4 * last ** 2) / 2),
                                                      abs=1e-6)
    assert len(out["outages"]) == 2
    table = markdown_table(result)
    assert "| 2 | 55.0 | 15.0 |" in table and "RMS / max" in table


def test_constant_offset_of_the_truth_is_removed_and_window_changes_measured():
    """A truth 6 m off (an RTK base of unknown coordinates) and an estimate with a zero-mean
    1 m east oscillation: without the offset the RMS is the oscillation's; the change of the
    error within a window is the same with or without it (it does not see constant errors)."""
    t = np.arange(0.0, 100.0, 0.25)
    truth = _circle(t)
    wiggle = np.sqrt(2.0) * np.sin(2 * np.pi * t / 10.0)  # RMS 1 m, mean 0 over whole periods
    windows = np.array([[10.0, 12.5]])
    estimate = _shift(truth, east=wiggle - 4.0, north=3.0, up=1.0)
    result = evaluate(estimate, truth, windows=windows, remove_offset=True)
    assert result.offset_enu == pytest.approx([-4.0, 3.0, 1.0], abs=1e-6)
    assert result.stats["horizontal_m"].rms == pytest.approx(1.0, abs=1e-6)
    assert result.stats["vertical_m"].max < 1e-6
    inside = (t >= 10.0) & (t < 12.5)
    change = np.abs(wiggle[inside] - wiggle[inside][0]).max()
    for r in (result, evaluate(estimate, truth, windows=windows)):
        assert r.outages[0].max_change_m == pytest.approx(change, abs=1e-6)
    out = result.to_json()
    assert out["removed_offset_enu_m"] == pytest.approx([-4.0, 3.0, 1.0], abs=1e-6)
    assert out["outage_change_rms_m"] == pytest.approx(change, abs=1e-6)
    assert "removed_offset_enu_m" not in evaluate(estimate, truth).to_json()


def test_json_contract_keys():
    truth = _circle(np.arange(0.0, 20.0, 0.25))
    out = evaluate(_shift(truth, east=1.0), truth).to_json()
    for key in ("horizontal_rms_m", "vertical_rms_m", "roll_rms_deg", "pitch_rms_deg",
                "heading_rms_deg"):
        assert isinstance(out[key], float)
    assert "outage_drift_rms_m" not in out
    json.dumps(out)
    # Truth without attitude: attitude statistics are null, not errors.
    bare = Trajectory(**{**vars(truth), "q_nb": None, "vel_enu": None})
    out = evaluate(truth, bare, windows=np.array([[100.0, 110.0]])).to_json()
    assert out["heading_rms_deg"] is None and out["velocity_horizontal_rms_mps"] is None
    assert out["outage_drift_max_m"] is None
    json.dumps(out)


def test_nees_consistent_filter():
    rng = np.random.default_rng(1)
    t = np.arange(0.0, 2000.0, 0.2)
    truth = _circle(t, radius=500.0, period=600.0)
    n = len(t)
    pos_cov = np.diag([1.0, 4.0, 9.0])
    vel_cov = np.array([[0.04, 0.01, 0.0], [0.01, 0.09, 0.0], [0.0, 0.0, 0.01]])
    att_cov = np.diag(np.radians([0.1, 0.2, 1.0]) ** 2)
    dpos = rng.multivariate_normal(np.zeros(3), pos_cov, n)
    dvel = rng.multivariate_normal(np.zeros(3), vel_cov, n)
    phi = rng.multivariate_normal(np.zeros(3), att_cov, n)
    # q_est = exp(phi) q_true with phi resolved in ENU (left multiplication, via scipy).
    true_rot = Rotation.from_quat(truth.q_nb[:, [1, 2, 3, 0]])
    q_est = (Rotation.from_rotvec(phi) * true_rot).as_quat()[:, [3, 0, 1, 2]]
    est = _shift(truth, *dpos.T)
    est = Trajectory(**{**vars(est), "vel_enu": truth.vel_enu + dvel, "q_nb": q_est,
                        "pos_cov_enu": np.broadcast_to(pos_cov, (n, 3, 3)),
                        "vel_cov_enu": np.broadcast_to(vel_cov, (n, 3, 3)),
                        "att_cov": np.broadcast_to(att_cov, (n, 3, 3))})
    result = evaluate(est, truth)
    # Mean of n chi-square(3) samples: 3 +- sqrt(6 / n) (0.024 here).
    for name in ("position", "velocity", "attitude"):
        assert result.nees[name] == pytest.approx(3.0, abs=0.07), name
    assert np.allclose(result.errors.att_rotvec, phi, atol=1e-9)
    assert np.allclose(result.errors.pos_sigma, [1.0, 2.0, 3.0])
    # Euler-error sigmas follow from the attitude covariance; empirical std must match them.
    assert np.std(result.errors.euler, axis=0) == pytest.approx(
        np.sqrt(np.mean(result.errors.euler_sigma ** 2, axis=0)), rel=0.05)
    # An over-confident filter (covariance 4x too small) shows NEES about 4x too large.
    small = Trajectory(**{**vars(est), "pos_cov_enu": est.pos_cov_enu / 4})
    assert evaluate(small, truth).nees["position"] == pytest.approx(12.0, rel=0.05)


def test_euler_error_jacobian():
    rng = np.random.default_rng(2)
    roll, pitch = rng.uniform(-0.5, 0.5, 20), rng.uniform(-1.0, 1.0, 20)
    yaw = rng.uniform(-3.0, 3.0, 20)
    q = _quat(roll, pitch, yaw)
    phi = rng.normal(0, 1e-6, (20, 3))
    perturbed = Rotation.from_rotvec(phi) * Rotation.from_quat(q[:, [1, 2, 3, 0]])
    yaw2, pitch2, roll2 = perturbed.as_euler("ZYX").T
    # Numerical Euler differences (azimuth = -yaw change) vs the linear map.
    numeric = np.column_stack([roll2 - roll, pitch2 - pitch, -(yaw2 - yaw)])
    linear = np.einsum("nij,nj->ni", euler_error_jacobian(q), phi)
    assert np.allclose(numeric, linear, atol=1e-11)


def test_nees_leaves_out_epochs_without_a_covariance():
    t = np.arange(0.0, 100.0, 0.5)
    truth = _circle(t)
    est = _shift(truth, east=1.0)
    pos_cov = np.broadcast_to(np.eye(3), (len(t), 3, 3)).copy()
    pos_cov[:10] = np.nan  # e.g. the strapdown's start-up states, before the filter published
    est = Trajectory(**{**vars(est), "pos_cov_enu": pos_cov})
    assert evaluate(est, truth).nees["position"] == pytest.approx(1.0)


def test_nees_is_also_given_inside_and_outside_the_outages():
    """A covariance that holds inside the outages and is 4x too small outside them (as against
    a truth that shares the aiding's errors): the split shows it, the mean over all does not."""
    t = np.arange(0.0, 100.0, 0.5)
    truth = _circle(t)
    windows = np.array([[20.0, 40.0], [60.0, 80.0]])
    inside = ((t >= 20.0) & (t < 40.0)) | ((t >= 60.0) & (t < 80.0))
    pos_cov = np.broadcast_to(np.eye(3), (len(t), 3, 3)).copy()
    pos_cov[~inside] /= 4.0
    est = Trajectory(**{**vars(_shift(truth, east=1.0)), "pos_cov_enu": pos_cov})
    result = evaluate(est, truth, windows=windows)
    assert result.nees_by_aiding["inside"]["position"] == pytest.approx(1.0)
    assert result.nees_by_aiding["outside"]["position"] == pytest.approx(4.0)
    assert result.nees["position"] == pytest.approx(0.4 * 1.0 + 0.6 * 4.0)
    out = result.to_json()
    assert out["nees_position_inside_outages_mean"] == pytest.approx(1.0)
    assert out["nees_velocity_outside_outages_mean"] is None  # no velocity covariance
    assert "| inside the outages | 1.00 |" in markdown_table(result)
    assert evaluate(est, truth).nees_by_aiding == {}


def test_odometry_covariance_is_attached_only_near_published_messages():
    from nav_msgs.msg import Odometry

    from ins_gnss_ros.io import BagMessage, sec_to_stamp
    from ins_gnss_ros.trial.export import attach_odometry_covariance

    t = np.arange(0.0, 10.0, 0.1)
    estimate = _circle(t)
    messages = []
    # published from 2 s to 6 s only, with a 1 s gap after 3.95 s: no covariance is carried
    # across it (held or interpolated, it would vouch for states no filter published)
    stamps = np.round(np.arange(2.0, 6.0, 0.05), 2)
    stamps = stamps[(stamps < 3.96) | (stamps > 4.94)]
    for ts in stamps:
        odom = Odometry()
        odom.header.stamp = sec_to_stamp(ts)
        odom.pose.covariance = (np.eye(6) * 4.0).flatten().tolist()
        odom.twist.covariance = np.eye(6).flatten().tolist()
        messages.append(BagMessage("/nav/odom", int(round(ts * 1e9)), odom))
    out = attach_odometry_covariance(estimate, messages, 0)
    known = np.isfinite(out.pos_cov_enu[:, 0, 0])
    published = ((t >= 2.0 - 1e-9) & (t <= 3.95 + 1e-9)) | ((t >= 4.95 - 1e-9) & (t <= 5.95))
    assert np.array_equal(known, published)
    assert np.allclose(out.pos_cov_enu[known], 4.0 * np.eye(3))


def test_nees_judges_the_published_solution_with_its_own_covariance():
    """The estimate between the filter's outputs (the strapdown's states) may lack an update
    that the published covariance follows: the NEES is of the published solution's own
    state, the statistics of the estimate's; truth epochs its samples do not bracket within
    PUBLISHED_MAX_GAP_S get none."""
    from ins_gnss_ros.trial.evaluate import PUBLISHED_MAX_GAP_S

    truth = _circle(np.linspace(0.0, 19.9, 399))
    estimate = _shift(truth, east=0.5)
    # published at 10 Hz 0.1 m east with a 0.1 m sigma on each axis, with a gap from 8 s
    t = np.round(np.arange(0.0, 20.0, 0.1), 6)
    t = t[(t < 8.0) | (t > 8.0 + 2 * PUBLISHED_MAX_GAP_S)]
    published = _shift(_circle(t), east=0.1)
    published = Trajectory(**{**vars(published), "pos_cov_enu": np.broadcast_to(
        0.01 * np.eye(3), (len(t), 3, 3))})
    result = evaluate(estimate, truth, published=published)
    assert result.stats["horizontal_m"].rms == pytest.approx(0.5, abs=1e-6)
    nees = result.errors.nees_pos
    gap = (truth.time > t[t < 8.0][-1] + 1e-9) & (truth.time < t[t > 8.0][0] + 1e-9)
    assert np.isnan(nees[gap]).all() and np.isfinite(nees[~gap]).all()
    # (between its samples, the chord of the circle: within 2 %)
    assert nees[~gap] == pytest.approx(1.0, abs=0.02)
    assert np.allclose(result.errors.pos_sigma[~gap], 0.1)
    # the estimate's mean error taken out of the published solution's as well
    off = evaluate(estimate, truth, remove_offset=True, published=published)
    assert off.nees["position"] == pytest.approx(0.4 ** 2 / 0.01, rel=0.02)


def test_published_solution_of_fix_and_odometry():
    """nav/fix positions (deg) with the attitude, body velocity turned into ENU and the
    covariances of the nav/odom of the same stamp; an odometry without its fix is left out."""
    from nav_msgs.msg import Odometry
    from sensor_msgs.msg import NavSatFix

    from ins_gnss_ros.io import BagMessage, sec_to_stamp
    from ins_gnss_ros.trial.report import published_solution

    yaw = np.radians(30.0)  # body x 30 deg left of east
    messages = []
    for ts, with_fix in ((1.0, True), (1.1, False), (1.2, True)):
        stamp = sec_to_stamp(ts)
        odom = Odometry()
        odom.header.stamp = stamp
        odom.pose.pose.orientation.w, odom.pose.pose.orientation.z = np.cos(yaw / 2), np.sin(
            yaw / 2)
        odom.twist.twist.linear.x = 10.0
        odom.pose.covariance = np.diag([1.0, 4.0, 9.0, 1e-4, 2e-4, 3e-4]).flatten().tolist()
        twist = np.zeros((6, 6))
        twist[:3, :3] = np.diag([0.04, 0.01, 0.09])  # along, across, up
        odom.twist.covariance = twist.flatten().tolist()
        messages.append(BagMessage("/nav/odom", int(round(ts * 1e9)), odom))
        if with_fix:
            fix = NavSatFix()
            fix.header.stamp = stamp
            fix.latitude, fix.longitude, fix.altitude = 45.0, 10.0 + ts, 100.0
            messages.append(BagMessage("/nav/fix", int(round(ts * 1e9)), fix))
    sol = published_solution(messages, int(0.5e9))
    assert sol.time == pytest.approx([0.5, 0.7])
    assert sol.lat == pytest.approx(np.radians([45.0, 45.0]))
    assert sol.lon == pytest.approx(np.radians([11.0, 11.2]))
    assert sol.vel_enu[0] == pytest.approx([10 * np.cos(yaw), 10 * np.sin(yaw), 0.0])
    assert np.allclose(sol.pos_cov_enu[0], np.diag([1.0, 4.0, 9.0]))
    assert np.allclose(sol.att_cov[0], np.diag([1e-4, 2e-4, 3e-4]))
    c, s_ = np.cos(yaw), np.sin(yaw)
    east_var = 0.04 * c * c + 0.01 * s_ * s_
    assert sol.vel_cov_enu[0, 0, 0] == pytest.approx(east_var)
    assert sol.vel_cov_enu[0, 2, 2] == pytest.approx(0.09)
    assert published_solution(messages[:2], 0) is None  # one solution: nothing to interpolate


def test_truth_at_the_antenna_and_lagging_velocities_are_referred_to_the_estimate():
    from ins_gnss_ros.nav.lever_arm import lever_arm_position
    from ins_gnss_ros.trial.report import referred_to_truth

    t = np.arange(0.0, 60.0, 0.25)
    base = _circle(t)  # the vehicle's base_link: the estimate, exact
    antenna = np.array([0.5, -0.3, 1.2])
    lat, lon, h = lever_arm_position(base.lat, base.lon, base.height, base.q_nb, antenna)
    delay = 0.25  # the truth's velocity stamped t is the velocity of t - 0.25 s
    late = np.column_stack([np.interp(t - delay, t, v) for v in base.vel_enu.T])
    truth = Trajectory(time=t, lat=lat, lon=lon, height=h, vel_enu=late)
    raw = evaluate(base, truth)
    assert raw.stats["horizontal_m"].rms > 0.4  # the lever arm, seen as error
    est, ref = referred_to_truth(base, truth, antenna, delay)
    result = evaluate(est, ref)
    assert result.stats["horizontal_m"].max < 1e-6
    assert result.stats["velocity_horizontal_mps"].max < 1e-3
