"""Modes of the navigator and every transition between them.

=============== ====================================================== ===============
from            event                                                  to
=============== ====================================================== ===============
(any)           reset, or the IMU time jumps backwards                 ALIGNING
ALIGNING        the first fix levels the INS and starts the filter     ALIGNING
ALIGNING        heading known: first motion or a heading fix           NAVIGATING
                (:func:`~ins_gnss_ros.nav.alignment.rotate_yaw`)
NAVIGATING,     an aiding measurement accepted (:func:`after_accepted`) NAVIGATING, or
DEAD_RECKONING                                                         DEAD_RECKONING
                                                                       while degraded
NAVIGATING      an aiding measurement rejected while degraded          DEAD_RECKONING
                (:func:`after_rejected`)
NAVIGATING,     no accepted aiding for ``dr_timeout`` s at an epoch    DEAD_RECKONING
DEAD_RECKONING  (:func:`after_epoch`)
=============== ====================================================== ===============

Degraded (:meth:`~ins_gnss_ros.nav.integrity.Integrity.degraded`): a measurement kind was
forced in and its noise floor has not yet decayed, an aiding kind has been rejected for
``suspect_time`` s, or the turns show the IMU's rates wrong. While ALIGNING, GNSS is used only
at rest and no update changes the mode. Constraint updates (non-holonomic, zero angular rate at
a velocity fix) are not aiding: they never change the mode.
"""
ALIGNING, NAVIGATING, DEAD_RECKONING = "ALIGNING", "NAVIGATING", "DEAD_RECKONING"
MODES = (ALIGNING, NAVIGATING, DEAD_RECKONING)
#: Never the navigator's: the strapdown's state once its IMU was lost, until the filter has
#: re-synchronised it (:meth:`~ins_gnss_ros.nav.strapdown_sync.ClosedLoopStrapdown.mode`).
INVALID = "INVALID"


def after_accepted(mode, degraded):
    """Mode after an accepted aiding measurement (`degraded`: bool, see module docstring)."""
    if mode == ALIGNING:
        return mode
    return DEAD_RECKONING if degraded else NAVIGATING


def after_rejected(mode, degraded):
    """Mode after a rejected aiding measurement."""
    return DEAD_RECKONING if mode == NAVIGATING and degraded else mode


def after_epoch(mode, t, t_last_aid, dr_timeout):
    """Mode at the end of a filter epoch at time t (s) with the last accepted aiding at
    t_last_aid (s)."""
    if mode != ALIGNING and t - t_last_aid > dr_timeout:
        return DEAD_RECKONING
    return mode
