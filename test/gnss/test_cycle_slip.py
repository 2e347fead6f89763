"""Cycle-slip detection on simulated phase with injected slips and clock jumps."""

import numpy as np

from ins_gnss_ros.gnss.constants import C_LIGHT, FREQ_L1
from ins_gnss_ros.gnss.cycle_slip import (
    detect_slips_dd, detect_slips_doppler, doppler_phase_residual)
from ins_gnss_ros.gnss.differences import form_double_differences, select_references
from ins_gnss_ros.nav.rotations import dcm_from_euler
from phase_sim import PhaseSim, WL1


ANT = np.array([[0.0, 0.0, 0.0], [1.5, 0.0, 0.0]])
RATE = 0.3          # rad/s yaw rate: a turning vessel, gives Doppler differences


def _attitude(t):
    yaw = 0.2 + RATE * t
    R = dcm_from_euler(0.0, 0.0, yaw)
    dR = RATE * np.array([[0, -1, 0], [1, 0, 0], [0, 0, 0]]) @ R
    return R, dR


def test_doppler_sign_convention_for_an_approaching_satellite():
    """RINEX: phase follows range, Doppler is positive when the range shrinks."""
    lam = C_LIGHT / FREQ_L1
    rho = lambda t: 2.2e7 - 800.0 * t + 0.4 * t * t          # noqa: E731
    rate = lambda t: -800.0 + 0.8 * t                         # noqa: E731
    r = doppler_phase_residual(rho(0) / lam, rho(1) / lam, -rate(0) / lam, -rate(1) / lam, 1.0)
    assert abs(r) < 1e-6
    assert -rate(0) / lam > 0


def test_doppler_test_finds_the_slipped_signal_and_ignores_clock_jumps():
    sim = PhaseSim(21, ANT)
    prev = sim.observe(0.0, *_attitude(0.0))
    s_slip = sim.ids[3]
    sim.slips[(1, s_slip)] = 2.0
    curr = sim.observe(1.0, *_attitude(1.0))
    # Antenna 0 steers its clock by 1 ms: phase and code jump, Doppler does not.
    curr[0].phase = curr[0].phase + 1e-3 * C_LIGHT / WL1
    assert detect_slips_doppler(prev[0], curr[0], 1.0) == set()
    assert detect_slips_doppler(prev[1], curr[1], 1.0) == {s_slip}
    curr[1].loss_of_lock = np.array([s == sim.ids[5] for s in sim.ids])
    assert detect_slips_doppler(prev[1], curr[1], 1.0) == {s_slip, sim.ids[5]}


def test_dd_test_finds_single_cycle_slips_without_false_alarms():
    sim = PhaseSim(22, ANT)
    refs, prev, false_alarms, found = None, None, 0, 0
    for i in range(80):
        t = float(i)
        R, _ = _attitude(t)
        los = sim.los(t)
        el = [np.arcsin(los[s][2]) for s in sim.ids]
        refs = select_references(sim.ids, el, [WL1] * len(sim.ids), refs)
        target = [s for s in sim.ids if s not in refs.values()][i % 6]
        if i % 10 == 5:
            sim.slips[(1, target)] = sim.slips.get((1, target), 0.0) + 1.0
        dd = form_double_differences(sim.observe(t, R), los, refs, sim.noise)
        if prev is not None:
            # The previous baseline from the truth plus 5 cm: a float-quality baseline.
            b_prev = (prev[1] @ ANT[1] + 0.05)[None, :]
            slipped = detect_slips_dd(prev[0], dd, b_prev)
            if i % 10 == 5:
                assert target in slipped
                found += 1
                slipped.discard(target)
            false_alarms += len(slipped)
        prev = (dd, R)
    assert found == 8
    assert false_alarms <= 1
