"""trial/installation.py and profile_with_installation: a recording's /tf_static places its IMU
and antenna frames in base_link, and a replay takes what the profile leaves at zero."""
from __future__ import annotations

import json
import subprocess
import sys

import numpy as np
import pytest
from conftest import REPO

from ins_gnss_ros.trial.offline import replay_offline
from ins_gnss_ros.trial.profile import load_profile, profile_with_installation
from ins_gnss_ros.trial.simulate import SimOptions, simulate


@pytest.fixture(scope="module")
def mounted(tmp_path_factory):
    """A simulated 10 s drive as an IMU mounted rolled 180 deg and yawed 90 deg records it,
    with base_link -> imu_link and base_link -> gnss on /tf_static (bench/driver_quirks.py)."""
    tmp = tmp_path_factory.mktemp("mounted")
    sim = simulate("car", 10.0, 3, tmp / "sim", SimOptions())
    subprocess.run([sys.executable, str(REPO / "bench" / "driver_quirks.py"), str(sim),
                    str(tmp / "bag"), "imu_mounted_tf"], check=True, cwd=REPO)
    return tmp / "bag"


def test_a_profile_leaving_the_installation_at_zero_takes_the_recording_s(mounted, tmp_path):
    profile, notes = profile_with_installation(
        load_profile(REPO / "config" / "default.yaml"), mounted, tmp_path / "profile.yaml")
    pre, ekf = profile.sections["imu_preprocessor"], profile.sections["ekf"]
    np.testing.assert_allclose(pre["mounting_rpy_deg"], [180.0, 0.0, 90.0], atol=1e-6)
    np.testing.assert_allclose(ekf["lever_arm"], SimOptions.antenna_lever_arm, atol=1e-9)
    assert profile.path == tmp_path / "profile.yaml"
    assert notes == [
        "imu_preprocessor mounting_rpy_deg [180.0, -0.0, 90.0]: from the bag's /tf_static",
        "ekf lever_arm [0.0, 0.0, 1.5]: from the bag's /tf_static"]
    # a profile that gives them keeps its own, and says what the recording gives
    kept, notes = profile_with_installation(load_profile(REPO / "config" / "car.yaml"), mounted)
    assert kept.sections == load_profile(REPO / "config" / "car.yaml").sections
    assert notes[0].startswith("imu_preprocessor mounting_rpy_deg: the profile's kept")


def test_an_offline_replay_navigates_in_base_link_with_the_recording_s_mounting(mounted,
                                                                                tmp_path):
    """The rotated IMU, mounted by the recording's /tf_static: the filter levels in base_link
    (roll and pitch of the simulated car, a few degrees), where without it it publishes the
    sensor's attitude (roll 180 deg) as base_link's."""
    summary = replay_offline(mounted, REPO / "config" / "default.yaml", tmp_path / "out")
    assert summary["installation"][0].endswith("from the bag's /tf_static")
    assert json.loads((tmp_path / "out" / "replay.json").read_text())["installation"] == \
        summary["installation"]
    from ins_gnss_ros import io
    from ins_gnss_ros.nav.rotations import quat_to_euler

    states = [m.msg for m in io.read_bag(tmp_path / "out" / "bag", ["/ins/state"])
              if m.msg.correction_sequence > 0]
    roll = [quat_to_euler(np.array([s.orientation.w, s.orientation.x, s.orientation.y,
                                    s.orientation.z]))[0] for s in states]
    assert len(roll) > 100 and np.max(np.abs(np.degrees(roll))) < 5.0
