"""The body attitude that GNSS antennas give, as ``gnss/heading`` (ins_gnss_msgs/Heading)
carries it: from a receiver's own baseline solution with the baseline's mounting offsets
(:func:`receiver_heading`), or from the phase-difference attitude core
(:func:`attitude_heading`).

Conventions of the message: azimuth of the body x axis clockwise from true north, pitch nose-up
positive (the seeds' azimuth-style convention, the negative of the ROS pitch of
:mod:`.attitude`), roll right side down positive; NaN where not observed.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from ..nav.conventions import wrap_2pi

if TYPE_CHECKING:  # the solver (scipy.stats) is not needed for receiver headings
    from .attitude import AttitudeSolution

#: Baselines within this angle of the body x axis (either direction) give pitch.
FORE_AFT_TOLERANCE = math.radians(15.0)


@dataclass(frozen=True)
class GnssHeading:
    """One heading measurement.

    Attributes
    ----------
    status : str
        "FIXED", "FLOAT" or "NONE" (no usable solution: the angles are NaN).
    azimuth : float
        Azimuth of the body x axis, clockwise from true north [rad], in [0, 2 pi).
    pitch, roll : float
        Nose-up pitch and right-side-down roll [rad].
    var_azimuth, var_pitch, var_roll : float
        Their variances [rad^2].
    baseline_length : float
        Length of the (first) baseline [m].
    satellites : int
        Satellites used (0: not reported).
    ratio : float
        Smallest ambiguity ratio-test statistic of the fixes in use (NaN: none).
    """

    status: str
    azimuth: float
    pitch: float
    roll: float
    var_azimuth: float
    var_pitch: float
    var_roll: float
    baseline_length: float
    satellites: int
    ratio: float


def receiver_heading(baseline_azimuth: float, azimuth_std: float, azimuth_offset: float,
                     elevation: float = math.nan, elevation_offset: float = 0.0,
                     pitch_std: float = math.nan, baseline_length: float = math.nan
                     ) -> GnssHeading:
    """Body heading (status FIXED) of a receiver's antenna-baseline solution.

    Parameters
    ----------
    baseline_azimuth : float
        Azimuth of the baseline (primary -> secondary antenna), clockwise from true north [rad].
    azimuth_std, pitch_std : float
        1-sigma accuracies [rad].
    azimuth_offset, elevation_offset : float
        Mounting: the baseline's azimuth in the body frame (clockwise from body x, i.e.
        towards starboard) and its elevation above the body x-y plane [rad].
    elevation : float
        Elevation of the baseline above the horizon [rad] (NaN: not observed).
    baseline_length : float
        [m].

    Notes
    -----
    Body azimuth = baseline azimuth - azimuth offset.  Pitch (nose up) is observable from one
    baseline only along the body x axis: for a baseline within ``FORE_AFT_TOLERANCE`` of it,
    pitch = +-(elevation - elevation offset) (sign of cos(azimuth offset)), the roll then
    leaking in by sin(azimuth offset); otherwise NaN.
    """
    fore_aft = abs(math.sin(azimuth_offset)) <= math.sin(FORE_AFT_TOLERANCE)
    pitch = math.copysign(1.0, math.cos(azimuth_offset)) * (elevation - elevation_offset) \
        if fore_aft else math.nan
    return GnssHeading(
        "FIXED", azimuth=float(wrap_2pi(baseline_azimuth - azimuth_offset)), pitch=pitch,
        roll=math.nan, var_azimuth=azimuth_std ** 2,
        var_pitch=pitch_std ** 2 if math.isfinite(pitch) else math.nan, var_roll=math.nan,
        baseline_length=float(baseline_length), satellites=0, ratio=math.nan)


def attitude_heading(sol: AttitudeSolution, use_float: bool) -> GnssHeading:
    """Body heading of a phase-attitude solution: its angles when FIXED (or FLOAT with
    ``use_float``, with the float solution's own variances), else status NONE; the satellite
    count and ratio always."""
    satellites = len({s[:3] for s in sol.satellites})
    usable = sol.status == "FIXED" or (sol.status == "FLOAT" and use_float)
    if not (usable and np.isfinite(sol.azimuth)):
        nan = math.nan
        return GnssHeading("NONE", azimuth=nan, pitch=nan, roll=nan, var_azimuth=nan,
                           var_pitch=nan, var_roll=nan, baseline_length=nan,
                           satellites=satellites, ratio=float(sol.ratio))
    return GnssHeading(
        sol.status, azimuth=float(sol.azimuth),
        pitch=-float(sol.pitch),  # the core's (ROS) pitch is nose-down positive
        roll=float(sol.roll), var_azimuth=float(sol.var_azimuth),
        var_pitch=float(sol.var_pitch), var_roll=float(sol.var_roll),
        baseline_length=float(np.linalg.norm(sol.baselines[0])), satellites=satellites,
        ratio=float(sol.ratio))


__all__ = ["FORE_AFT_TOLERANCE", "GnssHeading", "attitude_heading", "receiver_heading"]
