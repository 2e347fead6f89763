"""trial compare: identical bags say so; a changed field is named with its message index."""
import math

from ins_gnss_ros import io as bagio
from ins_gnss_ros.trial import contract_messages as msgs
from ins_gnss_ros.trial.cli import main
from ins_gnss_ros.trial.compare import compare

T0 = 1_767_225_600_000_000_000


def _write(path, azimuth_of_second=1.0):
    with bagio.BagWriter(path) as writer:
        writer.write("gnss/heading", msgs.heading_msg(T0, azimuth=0.5))
        writer.write("gnss/heading", msgs.heading_msg(T0 + 10, azimuth=azimuth_of_second))
        writer.write("gnss/fix", msgs.fix_msg(T0, math.radians(59.9), 0.5, 3.0, [1, 2, 3]))
    return path


def test_identical_bags_compare_identical_nan_fields_included(tmp_path):
    result = compare(_write(tmp_path / "a"), _write(tmp_path / "b"))
    assert result.identical
    assert [(t.topic, t.count_a) for t in result.topics] == [("/gnss/fix", 1),
                                                             ("/gnss/heading", 2)]
    assert main(["compare", str(tmp_path / "a"), str(tmp_path / "b")]) == 0


def test_a_changed_field_is_named(tmp_path, capsys):
    result = compare(_write(tmp_path / "a"), _write(tmp_path / "b", azimuth_of_second=1.5))
    assert not result.identical
    heading = next(t for t in result.topics if t.topic == "/gnss/heading")
    assert heading.first_difference == "message 1: azimuth: 1.0 vs 1.5"
    assert main(["compare", str(tmp_path / "a"), str(tmp_path / "b")]) == 1
    assert "DIFFERENT" in capsys.readouterr().out
