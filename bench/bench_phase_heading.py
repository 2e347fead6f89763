"""Simulated sea trial of the ``phase_heading`` node (issue 6): prints the acceptance numbers.

Truth: the seed 004 Lab 2 ``sea`` scenario (vessel at 6-10 m/s with course changes, in waves;
:func:`ins_gnss_ros.sim.scenarios.sea`). Observations: :class:`~ins_gnss_ros.gnss.simulator.
GnssSimulator` from real broadcast orbits (GPS L1 + Galileo E1, 10 deg mask, 2 mm + 2 mm/sin E
phase noise, elevation-dependent Gauss-Markov multipath, Klobuchar + Saastamoinen, one receiver
clock; GPS L1 C/A phase valid once its half-cycle ambiguity is resolved after 6 s of lock, the
pilot-tracked Galileo E1-C phase from lock), turned into ``gnss/observations`` and
``gnss/ephemeris`` messages as the ``gnss_simulator`` node publishes them (``nodes/gnss_messages``),
and fed to a
``PhaseHeadingNode`` on the in-process bus. Nothing of the truth reaches the node, except with
``--tilt-prior SIGMA_DEG``: then an ``ins/state`` in MODE_ALIGNING (corrected once) is published
with every epoch, as an INS levelled by its accelerometers but not aligned in heading would: the
true attitude with a slowly varying tilt error (first-order Gauss-Markov about East and North,
σ = SIGMA_DEG each, correlation time ``TILT_TAU_S``) and a heading off by a random constant of up
to ±180° per run.

Per epoch a FIXED solution is *correct* when every double-difference ambiguity the solver holds
equals the simulator's integer (DD of the true N of both antennas and both satellites), *wrong*
otherwise. Time to first fix counts from the first epoch (the receiver's half-cycle resolution
included) and, separately, from the first epoch with valid carrier phases.

With ``--independent`` the simulator is the independent one: its ionosphere, troposphere,
orbits and clocks differ from the broadcast models (:mod:`ins_gnss_ros.gnss.broadcast_residuals`)
and every run draws its multipath parameters (:func:`held_out_multipath`: σ0 of code and phase
x 0.5-2, elevation scale 10-30 deg, correlation times 10-120 s) that the node's ``multipath.*``
defaults (0.01 m, 20 deg, 30 s) do not know, on held-out seeds (1000 + the usual ones).

Usage: ``.venv/bin/python bench/bench_phase_heading.py [--quick] [--ratio R]
[--param NAME=VALUE ...] [--first-fix START:STOP] [--tilt-prior SIGMA_DEG] [--independent]``
"""
from __future__ import annotations

import argparse
import math
import sys
import time
import warnings
from dataclasses import dataclass, field, replace

import numpy as np
import rclpy
from ins_gnss_msgs.msg import InsState
from rclpy.parameter import Parameter

from ins_gnss_ros.gnss import ephemeris_data
from ins_gnss_ros.gnss.broadcast_residuals import BroadcastResiduals
from ins_gnss_ros.gnss.multipath import MultipathModel
from ins_gnss_ros.gnss.simulator import GnssSimulator, SimulatorConfig, SlipEvent
from ins_gnss_ros.io import sec_to_stamp
from ins_gnss_ros.nav.conventions import seed_angles_from_quat, wrap_pi
from ins_gnss_ros.nav.rotations import quat_from_rotvec, quat_mul
from ins_gnss_ros.nodes.base import InProcessBus
from ins_gnss_ros.nodes.convert import to_quaternion
from ins_gnss_ros.nodes.gnss_messages import ephemeris_msg, observations_msg
from ins_gnss_ros.nodes.phase_heading_node import PhaseHeadingNode
from ins_gnss_ros.sim import scenarios

