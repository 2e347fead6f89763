"""Detection of magnetic disturbances, so that a disturbed field is not published as heading.

A nearby steel mass, a current-carrying cable or an uncalibrated change of the vehicle's own field
adds a local field that turns the measured horizontal component and so the magnetic heading. The
added field almost always changes the magnitude or the inclination (dip) of the measured vector
as well; both are invariant to heading and, after tilt compensation, to roll and pitch, so they
can be compared with the expected field (Groves §6.1.1 and §16.1.11 "magnetic anomaly
detection"; seed 004 §2.9 uses the same a-priori field H_e, H_n, H_h):

* against the field model (WMM total intensity and inclination), with wide tolerances because
  local anomalies of a few per cent are normal;
* against running averages of the recently accepted field, with tight tolerances, which catches
  sudden small disturbances.

A hysteresis keeps the flag from chattering: the flag rises when any test exceeds its
threshold, and drops only after every test has stayed below ``release`` × threshold for
``clear_time`` seconds. The running averages are frozen while the flag is up, so a threshold
within the noise of a single sample would hold the flag up for good once noise has tripped it:
every threshold is at least :data:`NOISE_MARGIN` times the per-sample noise of what it tests
(the field noise for |F|; the field noise and the roll/pitch error of the attitude the field is
levelled with for the inclination), and the running averages start as the plain mean of the
accepted samples rather than from the first of them.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

#: Smallest ratio of a threshold to the per-sample noise (1σ) of the quantity it tests. At 6σ no
#: noise sample trips a test (2e-9 a sample), and the release level (half of it, 3σ) lets an
#: undisturbed field at 50 Hz through the 100 samples of a 2 s ``clear_time`` three times in
#: four. The default tolerances are 6.8-10.6 times the noise they were chosen for (50 nT, 0.05°);
#: with 100 nT and a MEMS INS's 0.3° tilt their release levels would be 2.6σ and 1.6σ, which an
#: undisturbed field hardly ever meets for 2 s once anything has tripped the flag.
NOISE_MARGIN = 6.0


@dataclass(frozen=True)
class DisturbanceStatus:
    """Result of one detector update.

    Attributes
    ----------
    disturbed : bool
        The heading from this sample must not be used.
    reasons : tuple of str
        Tests that exceeded their threshold on this sample: "model_total", "model_inclination",
        "running_total", "running_inclination".
    total : float
        Measured total intensity, T.
    inclination : float
        Measured inclination, rad, positive downward.
    """

    disturbed: bool
    reasons: tuple
    total: float
    inclination: float


def total_and_inclination(field_level) -> tuple[float, float]:
    """Total intensity and inclination (rad, positive down) of a tilt-compensated field.

    ``field_level`` is the field in any frame with z up (the level frame of
    :func:`ins_gnss_ros.magnetic.compass.level_field` or ENU), T.
    """
    f = np.asarray(field_level, float)
    return float(np.linalg.norm(f)), float(np.arctan2(-f[2], np.hypot(f[0], f[1])))


class DisturbanceDetector:
    """Magnitude/inclination gate with hysteresis.

    Parameters
    ----------
    total, inclination : float
        Expected total intensity (T) and inclination (rad) from the field model.
    model_total_tol : float
        Relative tolerance of |F| against the model (default 8 %).
    model_inclination_tol : float
        Tolerance of the inclination against the model, rad (default 4°).
    running_total_tol, running_inclination_tol : float
        Tolerances against the running averages (default 1 % and 0.5°). A disturbance of ΔB
        across the horizontal field turns the heading by ΔB / H (4° for 1000 nT at St Petersburg)
        while changing |F| and the dip far less, so these must be tight: about ten times the
        noise of |F| (50 nT of 53 µT) and of the INS tilt (0.05°) behind the dip (and never
        below :data:`NOISE_MARGIN` times the noise actually given).
    release : float
        Fraction of every threshold below which the flag may drop (default 0.5).
    clear_time : float
        Time all tests must stay below the release level before the flag drops, s.
    time_constant : float
        Time constant of the running averages, s.
    field_std : float
        Noise of the field per axis and sample, T (0: tolerances as given).
    tilt_std : float
        Roll and pitch error of the attitude the field is levelled with, rad.

    Every tolerance is raised to at least :data:`NOISE_MARGIN` times the per-sample noise of its
    test: ``field_std`` / |F| for the totals, the root sum of squares of that (in rad) and
    ``tilt_std`` for the inclinations.
    """

    def __init__(self, total: float, inclination: float, model_total_tol: float = 0.08,
                 model_inclination_tol: float = np.radians(4.0), running_total_tol: float = 0.01,
                 running_inclination_tol: float = np.radians(0.5), release: float = 0.5,
                 clear_time: float = 2.0, time_constant: float = 60.0, field_std: float = 0.0,
                 tilt_std: float = 0.0):
        self.set_reference(total, inclination)
        self.tol = {"model_total": model_total_tol, "model_inclination": model_inclination_tol,
                    "running_total": running_total_tol,
                    "running_inclination": running_inclination_tol}
        self.set_noise(field_std, tilt_std)
        self.release = release
        self.clear_time = clear_time
        self.time_constant = time_constant
        self.disturbed = False
        self._running = None     # (total, inclination) averages of accepted samples
        self._n_running = 0      # samples in them
        self._last_t = None
        self._quiet_since = None

    def set_reference(self, total: float, inclination: float):
        """Update the model field (when the position has moved)."""
        self.total, self.inclination = float(total), float(inclination)

    def restart(self):
        """Forget the running averages and the flag (the calibration of the field changed)."""
        self.disturbed = False
        self._running, self._n_running = None, 0
        self._last_t = self._quiet_since = None

    def set_noise(self, field_std: float, tilt_std: float):
        """Update the per-sample noise: field per axis (T) and roll/pitch error (rad)."""
        self.field_std, self.tilt_std = float(field_std), float(tilt_std)

    def tolerances(self) -> dict:
        """Thresholds in use: the configured ones, raised to NOISE_MARGIN × the noise."""
        # Isotropic noise of σ per axis moves |F| by σ and the direction of F by σ/|F| rad; a
        # tilt error moves the inclination by up to itself (tilted in the magnetic meridian).
        total_noise = self.field_std / self.total
        incl_noise = np.hypot(total_noise, self.tilt_std)
        noise = {"model_total": total_noise, "model_inclination": incl_noise,
                 "running_total": total_noise, "running_inclination": incl_noise}
        return {k: max(tol, NOISE_MARGIN * noise[k]) for k, tol in self.tol.items()}

    def _errors(self, total, incl) -> dict:
        err = {"model_total": abs(total / self.total - 1.0),
               "model_inclination": abs(incl - self.inclination)}
        if self._running is not None:
            err["running_total"] = abs(total / self._running[0] - 1.0)
            err["running_inclination"] = abs(incl - self._running[1])
        return err

    def update(self, t: float, field_level) -> DisturbanceStatus:
        """Check one tilt-compensated field sample (T) taken at time t (s)."""
        total, incl = total_and_inclination(field_level)
        err = self._errors(total, incl)
        tol = self.tolerances()
        reasons = tuple(k for k, e in err.items() if e > tol[k])
        quiet = all(e <= self.release * tol[k] for k, e in err.items())
        if reasons:
            self.disturbed = True
            self._quiet_since = None
        elif self.disturbed:
            if not quiet:
                self._quiet_since = None
            elif self._quiet_since is None:
                self._quiet_since = t
            elif t - self._quiet_since >= self.clear_time:
                self.disturbed = False
        if not self.disturbed and not reasons:
            self._track(t, total, incl)
        self._last_t = t
        return DisturbanceStatus(self.disturbed, reasons, total, incl)

    def _track(self, t, total, incl):
        self._n_running += 1
        if self._running is None:
            self._running = (total, incl)
            return
        dt = 0.0 if self._last_t is None else max(t - self._last_t, 0.0)
        # The plain mean until the averages span a time constant: an exponential average started
        # from one sample keeps e^(-t/τ) of that sample's noise (62 % after 30 s), and an offset
        # of 1σ makes the 3σ release level a 2σ one on that side.
        a = max(1.0 - np.exp(-dt / self.time_constant), 1.0 / self._n_running)
        self._running = (self._running[0] + a * (total - self._running[0]),
                         self._running[1] + a * (incl - self._running[1]))
