"""Forced measurement updates, their noise floors, and the degraded test.

Every measurement is gated (gating.py). A kind rejected continuously for `max_reject_time`
seconds is forced in (recovery after a divergence). With one source of each kind, a diverged
filter and a measurement gone wrong (a GNSS step, a spoofed position, a clock jump) look the
same: a sustained innovation nu beyond the gate. Forcing admits nu on both sides. The directly
measured state blocks are widened by nu^2 before the update (the INS may be wrong: the update
then follows the measurement), and the kind gets a noise floor F = nu^2 (the measurement may be
wrong), treated like an unobserved constant bias of the measurement (a "consider" parameter):

* :meth:`Integrity.covariance`, the covariance to publish, adds F to the blocks the kind
  measures, and repeated measurements cannot average it away;
* a measurement beyond the gate but within the gate of H P H^T + R + F is forced in at once, in
  the same way: a measurement that returns to the INS after a transient fault is followed again
  without a second 2 s wait;
* the gain keeps the nominal R: when the INS was the one that diverged (the usual case, e.g.
  after a GNSS outage on a real drive) the filter's accuracy is that of the nominal filter (a
  first version that also inflated R in the gain and held P at F took the real car drive's
  smoothed outage error from 0.52 to 21.9 m at worst; docs/results/faults.md).

The floors and the rejection times are not part of the checkpoints for delayed measurements
(rewind.py): a re-run keeps the current ones (a floor is only ever conservative). The start of
a kind's current rejection, which decides the forcing, is part of the run state and is rewound.

A rejection is continuous while the kind keeps arriving: a gap of more than
``GAP_FACTOR * max_reject_time`` without it (a GNSS outage) ends it, so that the first
measurements after the gap, which meet an INS that coasted through it, get the full
`max_reject_time` to be accepted before they are forced (a rejection counted from before a 15 s
outage forced the first fix after it at once on the real car drive, and its floor of the
outage's drift kept the solution degraded for minutes).

F decays by exp(-dt / floor_tau) over the time the kind is accepted (not while it is rejected).
While it exceeds degraded_ratio^2 times the kind's own variance, the solution is degraded
(mode DEAD_RECKONING, modes.py: it is not confirmed by its aiding) until the kind has been
accepted for confirm_time without being forced or rejected again: a stream of measurements that
agree with the solution (at 5 Hz, 50 in the default 10 s) confirms it, while the floor stays in
the published covariance until it has decayed, so that a persistent fault is covered as before
(a forced step nu keeps sigma >= nu exp(-t / (2 floor_tau)), 0.85 nu at the confirmation).
Degraded until the floor itself fell below the kind's variance, an RTK receiver's 39 cm
disagreement before an outage of the real car drive kept the solution DEAD_RECKONING for the
last 110 s of the drive, and the velocities forced after each 15 s outage (the INS drifts
1.3 m/s in one with config/default.yaml) most of the time between outages.

A kind in :data:`NOT_VOUCHING` is gated, forced and floored as any other, but neither its
rejections nor its floor degrade the solution: the receiver's vertical velocity, updated apart
from its horizontal one while it is :meth:`Integrity.troubled` (the INS's vertical channel is
its least stable: a consumer unit's ran 0.2-0.5 m/s off under a sigma of 0.015 on a car
speeding up with its pitch 1.3 deg off; the whole velocity refused, then forced, kept a
simulated drive DEAD_RECKONING for 20 s while every fix was taken: docs/results/
product_path.md, "2026-12-07 (session 46)"). The fixes still vouch for the height, and the
floor is published.

The solution is degraded too while an aiding kind keeps being rejected for `suspect_time` before
it is forced: the other kinds may still be accepted (a GNSS clock jump shifts the velocities a
little and the positions a lot), but the solution and the rejected kind disagree; and while the
turns show the IMU's rates wrong (:attr:`Integrity.imu_rates_wrong`, imu_timing.py:
gravity down, deg/s): the fixes still hold the solution, but what it does between them is not
navigation (the car drive published with gravity down: 22 of its 154 valid fixes beyond 5 sigma).
"""
from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from .gating import chi2_gate, normalised_innovation
from .measurements import GNSS_VEL_UP