TWO_ANTENNAS = ((0.75, 0.0, 1.0), (-0.75, 0.0, 1.0))                 # 1.5 m fore-aft
FOUR_ANTENNAS = ((0.75, 0.5, 1.0), (-0.75, 0.5, 1.0), (0.75, -0.5, 1.0), (-0.75, -0.5, 1.0))
STAMP0 = 1000.0   # ROS-axis stamp of trajectory time 0, s
#: Correlation time of the simulated INS tilt error, s: a levelled INS's tilt follows the
#: accelerometer bias and the Schuler loop, minutes rather than seconds.
TILT_TAU_S = 120.0


@dataclass
class Trial:
    """Per-epoch outcome of one run."""

    t: list = field(default_factory=list)
    status: list = field(default_factory=list)      # Heading.status
    correct: list = field(default_factory=list)     # held ambiguities all true (FIXED only)
    err: list = field(default_factory=list)         # (azimuth, pitch, roll) error, rad
    sigma: list = field(default_factory=list)       # their reported 1-sigma, rad
    phase_valid: list = field(default_factory=list)  # carrier phases valid on every antenna
    slips: tuple = ()                                # injected SlipEvents
    slips_detected: int = 0                          # of them, flagged at the epoch they occur
    max_norm_err_after_slip: float = 0.0             # max |heading err|/sigma within 5 s after
    seconds_node: float = 0.0
    tilt_rejections: int = 0                         # fixes the node's max_tilt_deg check refused


#: Seeds of the independent simulator's runs are these plus the usual ones (held out).
HELD_OUT_SEEDS = 1000


def held_out_multipath(seed):
    """Multipath parameters of one independent run, drawn from its seed: σ0 of code and phase
    scaled by 0.5-2 (log-uniform), elevation scale 10-30 deg, correlation times 10-120 s."""
    rng = np.random.default_rng(20_000 + seed)
    code_f, phase_f = np.exp(rng.uniform(math.log(0.5), math.log(2.0), 2))
    code_tau, phase_tau = rng.uniform(10.0, 120.0, 2)
    default = MultipathModel()
    return MultipathModel(code_sigma0=float(default.code_sigma0 * code_f),
                          phase_sigma0=float(default.phase_sigma0 * phase_f),
                          elevation_scale=math.radians(rng.uniform(10.0, 30.0)),
                          code_tau=float(code_tau), phase_tau=float(phase_tau))


