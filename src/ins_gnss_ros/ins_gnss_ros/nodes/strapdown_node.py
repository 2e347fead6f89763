"""``strapdown`` node: mechanises ``imu/delta`` into ``ins/state`` and applies ``ins/correction``.

Corrections refer to the epoch the filter computed them for (their header stamp). The node keeps
the raw increments of the last ``history_s`` seconds, applies the correction to the state of that
epoch and re-mechanises the increments since, so a filter running late never corrects the wrong
epoch. Sensor-error estimates in a correction (bias and scale-factor increments) are accumulated
and applied to every increment from that epoch on, unless ``apply_sensor_corrections`` is false
(when the ``imu_preprocessor`` applies them instead: exactly one of the two must).
Without corrections the node keeps navigating (dead reckoning) and says so in ``mode``.

A gap in ``imu/delta`` (samples lost before or in the ``imu_preprocessor``) of up to
``max_imu_gap_s`` is bridged by holding the rates of the increment after it over the whole gap,
in steps of its length (that increment alone covers only its ``dt``: integrated over the gap it
would be free fall). A longer gap means the IMU was lost: the node starts a new run at the next
increment, as if restarted (kept history and older corrections dropped), and reports
``MODE_INVALID`` until the filter has re-synchronised it.
"""

from __future__ import annotations

from collections import deque
from dataclasses import dataclass, field

import numpy as np
from ins_gnss_msgs.msg import ImuDelta, InsCorrection, InsState

from ..io import new, stamp_to_sec
from ..nav.conventions import yaw_from_azimuth
from ..nav.rotations import quat_from_euler
from ..nav.strapdown import NavState, Strapdown
from .base import SENSOR_QOS, STATE_QOS, NavNode, Param, run
from .convert import fill_ins_state, held_increments, increment_problem, set_vector3, vec


@dataclass
class SensorCorrection:
    """Applied estimates: measured increment = (1 + s) * true + b * dt, per axis."""

    gyro_bias: np.ndarray = field(default_factory=lambda: np.zeros(3))
    accel_bias: np.ndarray = field(default_factory=lambda: np.zeros(3))
    gyro_scale: np.ndarray = field(default_factory=lambda: np.zeros(3))
    accel_scale: np.ndarray = field(default_factory=lambda: np.zeros(3))

    def compensate(self, dtheta, dv, dt):
        return ((dtheta - self.gyro_bias * dt) / (1.0 + self.gyro_scale),
                (dv - self.accel_bias * dt) / (1.0 + self.accel_scale))

    def add(self, msg: InsCorrection) -> "SensorCorrection":
        return SensorCorrection(self.gyro_bias + vec(msg.gyro_bias),
                                self.accel_bias + vec(msg.accel_bias),
                                self.gyro_scale + vec(msg.gyro_scale_factor),
                                self.accel_scale + vec(msg.accel_scale_factor))


