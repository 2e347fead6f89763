"""Phase-difference heading fused with the IMU in the EKF: simulated sea trial (issue 6).

The whole node graph runs on the in-process bus, nothing of the truth reaching the navigation:

    sim.scenarios.sea --> sim.imu_sim (MEMS, ADIS16405 class) --> imu/delta --> strapdown, ekf
                      \\-> sim/truth (5 Hz) --> gnss_simulator (real orbits, GPS L1 + Galileo E1,
                          10 deg mask, 2 mm + 2 mm/sin E phase noise, elevation-dependent
                          multipath) --> gnss/observations per antenna, gnss/ephemeris,
                          gnss/fix + gnss/vel (antenna 0 SPP) --> phase_heading --> gnss/heading
                          --> ekf (use_heading) <--> strapdown (ins/state, ins/correction)

IMU grade: seed 004 describes ISON-2's sensing block as cheap vibrating quartz gyros with a rate
error of (5e-3 ... 5e-2) deg/s and ISON-1 as an ADIS16405 MEMS IMU (plus one vertical FOG): the
project's ``MEMS_ADIS16405`` budget (0.05 deg/s turn-on bias, 0.007 deg/s in-run, 0.07 deg/s/rtHz
noise, 1000 ppm scale factor, 3' non-orthogonality) is that class. It runs at 100 Hz, ISON-1's
navigation rate (seed 004 section 3.2), half ISON-2's 200 Hz sensing rate, to keep the CPU cost
of a 600 s run in Python down.

Errors are the Euler-angle errors (heading clockwise from north, pitch, roll) of ``ins/state``
against the scenario after ``settle_s``, at the 10 Hz epochs the ekf node republishes as
``nav/odom``; the heading NEES uses the filter covariance published there with the same state.
The standalone row is the ``gnss/heading`` of the same run, over its FIXED epochs after
``settle_s``.

``--fuse-tilt`` runs the prototype below (:class:`TiltEkfNode`), which also fuses the pitch and
roll of the phase attitude; ``--grade tactical`` a FOG-class IMU instead of the MEMS one.

Usage: ``.venv/bin/python bench/bench_fused_heading.py [--quick] [--antennas 2 4] [--seeds 1 2]
[--grade NAME] [--fuse-tilt] [--duration S] [--phase-param NAME=VALUE ...]``
"""
from __future__ import annotations

import argparse
import sys
import time
from dataclasses import dataclass

import numpy as np
import rclpy
from builtin_interfaces.msg import Time
from ins_gnss_msgs.msg import Heading, ImuDelta, InsState
from rclpy.parameter import Parameter

from ins_gnss_ros.io import stamp_to_sec
from ins_gnss_ros.nav.conventions import seed_angles_from_quat, wrap_pi
from ins_gnss_ros.nav.measurements import Innovation
from ins_gnss_ros.nav import Navigator
from ins_gnss_ros.nav.sensor_errors import GRADES, MEMS_ADIS16405
from ins_gnss_ros.nav.strapdown import NavState
from ins_gnss_ros.nodes.base import InProcessBus
from ins_gnss_ros.nodes.convert import fill_ins_state, quat, to_vector3
from ins_gnss_ros.nodes.ekf_node import EkfNode
from ins_gnss_ros.nodes.gnss_simulator_node import GnssSimulatorNode
from ins_gnss_ros.nodes.phase_heading_node import PhaseHeadingNode
from ins_gnss_ros.nodes.strapdown_node import StrapdownNode
from ins_gnss_ros.sim import scenarios
from ins_gnss_ros.sim.imu_sim import ImuSpec, simulate_imu
from ins_gnss_ros.trial.evaluate import euler_error_jacobian
from ins_gnss_ros.trial.simulate import array_antennas

TWO_ANTENNAS = array_antennas(2, 1.5, 0.0, (0.0, 0.0, 1.0))          # 1.5 m fore-aft