def run_trial(seed, duration, antennas, rate=5.0, slip_every=0.0, ratio=3.0, overrides=(),
              until=math.inf, context=None, tilt_sigma=0.0, independent=False):
    """One simulated sea trial through the node (``overrides``: more node Parameters; ``context``:
    its rclpy context, the default one if None), fed up to trajectory time ``until`` (the
    scenario, its slips and satellites are still those of ``duration``: the start of a long run,
    reproduced quickly); with ``tilt_sigma`` > 0 (rad) an aligning ins/state with that tilt
    error is published with every epoch (:class:`AligningIns`); ``independent``: the
    independent simulator on held-out seed ``HELD_OUT_SEEDS + seed``; returns a
    :class:`Trial`."""
    if independent:
        seed += HELD_OUT_SEEDS
    sc = scenarios.sea(duration=duration, seed=seed, rate=2 * rate, oversample=2)
    tr = sc.trajectory
    broadcast = ephemeris_data.load(tr.lon[0])
    config = SimulatorConfig(lever_arms=antennas, seed=seed)
    if independent:
        config = replace(config, residuals=BroadcastResiduals(),
                         multipath=held_out_multipath(seed))
    sim = GnssSimulator(broadcast, config)
    if slip_every > 0:
        # Slips on antenna 1 every slip_every s, each on the satellite highest at the start (the
        # likely reference satellite: the hardest case for holding the other ambiguities).
        first = sim.epoch(tr.t[0], tr.lat[0], tr.lon[0], tr.h[0], tr.v_enu[0], tr.q_nb[0])
        by_el = [o.sat_id for _, o in sorted(zip(-first[0].truth.elevation, first[0].raw.obs),
                                             key=lambda x: x[0])]
        slips = tuple(SlipEvent(t, by_el[i % len(by_el)], (-1) ** i * (1 + i % 3), antenna=1)
                      for i, t in enumerate(np.arange(slip_every, duration, slip_every)))
        sim = GnssSimulator(broadcast, replace(config, slips=slips))
    bus = InProcessBus()
    heads = []
    bus.recorders.append(lambda topic, msg: heads.append(msg) if topic == "/gnss/heading" else 0)
    node = PhaseHeadingNode(context=context, bus=bus, parameter_overrides=[
        Parameter("antenna_positions", value=[float(v) for a in antennas for v in a]),
        Parameter("ratio_threshold", value=ratio), *overrides])
    ins = AligningIns(tilt_sigma, seed) if tilt_sigma > 0 else None
    valid = {}
    out = Trial(slips=sim.config.slips)
    pending_slips = list(out.slips)
    step = int(round(1.0 / (tr.dt * rate)))
    for k in range(0, len(tr), step):
        if tr.t[k] >= until:
            break
        epochs = sim.epoch(tr.t[k], tr.lat[k], tr.lon[k], tr.h[k], tr.v_enu[k], tr.q_nb[k],
                           tr.omega_ib_b[k])
        stamp = sec_to_stamp(STAMP0 + tr.t[k])
        if ins is not None:
            bus.publish("ins/state", ins.state(stamp, 1.0 / rate, tr.lat[k], tr.lon[k], tr.h[k],
                                               tr.q_nb[k]))
        if k == 0:
            for eph in sim.ephemerides.values():
                bus.publish("gnss/ephemeris", ephemeris_msg(eph, stamp, epochs[0].raw.leap_s))
        ok_phase = True
        for ep in epochs:
            newly = []
            for o in ep.raw.obs:
                key = (ep.antenna, o.sat_id)
                newly.append(o.half_cycle_valid and not valid.get(key, False))
                valid[key] = o.half_cycle_valid
            ok_phase &= sum(o.half_cycle_valid for o in ep.raw.obs) >= 4
            # What the gnss_simulator node publishes: loss of lock also when a phase becomes
            # valid (half-cycle ambiguity resolved).
            bus.publish("gnss/observations", observations_msg(
                ep.raw, ep.antenna, stamp, f"gnss_antenna_{ep.antenna}",
                [bool(a or b) for a, b in zip(ep.loss_of_lock, newly)]))
        n_before = len(heads)
        t0 = time.perf_counter()
        bus.drain()
        out.seconds_node += time.perf_counter() - t0
        if len(heads) == n_before:
            continue
        h = heads[-1]
        sol = node.pipeline.last_solution
        while pending_slips and pending_slips[0].t <= tr.t[k]:
            out.slips_detected += pending_slips.pop(0).sat_id in sol.slipped
        az, pitch, roll = seed_angles_from_quat(tr.q_nb[k])
        if h.status == 2 and any(0.0 <= tr.t[k] - ev.t < 5.0 for ev in out.slips):
            out.max_norm_err_after_slip = max(out.max_norm_err_after_slip, abs(
                wrap_pi(h.azimuth - az)) / math.sqrt(h.azimuth_variance))
        out.t.append(tr.t[k])
        out.status.append(h.status)
        out.phase_valid.append(ok_phase)
        out.err.append((wrap_pi(h.azimuth - az), h.pitch - pitch, h.roll - roll))
        out.sigma.append(np.sqrt([h.azimuth_variance, h.pitch_variance, h.roll_variance]))
        out.correct.append(h.status == 2 and held_ambiguities_true(node, epochs))
    out.tilt_rejections = node.diag.counts[
        "FIXED attitude beyond max_tilt_deg: wrong fix, ambiguities dropped"]
    node.destroy_node()
    return out


