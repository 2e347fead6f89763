"""``strapdown`` node: mechanises ``imu/delta`` into ``ins/state`` and applies ``ins/correction``.

Corrections refer to the epoch the filter computed them for (their header stamp). The node keeps
the raw increments of the last ``history_s`` seconds, applies the correction to the state of that
epoch and re-mechanises the increments since, so a filter running late never corrects the wrong
epoch. Sensor-error estimates in a correction (bias and scale-factor increments) are accumulated
and applied to every increment from that epoch on, unless ``apply_sensor_corrections`` is false
(when the ``imu_preprocessor`` applies them instead: exactly one of the two must).
The ``mode`` of ``ins/state`` is the filter's mode carried by the last correction applied
(``MODE_ALIGNING`` before the first: the state is the start-up parameters; with
``correction_sequence`` > 0 the filter has levelled it, the heading may still be unknown); with no
correction for ``dead_reckoning_after_s`` the node keeps navigating and says
``MODE_DEAD_RECKONING`` instead of ``MODE_NAVIGATING``.

A gap in ``imu/delta`` (samples lost before or in the ``imu_preprocessor``) of up to
``max_imu_gap_s`` is bridged by holding the rates of the increment after it over the whole gap,
in steps of its length (that increment alone covers only its ``dt``: integrated over the gap it
would be free fall). A longer gap means the IMU was lost: the node starts a new run at the next
increment, as if restarted (kept history and older corrections dropped), and reports
``MODE_INVALID`` until the filter has re-synchronised it.
"""

from __future__ import annotations

import numpy as np
from ins_gnss_msgs.msg import ImuDelta, InsCorrection, InsState

from ..io import stamp_to_ns
from ..nav.conventions import yaw_from_azimuth
from ..nav.modes import MODES
from ..nav.rotations import quat_from_euler
from ..nav.strapdown import NavState
from ..nav.strapdown_sync import ClosedLoopStrapdown, Correction
from .base import SENSOR_QOS, STATE_QOS, NavNode, Param, run
from .convert import MODE_VALUES, increment_of, ins_state_payload, sensor_errors_of, vec

#: InsCorrection mode -> the filter's mode (:mod:`..nav.modes`).
_CORRECTION_MODES = {MODE_VALUES[mode]: mode for mode in MODES}
#: ClosedLoopStrapdown events -> diagnostics.
_EVENTS = {"lost": "imu lost: gap in increments beyond max_imu_gap_s, new run",
           "bridged": "gap in increments: bridged by holding the rates",
           "stale": "increment stamp not after the previous one: dropped"}


def correction_from_msg(msg: InsCorrection) -> Correction:
    """ins_gnss_msgs/InsCorrection -> Correction."""
    return Correction(stamp_to_ns(msg.header.stamp), msg.sequence,
                      vec(msg.position_error), vec(msg.velocity_error), vec(msg.attitude_error),
                      sensor_errors_of(msg), _CORRECTION_MODES[msg.mode])


class StrapdownNode(NavNode):
    PARAMS = (
        Param("init.latitude_deg", 59.9, "initial geodetic latitude, deg", -90.0, 90.0),
        Param("init.longitude_deg", 30.3, "initial longitude, deg", -180.0, 360.0),
        Param("init.altitude_m", 0.0, "initial ellipsoidal height, m", -1000.0, 100000.0),
        Param("init.roll_deg", 0.0, "initial roll (ROS, right side down positive), deg", -180.0, 180.0),
        Param("init.pitch_deg", 0.0, "initial pitch (ROS, nose down positive), deg", -90.0, 90.0),
        Param("init.heading_deg", 0.0, "initial azimuth of the body x axis, clockwise from north, deg",
              -360.0, 720.0),
        Param("init.velocity_enu", [0.0, 0.0, 0.0], "initial velocity ENU, m/s", -1000.0, 1000.0, length=3),
        Param("history_s", 5.0, "increments kept for re-mechanisation after a late correction, s",
              0.0, 120.0),
        Param("apply_sensor_corrections", True,
              "apply the filter's bias/scale estimates here (false: the imu_preprocessor does)"),
        Param("dead_reckoning_after_s", 2.0,
              "report DEAD_RECKONING when no correction arrived for this long, s", 0.1, 3600.0),
        Param("publish_every", 1, "publish ins/state every n-th increment", 1, 1000),
        Param("max_imu_gap_s", 2.5, "longest gap in imu/delta bridged by holding the rates of the "
              "increment after it; a longer one loses the IMU (state INVALID until the filter "
              "re-synchronises it), s", 0.0, 60.0),
    )

    def __init__(self, **kwargs):
        super().__init__("strapdown", **kwargs)
        p = self.p
        q0 = quat_from_euler(np.radians(p["init.roll_deg"]), np.radians(p["init.pitch_deg"]),
                             yaw_from_azimuth(np.radians(p["init.heading_deg"])))
        state0 = NavState(np.radians(p["init.latitude_deg"]), np.radians(p["init.longitude_deg"]),
                          p["init.altitude_m"], np.array(p["init.velocity_enu"], float), q0, np.nan)
        self.loop = ClosedLoopStrapdown(state0, p["history_s"], p["max_imu_gap_s"],
                                        p["apply_sensor_corrections"])
        self.count = 0
        self.pub = self.publisher(InsState, "ins/state", SENSOR_QOS)
        # Increments read and states written by field (CDR payloads), on DDS and on the bus.
        self.subscribe(ImuDelta, "imu/delta", self.on_delta, SENSOR_QOS, serialized=True)
        self.subscribe(InsCorrection, "ins/correction", self.on_correction, STATE_QOS)

    def on_delta(self, data: bytes) -> None:
        inc = increment_of(data)
        if inc.problem is not None:
            self.diag.count(inc.problem)
            return
        event = self.loop.add(inc.t, inc.dtheta, inc.dv, inc.dt)
        if event is not None:
            self.diag.count(_EVENTS[event])
            if event == "stale":
                return
        self.count += 1
        if self.count % self.p["publish_every"] == 0:
            self.publish_state()

    def on_correction(self, msg: InsCorrection) -> None:
        errors = [vec(msg.position_error), vec(msg.velocity_error), vec(msg.attitude_error)]
        if not all(np.all(np.isfinite(e)) for e in errors):
            self.diag.count("non-finite correction rejected")
            return
        if msg.mode not in _CORRECTION_MODES:
            self.diag.count("correction with an unknown mode rejected")
            return
        event = self.loop.correct(correction_from_msg(msg))
        if event == "older than this run":
            self.diag.count("correction older than this run ignored", log=False)
        elif event is not None:
            self.diag.count("correction epoch outside the kept history: applied to the latest "
                            "state")

    def publish_state(self) -> None:
        loop = self.loop
        comp, dt = loop.last_compensated
        angular_velocity, specific_force = (comp / dt).tolist()
        self.pub.publish(ins_state_payload(
            loop.state, angular_velocity, specific_force, loop.sensor,
            MODE_VALUES[loop.mode(self.p["dead_reckoning_after_s"])], loop.correction_sequence))


def main(args=None) -> int:
    return run(StrapdownNode, args)
