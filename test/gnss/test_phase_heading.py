"""The phase-heading pipeline around the attitude core: epoch grouping and input checks (the
whole pipeline on simulated and recorded data: test/nodes/test_phase_heading_node.py)."""
import math

import numpy as np

from ins_gnss_ros.gnss.attitude import AttitudeSolver
from ins_gnss_ros.gnss.phase_heading import (AntennaObservations, PhaseHeading,
                                             PhaseHeadingConfig, signal_id)


def _pipeline():
    reports = []
    solver = AttitudeSolver(np.array([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0]]))
    return PhaseHeading(solver, 2, PhaseHeadingConfig(), reports.append), reports


def _obs(antenna, t, tag=None):
    return AntennaObservations(antenna, t, 1000.0 + t, None, False, tag)


def test_epochs_are_grouped_by_gnss_time_and_handed_out_complete_or_given_up():
    ph, reports = _pipeline()
    assert ph.add(_obs(0, 100.0, "m")) == []
    (epoch,) = ph.add(_obs(1, 100.001))           # within epoch_tolerance
    assert sorted(epoch.antennas) == [0, 1] and epoch.tag == "m"
    assert ph.add(_obs(0, 100.002)) == []
    assert ph.add(_obs(0, 101.0)) == [] and ph.add(_obs(0, 101.0)) == []
    assert ph.add(_obs(2, 101.0)) == [] and ph.add(_obs(1, math.nan)) == []
    assert reports == ["late observations (epoch already handled) dropped",
                       "duplicate observations of an antenna in one epoch dropped",
                       "observations with an unknown antenna_id or time dropped",
                       "observations with an unknown antenna_id or time dropped"]
    (late,) = ph.add(_obs(1, 101.6, "s"))         # 101.0 given up after max_latency
    assert late.t_gnss == 101.0 and ph.solve(late).status == "NONE"
    assert reports[-1] == "epoch without every antenna skipped"
    (incomplete,) = ph.add(_obs(0, 102.2))        # the master missing: antenna 1's tag
    assert incomplete.tag == "s"


def test_inputs_with_non_finite_values_are_not_taken():
    ph, _ = _pipeline()
    ph.fix(10.0, math.nan, 0.1, 5.0)
    assert ph.position is None
    assert not ph.ins_state(10.0, 0.9, 0.1, 5.0, [0.0, 0.0, 0.0, 0.0], True, True)
    assert ph.ins_state(10.0, 0.9, 0.1, 5.0, [1.0, 0.0, 0.0, 0.0], True, False)
    assert ph.ins[2] is False and ph.position[0] == 10.0
    ph.filter_status(False, [0.01, 0.02, math.radians(5.0)])  # heading σ above the prior's
    assert ph.filter == (False, 0.02)


def test_signal_ids_name_the_primary_signal_by_satellite():
    assert signal_id("G05", "1C") == "G05" and signal_id("G05", "2L") == "G05_2L"