def four_antennas(length: float = 1.5, width: float = 1.0) -> tuple:
    """Antennas at the corners of a length (fore-aft) x width (athwartship) rectangle, 1 m
    above the IMU (FLU, m): the layout of ``trial simulate --antennas 4 --array LxW``."""
    return array_antennas(4, length, width, (0.0, 0.0, 1.0))


STAMP0_S = 1_750_000_000   # ROS-axis stamp of trajectory time 0, whole s
IMU_RATE = 100.0           # Hz
GNSS_RATE = 5.0            # Hz
#: ISON-2's sensing-block ranges (seed 004 section 3.3): +-150 deg/s, +-30 m/s^2.
ISON2_SPEC = dict(gyro_range=np.radians(150.0), accel_range=30.0)


@dataclass
class FusedTrial:
    """Errors of one run after the settling time, rad (heading, pitch, roll: the seeds' angles).

    Attributes
    ----------
    fused : ndarray, shape (n, 3)
        ins/state minus truth at the nav/odom epochs.
    fused_sigma : ndarray, shape (n, 3)
        Their 1-sigma from the filter covariance.
    phase : ndarray, shape (m, 3)
        gnss/heading (FIXED) minus truth; roll NaN with 2 antennas.
    phase_sigma : ndarray, shape (m, 3)
        The node's reported 1-sigma.
    fixed_fraction : float
        FIXED gnss/heading epochs over all GNSS epochs after the settling time.
    fixed_total : int
        FIXED gnss/heading messages over the whole run.
    heading_accepted, heading_rejected : int
        Heading updates the ekf reported accepted / rejected (gate) on nav/status.
    wall_s : float
    """

    fused: np.ndarray
    fused_sigma: np.ndarray
    phase: np.ndarray
    phase_sigma: np.ndarray
    fixed_fraction: float
    fixed_total: int
    heading_accepted: int
    heading_rejected: int
    wall_s: float


# ---------------------------------------------------------------------------------------------
# Prototype, for review (not yet in the ekf node): pitch and roll of a multi-antenna phase
# attitude as an EKF measurement. The lead moves TiltFix next to HeadingFix in nav/navigator.py,
# tilt_innovation into nav/measurements.py, the _measure branch into Navigator._measure and the
# on_heading addition into EkfNode.on_heading (behind a parameter use_heading_tilt).
# ---------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class TiltFix:
    """Pitch (nose up) and roll (right side down) of base_link at time t, rad, and their
    variances, rad^2 (the Heading message's conventions); NaN where not observed."""

    t: float
    pitch: float
    roll: float
    pitch_variance: float
    roll_variance: float


def tilt_innovation(space, state, fix) -> Innovation:
    """Pitch and roll measurement of the error-state filter (the observed ones of the two).

    z = predicted - measured. :func:`~ins_gnss_ros.trial.evaluate.euler_error_jacobian` J gives
    d(roll, ROS pitch, azimuth) = J phi for C' = (I + [phi x]) C; the filter's attitude error is
    C_computed = (I - [phi x]) C_true (nav/ekf.py), hence H = -J, and the seeds' pitch is the
    negative of the ROS pitch: H_pitch = +J[1], H_roll = -J[0].

    Parameters
    ----------
    space : StateSpace
    state : NavState
        Solution at the measurement epoch.
    fix : TiltFix

    Returns
    -------
    Innovation
        Named "tilt", one or two rows.
    """
    _, pitch, roll = seed_angles_from_quat(state.q_nb)
    jac = euler_error_jacobian(np.asarray(state.q_nb, float)[None])[0]
    rows = [(pitch - fix.pitch, jac[1], fix.pitch_variance),
            (wrap_pi(roll - fix.roll), -jac[0], fix.roll_variance)]
    rows = [r for r in rows if np.isfinite(r[0]) and np.isfinite(r[2]) and r[2] > 0.0]
    H = np.zeros((len(rows), space.size))
    H[:, space["att"]] = [r[1] for r in rows]
    return Innovation("tilt", np.array([r[0] for r in rows]), H, np.diag([r[2] for r in rows]))


