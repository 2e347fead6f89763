"""Setting the navigator's pose from outside, as robot_localization's ``set_pose`` does.

robot_localization (``RosFilter::setPoseCallback``) forgets its measurement history and
continues from the given pose with the given covariance, ignoring data older than the pose.
Here the same: the navigator is reset and started NAVIGATING from the pose at its stamp
(:meth:`Navigator.start_from`), so measurements stamped before it are refused as too old. What
an INS has beyond the pose is kept: the velocity of the current solution (zero before the
filter runs: a pose is set at rest), the running sensor-error estimates and their covariance.
"""
from __future__ import annotations

import numpy as np

from .alignment import initial_covariance
from .strapdown import NavState


def set_pose(navigator, t: float, lat: float, lon: float, h: float, q_nb, pose_cov) -> None:
    """Navigate on from the pose at time t (s).

    Parameters
    ----------
    navigator : Navigator
    lat, lon, h : float
        Position of the IMU, rad, rad, m (ellipsoidal).
    q_nb : (4,) array_like
        Attitude ENU <- FLU, [w, x, y, z].
    pose_cov : (6, 6) array_like
        Covariance of the position (ENU, m^2) and of the attitude (small rotations about ENU
        axes, rad^2), the order of ``geometry_msgs/PoseWithCovariance``. A zero or negative
        variance (a pose given without one) takes the configured initial sigma instead; the
        position-attitude cross terms are not used.
    """
    space, cfg = navigator.space, navigator.config
    pose_cov = np.asarray(pose_cov, float).reshape(6, 6)
    if navigator.started:
        P = navigator.covariance().copy()
        v_enu = navigator.solution.v_enu.copy()
    else:
        P = initial_covariance(space, cfg.noise, cfg.sigma_pos0, cfg.sigma_vel0, cfg.sigma_tilt0)
        v_enu = np.zeros(3)
    estimates = {name: np.array(v, float) for name, v in navigator.estimates.items()}
    for block, cov, sigma0 in (("pos", pose_cov[:3, :3], cfg.sigma_pos0),
                               ("att", pose_cov[3:, 3:], cfg.sigma_tilt0)):
        rows = space[block]
        P[rows, :] = 0.0
        P[:, rows] = 0.0
        given = np.where(np.diag(cov) > 0.0, np.diag(cov), sigma0 ** 2)
        P[rows, rows] = np.diag(given)
    navigator.reset()
    navigator.start_from(NavState(lat, lon, h, v_enu, np.asarray(q_nb, float), t), estimates, P)
    # A follower of the solution (the strapdown node) must move to the new pose.
    navigator.revision += 1