#: A kind absent for more than this many times max_reject_time ends its continuous rejection:
#: a kind arriving at 0.5 Hz still continues one at the default 2 s.
GAP_FACTOR = 2.0
#: Kinds whose disagreement with the solution does not put it in doubt (module docstring).
NOT_VOUCHING = frozenset({GNSS_VEL_UP})


def rejection_start(span, epoch, max_reject_time):
    """Start (s) of the continuous rejection a measurement of the kind at `epoch` (s) would
    continue, or None: none is under way (`span` None) or the kind's last rejected measurement,
    ``span = (first, last)``, lies more than ``GAP_FACTOR * max_reject_time`` before it."""
    if span is None or epoch - span[1] > GAP_FACTOR * max_reject_time:
        return None
    return span[0]


@dataclass
class NoiseFloor:
    """The noise floor a forced measurement kind keeps.

    Attributes
    ----------
    var : ndarray
        Floor variances, one per measurement component (measurement units squared).
    t : float
        Epoch of its last decay, s.
    blocks : list of (str, ndarray)
        State blocks ("pos", "vel") the kind measures directly, each with the axis of the
        block each of the kind's components measures.
    r : float
        Largest variance of the kind's own noise at its last measurement.
    suspect : float
        Epoch of the kind's last forced update or rejection, s: it is confirmed once accepted
        for confirm_time after it.
    """

    var: np.ndarray
    t: float
    blocks: list
    r: float
    suspect: float

    def variances(self, m):
        """The floor as m variances (a kind whose dimension varies, e.g. pseudoranges, gets
        the largest one on every component)."""
        return self.var if len(self.var) == m else np.full(m, np.max(self.var))


