"""The direct carrier-phase update on the product path (issue 17): a simulated 4-antenna sea
trial (``trial simulate --antennas 4 --array 2.7x1.2``) replayed through config/sea_4ant.yaml,
where phase_heading publishes its fixed double differences on gnss/phase_dd and the ekf fuses
them. Truth is the scenario's attitude and the recorded lines of sight, which no node sees.
The 300 s figures are in docs/results/fused_heading.md.
"""
from __future__ import annotations

from collections import Counter

import numpy as np
import pytest
from conftest import REPO

from ins_gnss_ros.nav.rotations import quat_to_dcm
from ins_gnss_ros.trial.inputs import iter_topic
from ins_gnss_ros.trial.replay import replay
from ins_gnss_ros.trial.simulate import SimOptions, array_antennas, simulate

PROFILE = REPO / "config" / "sea_4ant.yaml"
ANTENNAS = np.array(array_antennas(4, 2.7, 1.2, SimOptions.antenna_lever_arm))


@pytest.fixture(scope="module")
def run(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("phase_dd")
    bag = simulate("sea", 30.0, 11, tmp / "sim",
                   SimOptions(imu_grade="mems_adis16405", antennas=4, array=(2.7, 1.2)))
    replay(bag, PROFILE, tmp / "out")
    return bag, tmp / "out" / "bag"


def _truth_attitudes(bag):
    return {m.t_ns: quat_to_dcm(np.array([m.msg.orientation.w, m.msg.orientation.x,
                                          m.msg.orientation.y, m.msg.orientation.z]))
            for m in iter_topic(bag, "truth/state")}


def test_simulated_trial_has_the_raw_gnss_of_every_antenna(run):
    bag, _ = run
    antennas = Counter(m.msg.antenna_id for m in iter_topic(bag, "gnss/observations"))
    assert set(antennas) == {0, 1, 2, 3} and len(set(antennas.values())) == 1
    assert next(iter_topic(bag, "gnss/ephemeris"), None) is not None
    assert next(iter_topic(bag, "gnss/fix"), None) is not None


def test_phase_heading_publishes_the_double_differences_of_the_true_attitude(run):
    bag, out = run
    truth = _truth_attitudes(bag)
    residuals, n = [], 0
    for m in iter_topic(out, "gnss/phase_dd"):
        msg = m.msg
        k = len(msg.value)
        assert k >= 9 and len(msg.covariance) == k * k
        assert set(msg.ambiguity_status) == {msg.AMBIGUITY_FIXED}
        b = np.array([[v.x, v.y, v.z] for v in msg.baseline])
        np.testing.assert_allclose(b, ANTENNAS[list(msg.remote_antenna)] - ANTENNAS[0],
                                   atol=1e-12)
        C = truth[m.t_ns]   # truth at 20 Hz holds every 5 Hz GNSS epoch
        g = np.array([[v.x, v.y, v.z] for v in msg.line_of_sight_difference])
        r = np.asarray(msg.value) - np.einsum("ij,ij->i", g, b @ C.T)
        cov = np.reshape(msg.covariance, (k, k))
        residuals.append(r @ np.linalg.solve(cov, r) / k)
        n += 1
    assert n > 100
    # Fixed integers: the values are the true geometry within the published covariance (a
    # wrong integer would be a 19 cm step).
    assert np.mean(residuals) < 2.0


def test_ekf_fuses_the_double_differences_instead_of_the_heading(run):
    _, out = run
    updates = Counter()
    for m in iter_topic(out, "nav/status"):
        updates.update((u.name, u.accepted) for u in m.msg.updates)
    assert updates[("phase_dd", True)] > 100
    assert updates[("phase_dd", False)] <= 0.01 * updates[("phase_dd", True)]
    assert updates[("heading", True)] == 0    # gnss/heading only aligned the heading
