"""The vessel in waves (smsfusion's ains_ahrs_imu.parquet) through the offline navigator.

Truth is the OrcaFlex simulation's own attitude and position. The navigator runs with the
benchmark's configuration (bench/bench_vessel.py, tuned on the first half only), position and
compass aiding at 10.24 Hz; the bounds are the issue-5 targets (what smsfusion's AidedINS reaches
on the same data: roll 0.036, pitch 0.020, heading 0.013 deg, position 0.05 m RMS after 30 s) and
the numbers achieved here with a margin, for each half of the run separately.
"""
import importlib.util

import numpy as np
import pytest
from conftest import REPO, shared_path

from ins_gnss_ros.nav.earth import earth_rate_enu
from ins_gnss_ros.nav.rotations import quat_to_dcm
from ins_gnss_ros.trial.evaluate import evaluate
from ins_gnss_ros.trial.vessel import load_vessel


def _bench():
    path = REPO / "bench" / "bench_vessel.py"
    spec = importlib.util.spec_from_file_location("bench_vessel", path)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


BENCH = _bench()


@pytest.fixture(scope="module")
def trial():
    vessel = load_vessel(shared_path("data", "vessel_waves", "ains_ahrs_imu.parquet"))
    out = BENCH.run_navigator(vessel, BENCH.vessel_config())
    return vessel, out, evaluate(BENCH.navigator_trajectory(out), vessel.truth).errors


# Per window: bound on roll, pitch, heading (deg RMS), 3-D position (m RMS). Achieved
# (docs/results/vessel.md): first half 0.0057 0.0057 0.0115 0.018, second half 0.0079 0.0101
# 0.0116 0.021; the heading bound is the target itself.
BOUNDS = {"first half (tuned)": (0.008, 0.008, 0.013, 0.025),
          "second half": (0.011, 0.013, 0.013, 0.027)}


@pytest.mark.parametrize("window", sorted(BOUNDS))
def test_accuracy_meets_target(trial, window):
    vessel, _, errors = trial
    start, end = BENCH.windows(vessel.time)[window]
    r = BENCH.error_rms(errors, start, end)
    roll, pitch, heading, pos = BOUNDS[window]
    assert r["roll"] < min(roll, 0.036)
    assert r["pitch"] < min(pitch, 0.020)
    assert r["heading"] < min(heading, 0.013)
    assert r["pos3d"] < min(pos, 0.05)
    # The attitude covariance is about right (NEES mean near the dimension 3).
    assert 1.0 < r["nees_att"] < 5.0


def test_gyro_bias_state_absorbs_missing_earth_rate(trial):
    """The simulation's gyros do not sense the Earth rate the navigator removes: at a steady
    heading that is a constant body-axis offset, which the gyro-bias state must take up exactly
    (minus the Earth rate in body axes plus the sensor's own bias, averaged over the last 2 min)."""
    vessel, out, _ = trial
    t_last = vessel.time[-1] - 120.0
    last = vessel.time >= t_last
    c_nb = np.stack([quat_to_dcm(q) for q in vessel.truth.q_nb[last]])
    earth_b = np.einsum("nji,j->ni", c_nb, earth_rate_enu(vessel.datum[0])).mean(axis=0)
    sensor_bias = (vessel.gyro_flu - vessel.gyro_flu_true)[last].mean(axis=0)
    estimate = out.estimates["bg"][out.t >= t_last].mean(axis=0)
    assert np.linalg.norm(earth_b) > 5e-5
    assert np.abs(estimate - (sensor_bias - earth_b)).max() < 1e-5
    # Without the Earth rate the expectation would be off by far more than that.
    assert np.abs(estimate - sensor_bias).max() > 2e-5


def test_point_samples_become_trapezoid_increments():
    """A rate ramp w(t) = a t sampled at t_k integrates to a (t_k^2 - t_k-1^2) / 2 exactly."""
    dt, a = 0.1, np.array([0.3, -0.2, 0.05])
    t = dt * np.arange(1, 6)
    got = BENCH.increments(a * t[:, None], dt)
    assert np.allclose(got[1:], a * (t[1:, None] ** 2 - t[:-1, None] ** 2) / 2.0)
