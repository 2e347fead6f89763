"""What the navigator keeps of a run: the per-epoch record of the forward pass (what the RTS
smoother, smoother.py, needs) and the result of every measurement update."""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .ekf import StateSpace
from .error_model import BLOCK_SIZES
from .lever_arm import lever_arm_position
from .track import Track


@dataclass
class NavigatorOutput(Track):
    """Per-epoch record of a forward pass (k epochs, n states).

    Attributes
    ----------
    t : (k,) s
    lat, lon, h : (k,) rad, rad, m (IMU position, after the updates of the epoch)
    v_enu : (k, 3) m/s
    q_nb : (k, 4)
    mode : (k,) str
    P : (k, n, n) or None
        Covariance after the updates of the epoch.
    P_prior : (k, n, n) or None
        Covariance before them.
    phi : (k, n, n) or None
        Transition matrix from the previous epoch (identity at the first).
    dx : (k, n)
        Sum of the corrections fed back at the epoch.
    estimates : dict of str to (k, size)
        Running sensor / clock / extra estimates after the epoch.
    space : StateSpace
    updates : list of UpdateResult
    """

    mode: np.ndarray
    P: np.ndarray | None
    P_prior: np.ndarray | None
    phi: np.ndarray | None
    dx: np.ndarray
    estimates: dict
    space: StateSpace
    updates: list

    def sigma(self, block):
        """Standard deviations of a block per epoch, (k, size)."""
        s = self.space[block]
        return np.sqrt(np.diagonal(self.P, axis1=1, axis2=2)[:, s])


def point_track(out, lever_b, lat=None, lon=None, h=None, q_nb=None):
    """Positions (lat, lon, h arrays) of the point at lever arm `lever_b` (FLU, m) along a track
    (by default the forward pass of `out`)."""
    lat = out.lat if lat is None else lat
    return lever_arm_position(lat, out.lon if lon is None else lon, out.h if h is None else h,
                              out.q_nb if q_nb is None else q_nb, np.asarray(lever_b, float))


def estimate_sizes(space):
    """(name, size) of the blocks whose running estimates live outside the filter (all but
    pos, vel, att)."""
    for name in space.blocks[3:]:
        yield name, (BLOCK_SIZES[name] if name in BLOCK_SIZES else space.extras[name].size)