@dataclass
class _Step:
    """One mechanised interval: the raw increments and the state they produced."""

    dtheta: np.ndarray
    dv: np.ndarray
    dt: float
    state: NavState


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
        # The vertical channel is left free here: the filter's height aiding closes that loop.
        self.ins = Strapdown(state0)
        self.sensor = SensorCorrection()
        self.history: deque[_Step] = deque()
        self.last_correction_t = -np.inf
        self.t_start = np.inf  # start of the first increment of this run, s
        self.correction_sequence = 0
        self.lost = False  # the IMU was lost (gap beyond max_imu_gap_s), no correction since
        self.count = 0
        self.last_compensated = None  # (dtheta, dv, dt) of the latest step, sensor-corrected
        self.pub = self.publisher(InsState, "ins/state", SENSOR_QOS)
        self.subscribe(ImuDelta, "imu/delta", self.on_delta, SENSOR_QOS)
        self.subscribe(InsCorrection, "ins/correction", self.on_correction, STATE_QOS)

    # -- increments ----------------------------------------------------------------------------
    def on_delta(self, msg: ImuDelta) -> None:
        problem = increment_problem(msg)
        if problem is not None:
            self.diag.count(problem)
            return
        t = stamp_to_sec(msg.header.stamp)
        dtheta, dv = vec(msg.delta_angle), vec(msg.delta_velocity)
        state = self.ins.state
        interval = t - state.t
        if interval > self.p["max_imu_gap_s"] + msg.dt:
            self.diag.count("imu lost: gap in increments beyond max_imu_gap_s, new run")
            self.lost = not np.isnan(state.t)
            self.history.clear()
            state = NavState(state.lat, state.lon, state.h, state.v_enu, state.q_nb, np.nan)
        steps = [(t, dtheta, dv)]
        if np.isnan(state.t):  # first increment (of this run) fixes the time axis
            self.t_start = t - msg.dt
            self.ins.state = NavState(state.lat, state.lon, state.h, state.v_enu, state.q_nb, t - msg.dt)
        elif t <= state.t:
            self.diag.count("increment stamp not after the previous one: dropped")
            return
        elif interval - msg.dt > 0.5 * msg.dt:
            # Hold the increment's rates over the interval its stamp says it covers, in steps
            # of its length as the ekf does (a correction may refer to an epoch in the gap).
            self.diag.count("gap in increments: bridged by holding the rates")
            steps = zip(*held_increments(t, dtheta, dv, msg.dt, interval))
        for t_k, dtheta_k, dv_k in steps:
            self._step(dtheta_k, dv_k, t_k - self.ins.state.t)
        self.count += 1
        if self.count % self.p["publish_every"] == 0:
            self.publish_state()

    def _step(self, dtheta, dv, dt) -> None:
        comp_dtheta, comp_dv = self._compensate(dtheta, dv, dt)
        self.ins.step(comp_dtheta, comp_dv, dt)
        self.last_compensated = (comp_dtheta, comp_dv, dt)
        self.history.append(_Step(dtheta, dv, dt, self.ins.state))
        while self.history and self.history[-1].state.t - self.history[0].state.t > self.p["history_s"]:
            self.history.popleft()

    def _compensate(self, dtheta, dv, dt):
        if self.p["apply_sensor_corrections"]:
            return self.sensor.compensate(dtheta, dv, dt)
        return dtheta, dv

    # -- closed loop ---------------------------------------------------------------------------
    def on_correction(self, msg: InsCorrection) -> None:
        errors = [vec(msg.position_error), vec(msg.velocity_error), vec(msg.attitude_error)]
        if not all(np.all(np.isfinite(e)) for e in errors):
            self.diag.count("non-finite correction rejected")
            return
        t_c = stamp_to_sec(msg.header.stamp)
        if not self.history or t_c < self.t_start:
            # ins/correction is TRANSIENT_LOCAL: a restarted node is first handed the corrections
            # of its previous run, which refer to another state. Applied to this one they would
            # be wrong while carrying the filter's current sequence (published as synchronised).
            self.diag.count("correction older than this run ignored", log=False)
            return
        # Index of the step whose end state is the correction epoch (half a step tolerance),
        # searched from the newest: the filter lags the strapdown by a few steps only.
        replay_from = None
        for i in range(len(self.history) - 1, -1, -1):
            step = self.history[i]
            if abs(step.state.t - t_c) <= 0.5 * step.dt:
                replay_from = i
                break
            if step.state.t < t_c:
                break
        if replay_from is None:
            self.diag.count("correction epoch outside the kept history: applied to the latest state")
            self.ins.correct(*errors)
            self.sensor = self.sensor.add(msg)
        else:
            later = list(self.history)[replay_from + 1:]
            for _ in later:
                self.history.pop()
            self.ins.state = self.history[-1].state
            self.ins.correct(*errors)
            self.history[-1].state = self.ins.state
            self.sensor = self.sensor.add(msg)
            for step in later:
                self._step(step.dtheta, step.dv, step.dt)
        self.correction_sequence = msg.sequence
        self.last_correction_t = t_c
        self.lost = False

    def publish_state(self) -> None:
        state = self.ins.state
        msg = new(InsState)
        msg.header.frame_id = "map"
        fill_ins_state(msg, state)
        dtheta, dv, dt = self.last_compensated
        set_vector3(msg.angular_velocity, dtheta / dt)
        set_vector3(msg.specific_force, dv / dt)
        set_vector3(msg.gyro_bias, self.sensor.gyro_bias)
        set_vector3(msg.accel_bias, self.sensor.accel_bias)
        set_vector3(msg.gyro_scale_factor, self.sensor.gyro_scale)
        set_vector3(msg.accel_scale_factor, self.sensor.accel_scale)
        silent = state.t - self.last_correction_t > self.p["dead_reckoning_after_s"]
        msg.mode = InsState.MODE_INVALID if self.lost else (
            InsState.MODE_DEAD_RECKONING if silent else InsState.MODE_NAVIGATING)
        msg.correction_sequence = self.correction_sequence
        self.pub.publish(msg)


def main(args=None) -> int:
    return run(StrapdownNode, args)