class Integrity:
    """Noise floors of forced kinds and the (first, last) epochs of current rejections.

    Parameters
    ----------
    config : NavigatorConfig
        max_reject_time, gate_prob, floor_tau, confirm_time, degraded_ratio, suspect_time.
    """

    def __init__(self, config):
        self.config = config
        self.floors = {}        # kind -> NoiseFloor
        self.rejecting = {}     # aiding kind -> (first, last) epoch of its current rejection
        self.imu_rates_wrong = False  # the turns show the IMU's rates wrong: degraded

    def update(self, ekf, space, innov, epoch, rejected_since, widen_prior, held=None):
        """Gate and apply one measurement, forced in after `max_reject_time` s of continuous
        rejection (since `rejected_since`, s, or None) or within its kind's floor.

        Parameters
        ----------
        ekf : ErrorStateEKF
        space : StateSpace
        innov : Innovation
        epoch : float
            s.
        rejected_since : float or None
            Start of the kind's current continuous rejection (:func:`rejection_start`), s.
        widen_prior : callable (indices, variances)
            Told of each widening of a state block by a forced update (the record's P-).
        held : array_like of int, optional
            States the update leaves as they are (:meth:`ErrorStateEKF.update`).

        Returns
        -------
        UpdateResult
            With reason "forced" when forced (the widened covariance usually passes the gate:
            it says why that was needed).
        """
        cfg = self.config
        force = rejected_since is not None and epoch - rejected_since > cfg.max_reject_time
        floor = self.floors.get(innov.name)
        if not force and floor is not None and cfg.gate_prob is not None:
            force = self._within_floor(ekf, innov, floor)
        if force:
            self._force(ekf, space, innov, epoch, widen_prior)
            floor = self.floors[innov.name]
        res = ekf.update(innov.name, epoch, innov.z, innov.H, innov.R, cfg.gate_prob, force,
                         held)
        if force:
            res = replace(res, reason="forced")
        if floor is not None:
            if res.accepted and not force:
                floor.var = floor.var * np.exp(-max(epoch - floor.t, 0.0) / cfg.floor_tau)
            floor.t, floor.r = epoch, float(np.max(np.diag(innov.R)))
            if np.max(floor.var) < 1e-2 * floor.r:
                del self.floors[innov.name]  # negligible beside the measurement's own noise
        return res

    def rejected(self, name, epoch):
        """An aiding measurement of kind `name` was rejected at `epoch` (s)."""
        first = rejection_start(self.rejecting.get(name), epoch, self.config.max_reject_time)
        self.rejecting[name] = (epoch if first is None else first, epoch)
        if name in self.floors:
            self.floors[name].suspect = epoch

    def accepted(self, name):
        """A measurement of kind `name` was accepted: its rejection is over."""
        self.rejecting.pop(name, None)

    def degraded(self, epoch):
        """A forced kind's noise floor is still large and not yet confirmed, or an aiding kind
        is being rejected for `suspect_time`, or the IMU's rates are wrong (module docstring)."""
        if self.imu_rates_wrong:
            return True
        if not self.floors and not self.rejecting:
            return False  # the usual case, asked after every update
        cfg = self.config
        ratio2 = cfg.degraded_ratio ** 2
        return any(np.max(f.var) > ratio2 * f.r and epoch - f.suspect < cfg.confirm_time
                   for name, f in self.floors.items() if name not in NOT_VOUCHING) or any(
            epoch - first >= cfg.suspect_time and epoch - last <= cfg.suspect_time
            for name, (first, last) in self.rejecting.items() if name not in NOT_VOUCHING)

    def variances(self, space):
        """What the noise floors add to the diagonal of the covariance published, (n,): on the
        state blocks each forced kind measures directly, the floor it keeps."""
        var = np.zeros(space.size)
        for floor in self.floors.values():
            for name, axes in floor.blocks:
                var[space[name].start + axes] += floor.var
        return var

    def troubled(self, ekf, innov):
        """Whether innov's kind keeps a floor or is being rejected, or innov lies beyond its
        gate as the filter stands (nothing is updated or recorded)."""
        if innov.name in self.floors or innov.name in self.rejecting:
            return True
        prob = self.config.gate_prob
        return prob is not None and not _within_gate(ekf, innov, prob)

    def _within_floor(self, ekf, innov, floor):
        """Beyond the gate of H P H^T + R, but within that of H P H^T + R + F (the floor)."""
        prob = self.config.gate_prob
        return not _within_gate(ekf, innov, prob) and _within_gate(ekf, innov, prob, floor)

    def _force(self, ekf, space, innov, epoch, widen_prior):
        """Widen the blocks `innov` measures directly by its innovation and set its kind's
        floor."""
        nu2 = (innov.z - innov.H @ ekf.x) ** 2
        blocks = []
        for name in ("pos", "vel"):
            axes = _measured_axes(innov.H[:, space[name]])
            if axes is not None:
                blocks.append((name, axes))
                k = space[name].start + axes
                ekf.P[k, k] += nu2
                widen_prior(k, nu2)
        old = self.floors.get(innov.name)
        if old is not None:
            nu2 = np.maximum(nu2, old.variances(len(nu2)))
        self.floors[innov.name] = NoiseFloor(nu2, epoch, blocks,
                                             float(np.max(np.diag(innov.R))), epoch)


def _within_gate(ekf, innov, prob, floor=None):
    """Whether innov's NIS under H P H^T + R (+ the floor's variances) is within its gate."""
    nu = innov.z - innov.H @ ekf.x
    S = innov.H @ ekf.P @ innov.H.T + innov.R
    if floor is not None:
        S = S + np.diag(floor.variances(len(nu)))
    return normalised_innovation(nu, 0.5 * (S + S.T)) <= chi2_gate(len(nu), prob)


def _measured_axes(block):
    """The axis each row of a measurement's H over a 3-axis state block measures directly (each
    row one of the identity's, as a position or velocity in those axes), or None."""
    axes = np.argmax(block, axis=1)
    return axes if np.allclose(block, np.eye(block.shape[1])[axes]) else None