class AligningIns:
    """ins/state of an INS that has levelled but not found its heading: the true attitude with a
    tilt error about East and North (first-order Gauss-Markov, ``sigma`` rad each, correlation
    time ``TILT_TAU_S``) and a heading error drawn once, uniform in ±180°."""

    def __init__(self, sigma, seed):
        self.sigma = sigma
        self.rng = np.random.default_rng(10_000 + seed)
        self.tilt = sigma * self.rng.standard_normal(2)
        self.heading_error = self.rng.uniform(-math.pi, math.pi)

    def state(self, stamp, dt, lat, lon, h, q_nb) -> InsState:
        a = math.exp(-dt / TILT_TAU_S)
        self.tilt = a * self.tilt + self.sigma * math.sqrt(1.0 - a * a) * \
            self.rng.standard_normal(2)
        # Errors about navigation axes premultiply q_nb; the heading one (about Up) last.
        q = quat_mul(quat_from_rotvec([0.0, 0.0, self.heading_error]),
                     quat_mul(quat_from_rotvec([*self.tilt, 0.0]), q_nb))
        msg = InsState(latitude=float(lat), longitude=float(lon), altitude=float(h),
                       orientation=to_quaternion(q), mode=InsState.MODE_ALIGNING,
                       correction_sequence=1)  # levelled by a filter's correction
        msg.header.stamp = stamp
        msg.header.frame_id = "map"
        return msg


def held_ambiguities_true(node, epochs) -> bool:
    """Whether every ambiguity held by the node's solver is the simulator's integer."""
    true = [dict(zip((o.sat_id for o in ep.raw.obs), ep.truth.ambiguity)) for ep in epochs]
    # The store is the solver's internal table (baseline, signal, reference) -> integer.
    for (k, s, r), n in node.pipeline.solver.store._n.items():
        dd = (true[k][s] - true[0][s]) - (true[k][r] - true[0][r])
        if abs(dd - n) > 1e-6:
            return False
    return len(node.pipeline.solver.store) > 0


def summarise(trials, label):
    """Print the acceptance numbers of a list of trials."""
    fixed_after, correct_after, wrong, ttff, ttff_phase, n_pub = 0, 0, 0, [], [], 0
    errs, sigmas = [], []
    for tr in trials:
        st = np.array(tr.status)
        idx = np.flatnonzero(st == 2)
        n_pub += st.size
        if idx.size == 0:
            ttff.append(math.inf)
            continue
        first = idx[0]
        ttff.append(tr.t[first] - tr.t[0])
        phase_ok = np.flatnonzero(tr.phase_valid)
        ttff_phase.append(tr.t[first] - tr.t[phase_ok[0]])
        after = np.arange(first, st.size)
        corr = np.array(tr.correct)
        correct_after += int(np.sum(corr[after]))
        fixed_after += after.size
        wrong += int(np.sum((st == 2) & ~corr))
        # Every published FIXED epoch counts, a wrong fix included: what a consumer gets.
        errs.append(np.array(tr.err)[st == 2])
        sigmas.append(np.array(tr.sigma)[st == 2])
    e = np.degrees(np.vstack(errs))
    s = np.degrees(np.vstack(sigmas))
    with np.errstate(invalid="ignore"), warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)     # roll: all NaN with 2 antennas
        rms = np.sqrt(np.nanmean(e ** 2, axis=0))
        nees = np.nanmean((e / s) ** 2, axis=0)
    print(f"\n## {label}")
    print(f"epochs published: {n_pub}, after the first fix: {fixed_after}")
    print(f"correct fix after the first fix: {correct_after}/{fixed_after} = "
          f"{100.0 * correct_after / max(fixed_after, 1):.2f} %")
    print(f"wrong fixes (FIXED with a wrong held integer): {wrong}/{n_pub} = "
          f"{100.0 * wrong / max(n_pub, 1):.3f} %; wrong fixes caught by the node's tilt check "
          f"(published as NONE): {sum(tr.tilt_rejections for tr in trials)}")
    print(f"time to first fix from start: median {np.median(ttff):.1f} s, max {np.max(ttff):.1f} s"
          f" over {len(ttff)} runs")
    if ttff_phase:
        print(f"time to first fix from the first epoch with valid phases: median "
              f"{np.median(ttff_phase):.1f} s, max {np.max(ttff_phase):.1f} s")
    nees_w, n_w = window_mean_nees(trials)
    if n_w:
        print(f"heading error averaged over 120 s windows: mean (mean err)^2 / (mean sigma^2 / n)"
              f" = {nees_w:.2f} over {n_w} windows")
    names = ("heading", "pitch", "roll")
    for i, name in enumerate(names):
        if np.all(np.isnan(e[:, i])):
            print(f"{name}: not observed")
            continue
        print(f"{name} RMS {rms[i]:.3f} deg, mean reported sigma {np.nanmean(s[:, i]):.3f} deg,"
              f" mean (err/sigma)^2 {nees[i]:.2f}, max |err| {np.nanmax(np.abs(e[:, i])):.3f} deg")