class Recorder:
    """Per-epoch record and update results of a run.

    Parameters
    ----------
    space : StateSpace
    record : bool
        Keep the per-epoch record and every update result; without it only the update results
        not yet forgotten (:meth:`forget_updates`) are kept (NavigatorConfig.record).
    store_covariance : bool
        Keep P, P_prior and Phi per epoch (NavigatorConfig.store_covariance).
    """

    _COLUMNS = ("t", "lat", "lon", "h", "v", "q", "mode", "P", "Pp", "phi", "dx", "est")

    def __init__(self, space, record, store_covariance):
        self.space = space
        self._record = record
        self._store_covariance = store_covariance
        self._out = {k: [] for k in self._COLUMNS}
        self._updates = []
        self._updates_dropped = 0   # update results forgotten in streaming use (record=False)

    # -- epochs ------------------------------------------------------------------------------
    @property
    def epochs(self):
        """Number of epochs recorded."""
        return len(self._out["t"])

    def epoch(self, state, phi, P_prior):
        """Record a new epoch: the run state after the propagation, with its Phi and P-."""
        if not self._record:
            return
        o, nav = self._out, state.nav
        o["t"].append(nav.t)
        o["lat"].append(nav.lat)
        o["lon"].append(nav.lon)
        o["h"].append(nav.h)
        o["v"].append(nav.v_enu)
        o["q"].append(nav.q_nb)
        o["mode"].append(state.mode)
        o["dx"].append(np.zeros(self.space.size))
        o["est"].append({k: v.copy() for k, v in state.estimates.items()})
        if self._store_covariance:
            o["P"].append(state.ekf.P.copy())
            o["Pp"].append(P_prior)
            o["phi"].append(phi)

    def correct(self, state, dx):
        """Replace the current epoch's record by the corrected state (after an update)."""
        if not self._record:
            return
        o, nav = self._out, state.nav
        o["lat"][-1], o["lon"][-1], o["h"][-1] = nav.lat, nav.lon, nav.h
        o["v"][-1], o["q"][-1], o["mode"][-1] = nav.v_enu, nav.q_nb, state.mode
        o["dx"][-1] = o["dx"][-1] + dx
        o["est"][-1] = {k: v.copy() for k, v in state.estimates.items()}
        if self._store_covariance:
            o["P"][-1] = state.ekf.P.copy()

    def set_mode(self, mode):
        """The current epoch's mode changed."""
        if self._record:
            self._out["mode"][-1] = mode

    def widen_prior(self, s, variances):
        """Add `variances` to the block `s` (slice) of the current epoch's P-: process noise of
        this epoch as far as the smoother is concerned."""
        if self._record and self._store_covariance:
            self._out["Pp"][-1][s, s] += np.diag(variances)

    # -- update results ----------------------------------------------------------------------
    @property
    def updates(self):
        """UpdateResult of every measurement kept, in processing order (read-only view)."""
        return self._updates

    @property
    def update_count(self):
        """Number of update results produced so far, including forgotten ones."""
        return self._updates_dropped + len(self._updates)

    def add_update(self, result):
        self._updates.append(result)

    def updates_since(self, count):
        """The update results after the first `count` (as counted by :attr:`update_count`)."""
        return self._updates[max(count - self._updates_dropped, 0):]

    def forget_updates(self, count):
        """Without `record`, drop the update results before the first `count`."""
        if self._record:
            return
        first = count - self._updates_dropped
        del self._updates[:first]
        self._updates_dropped += first

    # -- rewind and output -------------------------------------------------------------------
    def last_epoch(self):
        """A copy of the current epoch's record (None without one), for :meth:`truncate`."""
        if not self._record or not self._out["t"]:
            return None
        return {k: ({n: v.copy() for n, v in lst[-1].items()} if k == "est"
                    else np.copy(lst[-1]) if isinstance(lst[-1], np.ndarray) else lst[-1])
                for k, lst in self._out.items() if lst}

    def truncate(self, epochs, update_count, last_epoch=None):
        """Forget the epochs after the first `epochs` and the update results after the first
        `update_count`: a delayed measurement re-runs them. `last_epoch` (:meth:`last_epoch`
        when the run had got that far) restores the record of the epoch the re-run starts
        from: the updates re-applied there would otherwise add their corrections (dx) twice,
        which the smoother reads."""
        for lst in self._out.values():
            del lst[epochs:]
        del self._updates[update_count - self._updates_dropped:]
        if last_epoch is not None and epochs > 0:
            for k, value in last_epoch.items():
                self._out[k][-1] = value

    def output(self):
        """The record so far, as a :class:`NavigatorOutput`."""
        o = self._out
        full = self._store_covariance and len(o["P"]) > 0
        est = {name: np.array([e[name] for e in o["est"]]).reshape(len(o["t"]), size)
               for name, size in estimate_sizes(self.space)}
        return NavigatorOutput(
            t=np.array(o["t"]), lat=np.array(o["lat"]), lon=np.array(o["lon"]),
            h=np.array(o["h"]), v_enu=np.array(o["v"]).reshape(-1, 3),
            q_nb=np.array(o["q"]).reshape(-1, 4), mode=np.array(o["mode"]),
            P=np.array(o["P"]) if full else None, P_prior=np.array(o["Pp"]) if full else None,
            phi=np.array(o["phi"]) if full else None,
            dx=np.array(o["dx"]).reshape(len(o["t"]), self.space.size), estimates=est,
            space=self.space, updates=list(self._updates))
