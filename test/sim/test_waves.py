"""Wave spectrum and wave-induced motion (ins_gnss_ros.sim.waves)."""
import numpy as np
import pytest
from scipy.integrate import quad

from ins_gnss_ros.sim import waves


@pytest.mark.parametrize("gamma, tol", [(1.0, 1e-5), (3.3, 0.02)])
def test_spectrum_keeps_significant_wave_height(gamma, tol):
    """H_s = 4 √m0 (DNV-RP-C205 §3.5.5): exact for Pierson–Moskowitz, within the A_γ
    normalisation's few per cent for JONSWAP."""
    hs, tp = 2.0, 7.0
    m0 = quad(lambda w: waves.jonswap(w, hs, tp, gamma), 0.05, 20.0, limit=200)[0]
    assert 4.0 * np.sqrt(m0) == pytest.approx(hs, rel=tol)
    w = np.linspace(0.3, 3.0, 27001)
    assert w[np.argmax(waves.jonswap(w, hs, tp, gamma))] == pytest.approx(2 * np.pi / tp,
                                                                          abs=2e-3)


@pytest.fixture(scope="module")
def motion():
    return waves.wave_motion(waves.SeaState(), waves.HullResponse(), np.random.default_rng(9))


def test_motion_levels_and_derivatives(motion):
    hull = waves.HullResponse()
    np.testing.assert_allclose(motion.std[:3], hull.angle_std, rtol=1e-12)
    t = np.arange(0.0, 3600.0, 0.05)
    val, rate, acc = motion.evaluate(t)
    # A long record has the designed standard deviation (sum of random-phase sinusoids).
    np.testing.assert_allclose(val.std(axis=0), motion.std, rtol=0.1)
    np.testing.assert_allclose(np.gradient(val, t, axis=0)[1:-1], rate[1:-1],
                               atol=2e-3 * np.abs(rate).max())
    np.testing.assert_allclose(np.gradient(rate, t, axis=0)[1:-1], acc[1:-1],
                               atol=2e-3 * np.abs(acc).max())
    # Heave keeps the physical level: below the wave elevation's H_s/4 (hull low-pass),
    # and of the same order.
    sea = waves.SeaState()
    assert 0.3 * sea.hs / 4 < motion.std[3] < sea.hs / 4
    # Roll is resonant near its natural period: its dominant frequency lies near 2π/T_roll.
    spec = np.abs(np.fft.rfft(val[:, 0])) ** 2
    f = np.fft.rfftfreq(len(t), 0.05)
    assert 1.0 / f[np.argmax(spec)] == pytest.approx(hull.periods[0], rel=0.25)


def test_seeded(motion):
    again = waves.wave_motion(waves.SeaState(), waves.HullResponse(), np.random.default_rng(9))
    np.testing.assert_array_equal(again.phase, motion.phase)
    other = waves.wave_motion(waves.SeaState(), waves.HullResponse(), np.random.default_rng(10))
    assert not np.allclose(other.phase, motion.phase)