def window_mean_nees(trials, window_s=120.0) -> tuple[float, int]:
    """Heading error averaged over each ``window_s`` of FIXED epochs against the variance a
    filter taking every epoch as independent assigns to that average (mean of σ² over n²):
    the mean of their squared ratio and the number of windows. About 1 when the published
    variances carry the time-correlated errors (a bit less for windows of a few τ); far above
    when they are white-noise variances of a correlated error."""
    ratios = []
    for tr in trials:
        t, st = np.array(tr.t), np.array(tr.status)
        err, sig = np.array(tr.err)[:, 0], np.array(tr.sigma)[:, 0]
        for start in np.arange(t[0], t[-1] - window_s + 1e-9, window_s):
            inside = (t >= start) & (t < start + window_s)
            sel = inside & (st == 2)
            n = sel.sum()
            if n < 0.9 * inside.sum():      # windows with most epochs FIXED only
                continue
            ratios.append(np.mean(err[sel]) ** 2 / (np.mean(sig[sel] ** 2) / n))
    return (float(np.mean(ratios)) if ratios else math.nan), len(ratios)


def print_slips(trials):
    """Slips detected at the epoch they occurred, and the worst FIXED heading shortly after."""
    n = sum(len(tr.slips) for tr in trials)
    found = sum(tr.slips_detected for tr in trials)
    worst = max(tr.max_norm_err_after_slip for tr in trials)
    print(f"slips injected on antenna 1: {n}, flagged at the epoch of the slip: {found}; "
          f"largest FIXED |heading error|/sigma within 5 s after a slip: {worst:.2f}")


