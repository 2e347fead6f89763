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
class SampleTrack(Track):
    """The forward pass's solution at its IMU samples (m samples): each mechanised from the
    epoch before it with that epoch's sensor error estimates, as the strapdown node publishes
    it (at a sample that ends an epoch: before that epoch's updates).

    Attributes
    ----------
    epoch : (m,) int
        Index of the epoch each sample precedes (its solution follows epoch ``epoch - 1``).
    """

    epoch: np.ndarray


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
        Covariance after the updates of the epoch (the filter's: relative to the fixes it
        follows; :func:`published_covariance` adds what they share).
    P_prior : (k, n, n) or None
        Covariance before them.
    phi : (k, n, n) or None
        Transition matrix from the previous epoch (identity at the first).
    dx : (k, n)
        Sum of the corrections fed back at the epoch.
    published_var : (k, n)
        What the published covariance adds to the diagonal of P at the epoch
        (:func:`published_covariance`; Navigator.covariance).
    estimates : dict of str to (k, size)
        Running sensor / clock / extra estimates after the epoch.
    space : StateSpace
    updates : list of UpdateResult
    samples : SampleTrack or None
        The solution at the IMU samples (what the strapdown node publishes as ins/state).
    """

    mode: np.ndarray
    P: np.ndarray | None
    P_prior: np.ndarray | None
    phi: np.ndarray | None
    dx: np.ndarray
    published_var: np.ndarray
    estimates: dict
    space: StateSpace
    updates: list
    samples: SampleTrack | None = None

    def sigma(self, block):
        """Standard deviations of a block per epoch, (k, size)."""
        s = self.space[block]
        return np.sqrt(np.diagonal(self.P, axis1=1, axis2=2)[:, s])


def published_covariance(P, published_var):
    """The covariance to publish of one epoch's (n, n) or a block of epochs' (k, n, n) filter
    covariance P: P with the variances published_var ((n,) or (k, n)) added to its diagonal.
    They are what the filter's P leaves out (Navigator.covariance): the noise floors of forced
    measurement kinds (integrity.py) and, on the horizontal position, the error common to the
    fixes the filter follows (GnssFix.common_var). P itself is not changed."""
    var = np.asarray(published_var, float)
    if not np.any(var > 0.0):
        return P
    P = P.copy()
    diagonal = np.arange(P.shape[-1])
    P[..., diagonal, diagonal] += var
    return P


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


#: The sample buffer of a run without a record (nothing written).
_NO_SAMPLES = np.empty((0, 10))


class _Columns:
    """Per-epoch (or per-sample) values in numpy columns that grow by doubling, so that a long run costs no
    Python object per value and the record's output is a view of them. A doubled column is
    only resident as far as it is written (the pages beyond are address space), and the old
    one is freed at once: the copy is the only transient.

    Parameters
    ----------
    schema : dict of str to (tuple, dtype)
        Each column's per-epoch shape and type.
    """

    def __init__(self, schema):
        self.n = 0
        self._schema = schema
        self._capacity = 0
        self.data: dict[str, np.ndarray] = {}

    def new_rows(self, m: int = 1) -> int:
        """Add m rows (epochs, or samples; their values to be written into :attr:`data`);
        returns the first one's index."""
        n, data = self.n, self.data
        if n + m > self._capacity:
            self._capacity = max(1024, 2 * n, n + m)
            for k, (shape, dtype) in self._schema.items():
                grown = np.empty((self._capacity,) + shape, dtype)
                if n:
                    grown[:n] = data[k][:n]
                data[k] = grown
        self.n = n + m
        return n

    def set_last(self, values: dict) -> None:
        """Overwrite the current epoch's values of the names in `values`."""
        k, data = self.n - 1, self.data
        for name, value in values.items():
            data[name][k] = value

    def view(self, name) -> np.ndarray:
        if not self.data:  # nothing recorded: an empty column of its shape and type
            shape, dtype = self._schema[name]
            return np.empty((0,) + shape, dtype)
        return self.data[name][:self.n]

    def last_values(self) -> dict:
        """A copy of the current epoch's values (an element of a column of scalars is one)."""
        k = self.n - 1
        return {name: v[k].copy() if v.ndim > 1 else v[k] for name, v in self.data.items()}


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

    def __init__(self, space, record, store_covariance):
        self.space = space
        self._record = record
        self._store_covariance = store_covariance
        self._estimates = dict(estimate_sizes(space))
        self._estimate_keys = {name: "est:" + name for name in self._estimates}
        n, f = space.size, float
        schema = {"t": ((), f), "lat": ((), f), "lon": ((), f), "h": ((), f), "v": ((3,), f),
                  "q": ((4,), f), "mode": ((), object), "dx": ((n,), f),
                  "published_var": ((n,), f),
                  **{key: ((self._estimates[name],), f)
                     for name, key in self._estimate_keys.items()}}
        if store_covariance:
            schema.update(P=((n, n), f), Pp=((n, n), f), phi=((n, n), f))
        self._out = _Columns(schema)
        self._samples = _Columns({"t": ((), f), "nav": ((10,), f), "epoch": ((), np.int64)})
        self._updates = []
        self._updates_dropped = 0   # update results forgotten in streaming use (record=False)

    # -- epochs ------------------------------------------------------------------------------
    @property
    def epochs(self):
        """Number of epochs recorded."""
        return self._out.n

    def epoch(self, state, phi, P_prior, published_var):
        """Record a new epoch: the run state after the propagation, with its Phi and P-, and
        what the published covariance adds to P's diagonal at the moment (n,)."""
        if not self._record:
            return
        o = self._out
        k = o.new_rows()
        d = o.data
        d["t"][k] = state.nav.t
        d["dx"][k] = 0.0
        if self._store_covariance:
            d["Pp"][k] = P_prior
            d["phi"][k] = phi
        self._write(d, k, state, published_var)

    def sample_buffer(self, n):
        """Where a segment of n samples is to write the solution after each of them (the
        last before the updates of the epoch it ends at): (n, 10), or (0, 10) without a
        record."""
        return np.empty((n, 10)) if self._record else _NO_SAMPLES

    def samples(self, t, states):
        """Record the solution at the samples (times t, s) of the segment whose epoch is
        recorded next: states as :meth:`sample_buffer` gave them, filled (nothing without a
        record)."""
        if not len(states):
            return
        o = self._samples
        k = o.new_rows(len(states))
        rows = slice(k, o.n)
        o.data["t"][rows] = t
        o.data["nav"][rows] = states
        o.data["epoch"][rows] = self._out.n

    def correct(self, state, dx, published_var):
        """Replace the current epoch's record by the corrected state (after an update) and
        what the published covariance adds to P's diagonal after it (n,)."""
        if not self._record:
            return
        d, k = self._out.data, self._out.n - 1
        self._write(d, k, state, published_var)
        d["dx"][k] += dx

    def _write(self, d, k, state, published_var):
        """The state's values of row k (written one by one: a dict of them per epoch and
        update cost more than the writes)."""
        nav = state.nav
        d["lat"][k] = nav.lat
        d["lon"][k] = nav.lon
        d["h"][k] = nav.h
        d["v"][k] = nav.v_enu
        d["q"][k] = nav.q_nb
        d["mode"][k] = state.mode
        d["published_var"][k] = published_var
        for name, key in self._estimate_keys.items():
            d[key][k] = state.estimates[name]
        if self._store_covariance:
            d["P"][k] = state.ekf.P

    def set_mode(self, mode):
        """The current epoch's mode changed."""
        if self._record:
            self._out.set_last({"mode": mode})

    def widen_prior(self, index, variances):
        """Add `variances` to the diagonal of the current epoch's P- at `index` (a slice or the
        states' indices): process noise of this epoch as far as the smoother is concerned."""
        if self._record and self._store_covariance:
            P = self._out.data["Pp"][self._out.n - 1]
            k = np.arange(len(P))[index]
            P[k, k] += variances

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
        if not self._record or not self._out.n:
            return None
        return self._out.last_values()

    def truncate(self, epochs, update_count, last_epoch=None):
        """Forget the epochs after the first `epochs` and the update results after the first
        `update_count`: a delayed measurement re-runs them. `last_epoch` (:meth:`last_epoch`
        when the run had got that far) restores the record of the epoch the re-run starts
        from: the updates re-applied there would otherwise add their corrections (dx) twice,
        which the smoother reads."""
        self._out.n = min(self._out.n, epochs)
        if self._samples.n:
            self._samples.n = int(np.searchsorted(self._samples.view("epoch"), epochs))
        del self._updates[update_count - self._updates_dropped:]
        if last_epoch is not None and epochs > 0:
            self._out.set_last(last_epoch)

    def output(self):
        """The record so far, as a :class:`NavigatorOutput` of views, not copies, of the
        record (a record is as large as its output): take it when the run is over, as what a
        run does next may rewrite its last epochs."""
        o, n = self._out, self._out.n
        full = self._store_covariance and n > 0
        est = {name: o.view("est:" + name).reshape(n, size)
               for name, size in self._estimates.items()}
        return NavigatorOutput(
            t=o.view("t"), lat=o.view("lat"), lon=o.view("lon"), h=o.view("h"),
            v_enu=o.view("v").reshape(n, 3), q_nb=o.view("q").reshape(n, 4),
            mode=o.view("mode").astype(str), P=o.view("P") if full else None,
            P_prior=o.view("Pp") if full else None, phi=o.view("phi") if full else None,
            dx=o.view("dx").reshape(n, self.space.size),
            published_var=o.view("published_var").reshape(n, self.space.size), estimates=est,
            space=self.space, updates=list(self._updates), samples=self._sample_track())

    def _sample_track(self):
        """The recorded samples between the epochs as a SampleTrack of views (None without
        a record)."""
        if not self._record:
            return None
        o = self._samples
        nav = o.view("nav")
        return SampleTrack(t=o.view("t"), lat=nav[:, 0], lon=nav[:, 1], h=nav[:, 2],
                           v_enu=nav[:, 3:6], q_nb=nav[:, 6:10], epoch=o.view("epoch"))
