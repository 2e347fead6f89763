"""The SAR way of judging a trajectory (seed 003): the error of the relative position over the
synthetic aperture.

A SAR forms its image from the echoes along an aperture of a few seconds; what blurs it is how
the antenna phase centre's (APC's) measured path departs from the true one within the
aperture. A constant offset only shifts the image and a linear drift of the error only tilts
or stretches it (autofocus and the geocoding take both out), so over each window of the
aperture's length the ENU position error is fitted by a straight line in time, per axis, and
what remains is the relative error. Its RMS (3-D, over all epochs of all windows) is reported
next to the absolute error.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class ApertureError:
    """Relative position error over windows of one length.

    Attributes
    ----------
    window_s : float
    rms_m, max_m : float
        3-D residual after the linear fit, RMS and largest, m.
    windows : int
        Windows evaluated (consecutive, not overlapping; a window needs 3 epochs).
    """

    window_s: float
    rms_m: float
    max_m: float
    windows: int


def aperture_error(time, pos_error_enu, window_s) -> ApertureError:
    """The relative position error over consecutive windows of ``window_s`` seconds.

    Parameters
    ----------
    time : (k,) s, increasing
    pos_error_enu : (k, 3) m
        Position error (estimate - truth) of the point the SAR cares about.
    window_s : float
        Aperture length, s.
    """
    time = np.asarray(time, float)
    error = np.asarray(pos_error_enu, float)
    if not window_s > 0.0:
        raise ValueError(f"an aperture must be > 0 s, got {window_s}")
    index = np.floor((time - time[0]) / window_s).astype(np.int64)
    residuals = []
    for w in np.unique(index):
        sel = index == w
        if sel.sum() < 3 or time[sel][-1] - time[sel][0] < 0.5 * window_s:
            continue  # too few epochs, or the run's ragged end
        t = time[sel] - time[sel].mean()
        design = np.column_stack([np.ones_like(t), t])
        coef, *_ = np.linalg.lstsq(design, error[sel], rcond=None)
        residuals.append(np.linalg.norm(error[sel] - design @ coef, axis=1))
    if not residuals:
        return ApertureError(float(window_s), np.nan, np.nan, 0)
    r = np.concatenate(residuals)
    return ApertureError(float(window_s), float(np.sqrt(np.mean(r * r))), float(r.max()),
                         len(residuals))


def markdown_lines(results) -> list:
    """Lines of a Markdown table of ApertureError results."""
    lines = ["| aperture | relative position error RMS | max | windows |", "|---:|---:|---:|---:|"]
    lines += [f"| {a.window_s:g} s | {a.rms_m * 1e3:.2f} mm | {a.max_m * 1e3:.2f} mm | "
              f"{a.windows} |" for a in results]
    return lines