def first_fix_sample(seeds, until=10.0, ratio=3.0, overrides=(), tilt_sigma=0.0):
    """The first ``until`` s of many runs (2 antennas: the 30 s TTFF runs; 4 antennas: the
    600 s runs with slips), where the first fix comes from the Galileo satellites alone: how
    often a wrong fix is published before GPS phases join (6 s) and exposes it."""
    for antennas, duration, name in ((TWO_ANTENNAS, 30.0, "2 antennas"),
                                     (FOUR_ANTENNAS, 600.0, "4 antennas")):
        trials = [run_trial(seed, duration, antennas, slip_every=30.0, ratio=ratio,
                            overrides=overrides, until=until, tilt_sigma=tilt_sigma)
                  for seed in seeds]
        summarise(trials, f"first {until:.0f} s of {len(seeds)} runs (seeds {seeds[0]}-"
                          f"{seeds[-1]}), {name}")
        bad = [seed for seed, tr in zip(seeds, trials)
               if any(st == 2 and not ok for st, ok in zip(tr.status, tr.correct))]
        print(f"runs with a wrong FIXED epoch: {len(bad)}/{len(seeds)} {bad}")


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="short runs (smoke test)")
    ap.add_argument("--ratio", type=float, default=3.0, help="ratio_threshold of the node")
    ap.add_argument("--param", action="append", default=[], metavar="NAME=VALUE",
                    help="node parameter override, e.g. multipath.phase_m=0.0 or "
                         "fix_confirm_epochs=1 (a value with a point is a float)")
    ap.add_argument("--first-fix", metavar="START:STOP",
                    help="only the first-fix sample: the first 10 s of seeds START..STOP-1")
    ap.add_argument("--tilt-prior", type=float, default=0.0, metavar="SIGMA_DEG",
                    help="publish an aligning ins/state (true tilt with this 1-sigma error, "
                         "heading wrong) with every epoch: the node's tilt prior")
    ap.add_argument("--independent", action="store_true",
                    help="independent simulator: broadcast-model residuals and multipath "
                         "parameters drawn per run, on held-out seeds")
    args = ap.parse_args(argv)
    tilt = math.radians(args.tilt_prior)
    extra = [Parameter(name, value=float(value) if "." in value else int(value))
             for name, value in (item.split("=", 1) for item in args.param)]
    if args.first_fix:
        start, stop = (int(v) for v in args.first_fix.split(":"))
        rclpy.init()
        try:
            first_fix_sample(list(range(start, stop)), ratio=args.ratio, overrides=extra,
                             tilt_sigma=tilt)
        finally:
            rclpy.shutdown()
        return 0
    long_s, ttff_runs, ttff_s = (120.0, 3, 20.0) if args.quick else (600.0, 10, 30.0)
    rclpy.init()
    try:
        wall = time.perf_counter()
        print(f"ratio_threshold {args.ratio}; sea scenario; GPS L1 + Galileo E1; 10 deg mask; "
              "2 mm + 2 mm/sin(E) phase noise + multipath; 5 Hz"
              + (f"; aligning ins/state, tilt error {args.tilt_prior} deg" if tilt > 0 else "")
              + ("; independent simulator, held-out seeds" if args.independent else "")
              + "".join(f"; {item}" for item in args.param))
        summarise([run_trial(100 + i, ttff_s, TWO_ANTENNAS, ratio=args.ratio, overrides=extra,
                             tilt_sigma=tilt, independent=args.independent)
                   for i in range(ttff_runs)],
                  f"time to first fix: {ttff_runs} runs x {ttff_s:.0f} s, 2 antennas, 1.5 m")
        runs = [run_trial(seed, long_s, TWO_ANTENNAS, slip_every=30.0, ratio=args.ratio,
                          overrides=extra, tilt_sigma=tilt, independent=args.independent)
                for seed in (1, 2, 3, 4)]
        summarise(runs, f"2 antennas 1.5 m, 4 x {long_s:.0f} s, slips on antenna 1 every 30 s")
        print_slips(runs)
        n_ep = sum(len(r.t) for r in runs)
        print(f"node time per epoch: {1e3 * sum(r.seconds_node for r in runs) / n_ep:.2f} ms")
        runs4 = [run_trial(seed, long_s, FOUR_ANTENNAS, slip_every=30.0, ratio=args.ratio,
                           overrides=extra, tilt_sigma=tilt, independent=args.independent)
                 for seed in (5, 6)]
        summarise(runs4, f"4 antennas (1.5 m x 1.0 m), 2 x {long_s:.0f} s, slips every 30 s")
        print_slips(runs4)
        n_ep = sum(len(r.t) for r in runs4)
        print(f"node time per epoch: {1e3 * sum(r.seconds_node for r in runs4) / n_ep:.2f} ms")
        print(f"\nwall time {time.perf_counter() - wall:.0f} s")
    finally:
        rclpy.shutdown()
    return 0


if __name__ == "__main__":
    sys.exit(main())