class TiltNavigator(Navigator):
    """Navigator that also applies TiltFix (once the heading is known, like HeadingFix)."""

    def _measure(self, m, st, epoch):
        if not isinstance(m, TiltFix):
            super()._measure(m, st, epoch)
        elif self.heading_known:
            innov = tilt_innovation(self.space, st, m)
            if innov.z.size:
                self._update(innov, epoch)


class TiltEkfNode(EkfNode):
    """ekf node that fuses the pitch and roll of a FIXED phase-difference Heading as well."""

    def __init__(self, **kwargs):
        super().__init__(**kwargs)
        self.navigator = TiltNavigator(self.config)

    def on_heading(self, msg: Heading) -> None:
        if msg.status == Heading.STATUS_FIXED and msg.source == Heading.SOURCE_PHASE_DIFFERENCE:
            self.navigator.add_measurement(TiltFix(stamp_to_sec(msg.header.stamp), msg.pitch,
                                                   msg.roll, msg.pitch_variance,
                                                   msg.roll_variance))
        super().on_heading(msg)


def stamp(t: float) -> Time:
    """Stamp of trajectory time t (s) in integer nanoseconds (a float sum with STAMP0_S would
    jitter by ~100 ns around the epoch grid; the gnss_simulator node tolerates 1 ms)."""
    ns = int(round(t * 1e9))
    return Time(sec=STAMP0_S + ns // 1_000_000_000, nanosec=ns % 1_000_000_000)


def since_start(msg) -> float:
    """Trajectory time (s) of a message's stamp."""
    return (msg.header.stamp.sec - STAMP0_S) + msg.header.stamp.nanosec * 1e-9


def seed_angle_errors(q_est, q_true):
    """(heading, pitch, roll) of q_est minus those of q_true, rad; heading wrapped to +-pi."""
    est, true = np.array(seed_angles_from_quat(q_est)), np.array(seed_angles_from_quat(q_true))
    d = est - true
    d[0] = wrap_pi(d[0])
    return d


def run_trial(seed, duration, antennas, settle_s=60.0, grade=MEMS_ADIS16405,
              ekf_overrides=(), fuse_tilt=False, context=None, phase_overrides=()) -> FusedTrial:
    """One simulated sea trial through imu/gnss simulation, phase_heading, ekf and strapdown.

    Parameters
    ----------
    seed : int
        Scenario, IMU and GNSS error seed.
    duration : float
        Length, s.
    antennas : tuple of (3,) tuples
        Antenna positions in base_link FLU, m (antenna 0 gives gnss/fix and the ekf lever arm).
    settle_s : float
        Errors are collected from this time on, s.
    grade : ImuGrade
        Simulated IMU, also the ekf's noise model.
    ekf_overrides : sequence of Parameter
        Extra ekf parameters.
    fuse_tilt : bool
        Run the prototype :class:`TiltEkfNode` (pitch and roll of the phase attitude fused too).
    context : rclpy.Context, optional
        Context of the nodes (default: the global one).
    phase_overrides : sequence of Parameter
        Extra phase_heading parameters.
    """
    wall = time.perf_counter()
    sc = scenarios.sea(duration=duration, seed=seed, rate=IMU_RATE, oversample=2)
    tr = sc.trajectory
    imu = simulate_imu(tr, ImuSpec(grade, rate=IMU_RATE, **ISON2_SPEC), seed=seed + 1000)
    arms = [float(v) for a in antennas for v in a]
    bus = InProcessBus()
    lat0, lon0 = np.degrees(tr.lat[0]), np.degrees(tr.lon[0])
    nodes = [
        # The strapdown starts from a position known to ~1 km and no attitude: the ekf aligns it.
        StrapdownNode(bus=bus, context=context, parameter_overrides=[
            Parameter("init.latitude_deg", value=round(lat0, 2)),
            Parameter("init.longitude_deg", value=round(lon0, 2))]),
        (TiltEkfNode if fuse_tilt else EkfNode)(bus=bus, context=context, parameter_overrides=[
            Parameter("lever_arm", value=arms[:3]), Parameter("imu_grade", value=grade.name),
            Parameter("layout", value="21"), Parameter("bias_model", value="rw"),
            Parameter("use_heading", value=True), *ekf_overrides]),
        GnssSimulatorNode(bus=bus, context=context, parameter_overrides=[
            Parameter("source", value="truth"), Parameter("lever_arms", value=arms),
            Parameter("rate_hz", value=GNSS_RATE), Parameter("seed", value=seed)]),
        PhaseHeadingNode(bus=bus, context=context, parameter_overrides=[
            Parameter("antenna_positions", value=arms), *phase_overrides]),
    ]
    # nav/odom is published from the ins/state the ekf has just received: pair the two.
    last_state, fused_log, headings = [None], [], []
    bus.subscribe("ins/state", lambda m: last_state.__setitem__(0, m))
    bus.subscribe("nav/odom", lambda m: fused_log.append(
        (last_state[0], np.reshape(m.pose.covariance, (6, 6))[3:, 3:])))
    bus.subscribe("gnss/heading", headings.append)
    verdicts = []    # accepted flag of every heading update the ekf reports
    bus.subscribe("nav/status", lambda m: verdicts.extend(
        u.accepted for u in m.updates if u.name == "heading"))
    gnss_every = int(round(IMU_RATE / GNSS_RATE))
    for k in range(len(imu.t)):
        if k % gnss_every == 0:   # truth of the epoch at the start of increment k
            truth = InsState()
            fill_ins_state(truth, NavState(tr.lat[k], tr.lon[k], tr.h[k], tr.v_enu[k],
                                           tr.q_nb[k], 0.0))
            truth.header.stamp = stamp(tr.t[k])
            truth.angular_velocity = to_vector3(tr.omega_ib_b[k])
            bus.publish("sim/truth", truth)
            bus.drain()
        delta = ImuDelta(dt=float(imu.dt))
        delta.header.stamp = stamp(imu.t[k])
        delta.delta_angle, delta.delta_velocity = to_vector3(imu.dtheta[k]), to_vector3(imu.dv[k])
        bus.publish("imu/delta", delta)
        bus.drain()
    fused, fused_sigma = [], []
    for msg, cov in fused_log:
        t = since_start(msg)
        k = int(round((t - tr.t[0]) / tr.dt))
        if t < settle_s or k >= len(tr.t):
            continue
        fused.append(seed_angle_errors(quat(msg.orientation), tr.q_nb[k]))
        # euler_error_jacobian gives (roll, pitch, azimuth) of an ENU error rotation; the seeds'
        # pitch is the negative of the ROS pitch, which leaves its variance unchanged.
        jac = euler_error_jacobian(tr.q_nb[k][None])[0]
        fused_sigma.append(np.sqrt(np.diag(jac @ cov @ jac.T))[[2, 1, 0]])
    phase, phase_sigma, n_epochs = [], [], 0
    for h in headings:
        t = since_start(h)
        if t < settle_s:
            continue
        n_epochs += 1
        if h.status != Heading.STATUS_FIXED:
            continue
        k = int(round((t - tr.t[0]) / tr.dt))
        true = seed_angles_from_quat(tr.q_nb[k])
        phase.append((wrap_pi(h.azimuth - true[0]), h.pitch - true[1], h.roll - true[2]))
        phase_sigma.append(np.sqrt([h.azimuth_variance, h.pitch_variance, h.roll_variance]))
    accepted = sum(verdicts)
    for node in nodes:
        node.destroy_node()
    return FusedTrial(np.array(fused), np.array(fused_sigma), np.array(phase),
                      np.array(phase_sigma), len(phase) / max(n_epochs, 1),
                      sum(h.status == Heading.STATUS_FIXED for h in headings), accepted,
                      len(verdicts) - accepted,
                      time.perf_counter() - wall)


def rms(x):
    """Column RMS of an (n, k) array, NaN columns ignored."""
    x = np.asarray(x)
    n = np.sum(np.isfinite(x), axis=0)
    return np.sqrt(np.where(n > 0, np.nansum(x ** 2, axis=0) / np.maximum(n, 1), np.nan))


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="one short run per configuration")
    ap.add_argument("--duration", type=float, default=600.0, help="run length, s")
    ap.add_argument("--seeds", type=int, nargs="+", default=[1, 2])
    ap.add_argument("--fuse-tilt", action="store_true",
                    help="also fuse the phase pitch/roll (prototype TiltEkfNode)")
    ap.add_argument("--antennas", type=int, choices=(2, 4), nargs="+", default=[2, 4])
    ap.add_argument("--grade", choices=sorted(GRADES), default=MEMS_ADIS16405.name,
                    help="simulated IMU and ekf noise model (sensor_errors.GRADES)")
    ap.add_argument("--array", default="1.5x1.0", metavar="LENGTHxWIDTH",
                    help="4-antenna rectangle, m (ISON-2's antenna unit is about 2.7 m long, "
                         "seed 004 section 3.3: 2.7x1.2)")
    ap.add_argument("--phase-param", action="append", default=[], metavar="NAME=FLOAT",
                    help="phase_heading parameter override, e.g. multipath.phase_m=0")
    args = ap.parse_args(argv)
    phase_overrides = [Parameter(name, value=float(value)) for name, value in
                       (item.split("=", 1) for item in args.phase_param)]
    duration, seeds = (120.0, args.seeds[:1]) if args.quick else (args.duration, args.seeds)
    variant = args.grade + (" + pitch/roll fusion" if args.fuse_tilt else "") + "".join(
        f"; phase_heading {item}" for item in args.phase_param)
    print(f"{variant}; sea scenario {duration:.0f} s per seed; errors after 60 s (deg RMS)\n")
    print("| run | fused heading | fused pitch | fused roll | heading NEES | standalone heading "
          "| standalone pitch | standalone roll | standalone heading NEES | FIXED "
          "| FIXED msgs: updates accepted/rejected | wall s |")
    print("|---|---|---|---|---|---|---|---|---|---|---|---|")
    rclpy.init()
    try:
        length, width = (float(x) for x in args.array.split("x"))
        configs = {2: ("2 ant. 1.5 m", TWO_ANTENNAS),
                   4: (f"4 ant. {length:g} x {width:g} m", four_antennas(length, width))}
        for label, antennas in (configs[n] for n in args.antennas):
            for seed in seeds:
                r = run_trial(seed, duration, antennas, grade=GRADES[args.grade],
                              fuse_tilt=args.fuse_tilt, phase_overrides=phase_overrides)
                f, p = np.degrees(rms(r.fused)), np.degrees(rms(r.phase))
                nees = np.mean((r.fused[:, 0] / r.fused_sigma[:, 0]) ** 2)
                nees_phase = np.mean((r.phase[:, 0] / r.phase_sigma[:, 0]) ** 2)
                print(f"| {label}, seed {seed} | {f[0]:.3f} | {f[1]:.3f} | {f[2]:.3f} | {nees:.2f} "
                      f"| {p[0]:.3f} | {p[1]:.3f} | {p[2]:.3f} | {nees_phase:.3f} "
                      f"| {100 * r.fixed_fraction:.1f} % "
                      f"| {r.fixed_total}: {r.heading_accepted}/{r.heading_rejected} "
                      f"| {r.wall_s:.0f} |",
                      flush=True)
    finally:
        rclpy.shutdown()
    return 0


if __name__ == "__main__":
    sys.exit(main())
