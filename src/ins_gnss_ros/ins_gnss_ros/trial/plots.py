"""PNG plots of a trial evaluation (matplotlib, Agg backend: no display needed).

Each function writes one figure and returns its path. Times are plotted in seconds from the first
evaluated epoch; GNSS outage windows are shaded grey on every time axis.
"""
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402  (the backend must be chosen first)
import numpy as np  # noqa: E402

from ins_gnss_ros.nav.conventions import azimuth_from_yaw  # noqa: E402
from ins_gnss_ros.nav.earth import ecef_to_enu, geodetic_to_ecef  # noqa: E402
from ins_gnss_ros.nav.rotations import quat_to_euler  # noqa: E402
from ins_gnss_ros.trial.outages import in_outage  # noqa: E402

_OUTAGE_STYLE = {"color": "0.85", "zorder": 0}
_AXES = ("east", "north", "up")


def plot_trajectory(estimate, truth, path, windows=None):
    """Plan view (east/north, m, about the first truth point) of estimate and truth.

    Estimate samples inside outage `windows` are drawn in red so the dead-reckoning arcs stand
    out; each outage start is marked on the truth track.
    """
    origin = (truth.lat[0], truth.lon[0], truth.height[0])
    true_en = _enu(truth, origin)
    est_en = _enu(estimate, origin)
    fig, ax = plt.subplots(figsize=(8, 7))
    ax.plot(true_en[:, 0], true_en[:, 1], color="k", lw=1.0, label="truth")
    ax.plot(est_en[:, 0], est_en[:, 1], color="tab:blue", lw=0.8, label="estimate")
    if windows is not None and len(windows):
        inside = in_outage(estimate.time, windows)
        ax.plot(np.where(inside, est_en[:, 0], np.nan), np.where(inside, est_en[:, 1], np.nan),
                color="tab:red", lw=1.2, label="estimate during GNSS outage")
        starts = np.interp(np.asarray(windows)[:, 0], truth.time, np.arange(len(truth.time)))
        index = np.round(starts).astype(int)
        ax.plot(true_en[index, 0], true_en[index, 1], "v", color="tab:red", ms=6,
                label="outage start")
    ax.set_xlabel("east (m)")
    ax.set_ylabel("north (m)")
    ax.set_title("Trajectory (local ENU about the first truth point)")
    ax.set_aspect("equal", adjustable="datalim")
    ax.grid(True, lw=0.3)
    ax.legend(loc="best")
    return _save(fig, path)


def plot_errors(evaluation, path, windows=None):
    """Position, velocity and attitude errors against time with their +-3 sigma envelopes.

    One column per quantity (position m, velocity m/s, roll/pitch/heading deg), one row per
    component; rows without data are left out.
    """
    e = evaluation.errors
    t = e.time - e.time[0]
    groups = [("position error (m)", e.pos_enu, e.pos_sigma, _AXES, 1.0)]
    if e.vel_enu is not None:
        groups.append(("velocity error (m/s)", e.vel_enu, e.vel_sigma, _AXES, 1.0))
    if e.euler is not None:
        groups.append(("attitude error (deg)", e.euler, e.euler_sigma,
                       ("roll", "pitch", "heading"), np.degrees(1.0)))
    fig, axes = plt.subplots(3, len(groups), figsize=(5 * len(groups), 8), sharex=True,
                             squeeze=False)
    for column, (title, values, sigma, names, scale) in enumerate(groups):
        for row in range(3):
            ax = axes[row, column]
            _shade(ax, windows, e.time[0])
            ax.plot(t, scale * values[:, row], color="tab:blue", lw=0.8, label="error")
            if sigma is not None:
                ax.plot(t, 3 * scale * sigma[:, row], color="tab:red", lw=0.6, ls="--",
                        label="±3σ")
                ax.plot(t, -3 * scale * sigma[:, row], color="tab:red", lw=0.6, ls="--")
            ax.set_ylabel(f"{names[row]} {title.split(' ')[-1]}")
            ax.grid(True, lw=0.3)
            if row == 0:
                ax.set_title(title)
                ax.legend(loc="upper right", fontsize="small")
        axes[2, column].set_xlabel("time (s)")
    fig.suptitle("Estimate minus truth (grey: GNSS outages)")
    return _save(fig, path)


