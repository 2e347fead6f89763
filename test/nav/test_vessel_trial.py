"""The vessel in waves (bags/vessel_waves, smsfusion's ains_ahrs_imu.parquet) through the
product's offline path (``trial replay --offline`` with config/sea_demo.yaml).

Truth is the OrcaFlex simulation's own attitude and position, evaluated as ``trial evaluate``
does; the windows and statistics are bench/bench_vessel.py's. The bounds are the issue-5 targets
(what smsfusion's AidedINS reaches on the same data: roll 0.036, pitch 0.020, heading 0.013 deg,
position 0.05 m RMS after 30 s) and the numbers achieved here with a margin, for each half of
the run separately.
"""
import importlib.util
import sys

import numpy as np
import pytest
from conftest import REPO, shared_path

from ins_gnss_ros.nav.earth import earth_rate_enu
from ins_gnss_ros.nav.rotations import quat_to_dcm
from ins_gnss_ros.trial.evaluate import evaluate
from ins_gnss_ros.trial.offline import forward_pass, replay_offline
from ins_gnss_ros.trial.report import load_run
from ins_gnss_ros.trial.vessel import load_vessel


sys.path.insert(0, str(REPO / "bench"))  # bench_vessel runs the trial commands of product_path


def _bench():
    path = REPO / "bench" / "bench_vessel.py"
    spec = importlib.util.spec_from_file_location("bench_vessel", path)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


BENCH = _bench()


@pytest.fixture(scope="module")
def trial(tmp_path_factory):
    out = tmp_path_factory.mktemp("vessel") / "offline"
    replay_offline(REPO / BENCH.BAG, REPO / BENCH.CONFIG, out)
    run = load_run(out)
    return run.truth, evaluate(run.estimate, run.truth, published=run.published).errors


# Per window: bound on roll, pitch, heading (deg RMS), 3-D position (m RMS). Achieved offline
# (docs/results/vessel.md): first half 0.0057 0.0057 0.0114 0.018, second half 0.0079 0.0101
# 0.0116 0.021; the heading bound is the target itself.
BOUNDS = {"first half (tuned)": (0.008, 0.008, 0.013, 0.025),
          "second half": (0.011, 0.013, 0.013, 0.027)}


@pytest.mark.parametrize("window", sorted(BOUNDS))
def test_accuracy_meets_target(trial, window):
    truth, errors = trial
    start, end = BENCH.windows(truth.time)[window]
    r = BENCH.error_rms(errors, start, end)
    roll, pitch, heading, pos = BOUNDS[window]
    assert r["roll"] < min(roll, 0.036)
    assert r["pitch"] < min(pitch, 0.020)
    assert r["heading"] < min(heading, 0.013)
    assert r["pos3d"] < min(pos, 0.05)
    # The attitude covariance is about right (NEES mean near the dimension 3).
    assert 1.0 < r["nees_att"] < 5.0


def test_gyro_bias_state_absorbs_missing_earth_rate():
    """The simulation's gyros do not sense the Earth rate the navigator removes: at a steady
    heading that is a constant body-axis offset, which the gyro-bias state must take up exactly
    (minus the Earth rate in body axes plus the sensor's own bias, averaged over the last 2 min)."""
    vessel = load_vessel(shared_path("data", "vessel_waves", "ains_ahrs_imu.parquet"))
    last = vessel.time >= vessel.time[-1] - 120.0
    c_nb = np.stack([quat_to_dcm(q) for q in vessel.truth.q_nb[last]])
    earth_b = np.einsum("nji,j->ni", c_nb, earth_rate_enu(vessel.datum[0])).mean(axis=0)
    sensor_bias = (vessel.gyro_flu - vessel.gyro_flu_true)[last].mean(axis=0)
    # The offline path's gyro-bias estimate over the same last 2 min (its ins/state leaves the
    # sensor-error fields empty: the navigator's record has them).
    out = forward_pass(REPO / BENCH.BAG, REPO / BENCH.CONFIG).navigator.output()
    estimate = out.estimates["bg"][out.t >= out.t[-1] - 120.0].mean(axis=0)
    assert np.linalg.norm(earth_b) > 5e-5
    assert np.abs(estimate - (sensor_bias - earth_b)).max() < 1e-5
    # Without the Earth rate the expectation would be off by far more than that.
    assert np.abs(estimate - sensor_bias).max() > 2e-5
