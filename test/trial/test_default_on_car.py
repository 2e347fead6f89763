"""config/default.yaml on the bundled real car drive, whose IMU log is stamped about 190 ms off
GNSS time (bags/README.md; the source's own mapping gives 125 ms): the ekf's /diagnostics must
not say OK while it navigates on an IMU that its turn check finds off the fixes' clock."""
import re

from diagnostic_msgs.msg import DiagnosticStatus

from conftest import REPO
from ins_gnss_ros import io as bagio
from ins_gnss_ros.trial.replay import replay


def test_an_imu_stamped_off_gnss_time_turns_the_ekf_diagnostics_to_warn(tmp_path):
    replay(REPO / "bags" / "car_drive_0708", REPO / "config" / "default.yaml", tmp_path / "out")
    ekf = [s for m in bagio.read_bag(tmp_path / "out" / "bag", ["/diagnostics"])
           for s in m.msg.status if s.name.endswith("ekf")]
    warned = [s for s in ekf if "IMU from turns" in s.message]
    assert warned and all(s.level == DiagnosticStatus.WARN for s in warned)
    last = warned[-1].message
    assert last.startswith("navigating; IMU from turns: ") and \
        "add it to imu_preprocessor time_offset_s" in last, last
    offset_ms = int(re.search(r"IMU from turns: ([+-]\d+) \+- (\d+) ms", last).group(1))
    assert -210 <= offset_ms <= -170
    # before the turns tell (the first minutes), navigating is OK
    assert any(s.level == DiagnosticStatus.OK and s.message == "navigating" for s in ekf)
