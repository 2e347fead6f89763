"""The heading of base_link from an IMU's own orientation estimate (an AHRS: sensor_msgs/Imu
``orientation``), when its covariance says the yaw is valid.

Many robot IMUs (Xsens, VectorNav, Microstrain, BNO055, Phidgets) publish their orientation in
ENU (REP-145). Its yaw is a heading source for the alignment and after it, like a magnetic
compass: a 9-axis unit refers it to magnetic north, and a 6-axis unit's yaw is relative to where
it started and says so by a huge or absent yaw covariance. Per REP-145 an orientation
covariance starting with -1 means "no orientation", all zeros "covariance unknown": neither is
taken, nor a yaw variance beyond :data:`MAX_YAW_VARIANCE` (a relative yaw).
"""
from __future__ import annotations

import math

import numpy as np

from ..nav.conventions import azimuth_from_yaw
from ..nav.rotations import quat_to_dcm

#: Largest yaw variance taken as an absolute heading, rad^2: (30 deg)^2.
MAX_YAW_VARIANCE = math.radians(30.0) ** 2


def orientation_heading(q_ns, covariance, c_bs):
    """The azimuth of the body x axis and its variance from an IMU orientation, or None.

    Parameters
    ----------
    q_ns : sequence of 4 float
        The IMU's orientation (w, x, y, z): ENU <- sensor frame.
    covariance : sequence of 9 float
        Its row-major orientation covariance (rotations about the fixed x, y, z axes), rad^2.
    c_bs : (3, 3) array_like
        The mounting: base_link <- sensor.

    Returns
    -------
    (azimuth, variance) : rad clockwise from the reference north in [0, 2 pi), rad^2; or None
        when the covariance does not say the yaw is valid.
    """
    cov = np.asarray(covariance, float)
    q = np.asarray(q_ns, float)
    if cov[0] == -1.0 or not np.all(np.isfinite(cov)) or not np.all(np.isfinite(q)):
        return None
    yaw_variance = float(cov[8])
    if not 0.0 < yaw_variance <= MAX_YAW_VARIANCE or not np.linalg.norm(q) > 0.5:
        return None
    x_n = quat_to_dcm(q / np.linalg.norm(q)) @ np.asarray(c_bs, float)[0]  # body x in ENU
    return float(azimuth_from_yaw(math.atan2(x_n[1], x_n[0]))), yaw_variance


class OrientationHeadings:
    """The headings of an IMU's orientation stream at no more than ``rate_hz`` (an AHRS
    publishes its orientation with every sample; the filter needs a few a second).

    Parameters
    ----------
    rate_hz : float
        Highest output rate, Hz (> 0).
    c_bs : (3, 3) array_like
        The mounting: base_link <- sensor.
    """

    def __init__(self, rate_hz: float, c_bs):
        self.period_ns = int(round(1e9 / rate_hz))
        self.c_bs = np.asarray(c_bs, float)
        self._next_ns = None
        self.without_yaw = 0  # orientations looked at whose covariance vouches for no yaw

    def due(self, t_ns: int) -> bool:
        """Whether :meth:`add` would look at a sample at t_ns: its orientation need not be
        read otherwise."""
        return self._next_ns is None or t_ns >= self._next_ns

    def add(self, t_ns: int, q_ns, covariance):
        """The heading of a sample at t_ns (as :func:`orientation_heading`) when one is due and
        valid, else None."""
        if not self.due(t_ns):
            return None
        # Looked at once a period, valid or not: the many drivers without an orientation
        # cost nothing per sample at 1 kHz.
        self._next_ns = t_ns + self.period_ns
        heading = orientation_heading(q_ns, covariance, self.c_bs)
        if heading is None and covariance[0] != -1.0 and any(c != 0.0 for c in covariance):
            # a covariance given (not "none" nor "unknown", which drivers without an
            # orientation leave) that rules the yaw out: worth a word on /diagnostics
            self.without_yaw += 1
        return heading