def plot_heading(estimate, truth, path, windows=None):
    """True heading (azimuth, deg clockwise from north) of estimate and truth against time."""
    fig, ax = plt.subplots(figsize=(10, 4))
    t0 = truth.time[0]
    _shade(ax, windows, t0)
    for trajectory, label, style in ((truth, "truth", {"color": "k", "lw": 1.0}),
                                     (estimate, "estimate", {"color": "tab:blue", "lw": 0.8})):
        if trajectory.q_nb is not None:
            azimuth = np.degrees(azimuth_from_yaw(quat_to_euler(trajectory.q_nb)[2]))
            # Break the line where the azimuth wraps so no vertical jumps are drawn.
            azimuth[1:][np.abs(np.diff(azimuth)) > 180.0] = np.nan
            ax.plot(trajectory.time - t0, azimuth, label=label, **style)
    ax.set_xlabel("time (s)")
    ax.set_ylabel("heading (deg, clockwise from north)")
    ax.set_ylim(0.0, 360.0)
    ax.set_yticks(np.arange(0, 361, 45))
    ax.set_title("Heading")
    ax.grid(True, lw=0.3)
    ax.legend(loc="best")
    return _save(fig, path)


def plot_innovations(time, innovations, path, nis=None, dof=None, labels=None, windows=None):
    """Filter innovations (and NIS with its 95 % chi-square bounds) against time.

    Parameters
    ----------
    time : ndarray, shape (n,)
        s.
    innovations : ndarray, shape (n, k)
        Innovation components, in the measurement's unit (named in `labels`).
    nis : ndarray, shape (n,), optional
        Normalised innovation squared.
    dof : int, optional
        Measurement dimension, for the chi-square bounds of the NIS (defaults to k).
    labels : sequence of str, optional
        Axis labels with units, one per component.
    """
    from scipy.stats import chi2

    innovations = np.asarray(innovations, float).reshape(len(time), -1)
    k = innovations.shape[1]
    labels = labels or [f"component {i}" for i in range(k)]
    rows = k + (nis is not None)
    fig, axes = plt.subplots(rows, 1, figsize=(10, 2.2 * rows), sharex=True, squeeze=False)
    t0 = time[0]
    for i in range(k):
        ax = axes[i, 0]
        _shade(ax, windows, t0)
        ax.plot(time - t0, innovations[:, i], ".", ms=2, color="tab:blue")
        ax.set_ylabel(labels[i])
        ax.grid(True, lw=0.3)
    if nis is not None:
        ax = axes[-1, 0]
        _shade(ax, windows, t0)
        dof = dof or k
        ax.semilogy(time - t0, nis, ".", ms=2, color="tab:blue", label="NIS")
        for bound in chi2.ppf([0.025, 0.975], dof):
            ax.axhline(bound, color="tab:red", ls="--", lw=0.8)
        ax.plot([], [], color="tab:red", ls="--", label=f"95 % χ²({dof}) bounds")
        ax.set_ylabel("NIS (-)")
        ax.legend(loc="upper right", fontsize="small")
        ax.grid(True, lw=0.3)
    axes[0, 0].set_title("Innovations")
    axes[-1, 0].set_xlabel("time (s)")
    return _save(fig, path)


def write_plots(evaluation, estimate, truth, out_dir, windows=None):
    """Write the trajectory, error and (with attitude) heading plots into `out_dir`.

    Returns
    -------
    list of Path
    """
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    paths = [plot_trajectory(estimate, truth, out_dir / "trajectory.png", windows),
             plot_errors(evaluation, out_dir / "errors.png", windows)]
    if estimate.q_nb is not None or truth.q_nb is not None:
        paths.append(plot_heading(estimate, truth, out_dir / "heading.png", windows))
    return paths


def _enu(trajectory, origin):
    return ecef_to_enu(geodetic_to_ecef(trajectory.lat, trajectory.lon, trajectory.height),
                       *origin)


def _shade(ax, windows, t0):
    if windows is None:
        return
    for start, end in np.asarray(windows, float).reshape(-1, 2):
        ax.axvspan(start - t0, end - t0, **_OUTAGE_STYLE)


def _save(fig, path):
    path = Path(path)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path
