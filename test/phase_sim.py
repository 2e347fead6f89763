"""PhaseSim: a seeded synthetic multi-antenna carrier-phase simulator for the attitude tests.

Exact ranges from each antenna to far satellites with known integer ambiguities, receiver clocks,
injectable cycle slips and elevation-dependent multipath: independent truth for double
differences, LAMBDA fixing and attitude.
"""
import numpy as np

from ins_gnss_ros.gnss.constants import C_LIGHT, FREQ_L1
from ins_gnss_ros.gnss.differences import AntennaEpoch, NoiseModel

WL1 = C_LIGHT / FREQ_L1
ORBIT_RANGE = 2.02e7   # m, roughly a GPS/Galileo slant range


class PhaseSim:
    """Antennas on a rigid body seeing GPS + Galileo L1/E1 satellites, RINEX-sign observables.

    Satellites sit at ``ORBIT_RANGE`` along slowly drifting azimuth/elevation; ranges are exact
    distances from each antenna (no plane-wave approximation). Phase noise per antenna and
    signal: white N(0, a²) plus a multipath-like sinusoid of variance b²/sin²(el) (random
    period 60-300 s and phase), so its marginal variance follows the elevation model.
    """

    def __init__(self, seed, antennas_flu, n_gps=5, n_gal=5, noise=NoiseModel(),
                 clock_m=300.0):
        rng = np.random.default_rng(seed)
        self.rng = rng
        self.antennas = np.asarray(antennas_flu, float)
        self.ids = [f"G{p:02d}" for p in rng.choice(np.arange(1, 33), n_gps, replace=False)] + \
                   [f"E{p:02d}" for p in rng.choice(np.arange(1, 37), n_gal, replace=False)]
        n = len(self.ids)
        self.az0 = rng.uniform(0, 2 * np.pi, n)
        self.el0 = rng.uniform(np.radians(15), np.radians(80), n)
        self.az_rate = rng.uniform(-1, 1, n) * np.radians(0.5) / 60   # <= 0.5 deg/min
        self.el_rate = rng.uniform(-1, 1, n) * np.radians(0.2) / 60
        n_ant = len(self.antennas)
        self.N = rng.integers(-10**6, 10**6, (n_ant, n)).astype(float)
        self.clock = rng.uniform(-clock_m, clock_m, n_ant)
        self.noise = noise
        self.mp_period = rng.uniform(60, 300, (2, n_ant, n))
        self.mp_phase = rng.uniform(0, 2 * np.pi, (2, n_ant, n))
        self.slips = {}   # (antenna, id) -> cycles added from the epoch of insertion on

    def azel(self, t):
        el = np.clip(self.el0 + self.el_rate * t, np.radians(12), np.radians(88))
        return self.az0 + self.az_rate * t, el

    def los(self, t):
        az, el = self.azel(t)
        e = np.c_[np.cos(el) * np.sin(az), np.cos(el) * np.cos(az), np.sin(el)]
        return {s: e[i] for i, s in enumerate(self.ids)}

    def _ranges(self, t, R_nb):
        e = np.array(list(self.los(t).values()))
        sat = ORBIT_RANGE * e
        r_ant = self.antennas @ R_nb.T          # antenna positions, ENU, master at the origin
        return np.linalg.norm(sat[None, :, :] - r_ant[:, None, :], axis=2), e

    def observe(self, t, R_nb, R_nb_rate=None):
        """Observations of every antenna at time t with attitude R_nb (and dR/dt for Doppler)."""
        rho, e = self._ranges(t, R_nb)
        el = np.arcsin(e[:, 2])
        nz = self.noise
        out = []
        dt = 1e-3
        R_next = R_nb if R_nb_rate is None else R_nb + R_nb_rate * dt
        rho_next, _ = self._ranges(t + dt, R_next)
        for a in range(len(self.antennas)):
            mp = [np.sqrt(2) * b / np.sin(el) *
                  np.sin(2 * np.pi * t / self.mp_period[k, a] + self.mp_phase[k, a])
                  for k, b in enumerate((nz.phase_b, nz.code_b))]
            ph_m = rho[a] + self.clock[a] + nz.phase_a * self.rng.normal(size=el.size) + mp[0]
            phase = ph_m / WL1 + self.N[a]
            for i, s in enumerate(self.ids):
                phase[i] += self.slips.get((a, s), 0.0)
            code = rho[a] + self.clock[a] + nz.code_a * self.rng.normal(size=el.size) + mp[1]
            doppler = -(rho_next[a] - rho[a]) / dt / WL1 + 0.02 * self.rng.normal(size=el.size)
            out.append(AntennaEpoch(list(self.ids), phase, code, np.full(el.size, WL1),
                                    doppler, np.zeros(el.size, bool)))
        return out
