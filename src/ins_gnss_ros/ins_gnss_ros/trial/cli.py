"""``trial``: the project's main job on the command line (CONTRACT.md "Trial CLI").

    trial simulate --scenario {car,robot,sea,aircraft} --duration S --seed N --out bags/NAME
    trial import {rtklib-drive,ubx,vessel-parquet} SRC --out bags/NAME
    trial replay bags/NAME --config config/PROFILE.yaml --out OUT [--outages LEN:PERIOD[:FIRST]]
                 [--init-from-truth] [--rate R --processes | --offline] [--faults FILE]
                 [--satellites N:LEN:PERIOD[:FIRST]]
    trial smooth bags/NAME --config config/PROFILE.yaml --out OUT [--outages LEN:PERIOD[:FIRST]]
                 [--point X,Y,Z] [--export csv,kml,pos]
    trial export OUT [--formats csv,kml,pos]
    trial evaluate OUT [--truth bags/NAME] [--json] [--skip S] [--truth-point X Y Z]
                   [--truth-velocity-delay S] [--remove-offset] [--point X Y Z] [--aperture S ...]
    trial compare OUT_A OUT_B [--with-diagnostics]
    trial batch --config PROFILE --out DIR (--scenario S --seeds N | --bags B ...) [--scheduler A]
    trial run --config config/PROFILE.yaml

Exit status: 0 done, 1 failed while running, 2 bad input (a missing, malformed or hostile bag,
profile or argument), reported as ONE line ``trial: error: ...`` on stderr without a traceback
(set ``TRIAL_DEBUG=1`` for the traceback).
"""
from __future__ import annotations

import argparse
import json
import os
import sys

#: Exit status for bad input.
EXIT_BAD_INPUT = 2


class _Parser(argparse.ArgumentParser):
    """argparse with a one-line error (no usage dump) and status 2."""

    def error(self, message):
        print(f"trial: error: {message}", file=sys.stderr)
        sys.exit(EXIT_BAD_INPUT)


def build_parser(command: str | None = None) -> argparse.ArgumentParser:
    """The parser of ``trial`` with every subcommand, and the arguments of ``command`` only.

    A subcommand's arguments import what their choices and defaults come from (the simulators,
    the importers: seconds): only the subcommand being run pays for it (None: none does, as
    for ``trial --help``).
    """
    parser = _Parser(prog="trial", description="Simulate, import, replay and evaluate trials.")
    sub = parser.add_subparsers(dest="command", required=True, parser_class=_Parser)
    for name, (help_text, add_arguments, _) in SUBCOMMANDS.items():
        p = sub.add_parser(name, help=help_text)
        if name == command:
            add_arguments(p)
    return parser


def _simulate_args(p):
    from ins_gnss_ros.sim.scenarios import SCENARIOS
    from ins_gnss_ros.trial.simulate import SimOptions

    p.add_argument("--scenario", choices=sorted(SCENARIOS), required=True)
    p.add_argument("--duration", type=float, default=120.0, help="s")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--imu", choices=("data_raw", "delta"), default="data_raw",
                   help="IMU topic: raw rates (imu/data_raw) or increments (imu/delta)")
    p.add_argument("--imu-grade", default=None, help="a key of nav.sensor_errors.GRADES")
    p.add_argument("--imu-rate", type=float, default=SimOptions.imu_rate, help="Hz")
    p.add_argument("--imu-stamp-jitter", type=float, default=0.0, metavar="S",
                   help="half-width of the uniform error of the IMU stamps (driver stamping), s")
    p.add_argument("--imu-orientation", type=float, default=0.0, metavar="DEG",
                   help="the IMU gives its own orientation (an AHRS), yaw to magnetic north "
                   "with this 1-sigma error (default: none)")
    p.add_argument("--mag-iron", type=int, default=None, metavar="VEHICLE_SEED",
                   help="imu/mag_raw from a magnetometer nobody calibrated: hard/soft iron, "
                   "scale and offsets of a car installation drawn from VEHICLE_SEED (the same "
                   "car on another drive: the same VEHICLE_SEED; default: an ideal sensor)")
    p.add_argument("--static", type=float, default=None, metavar="S",
                   help="car, robot: standstill before the drive, s (0: rolling start; default 30)")
    p.add_argument("--start-grade", type=float, default=0.0, metavar="RISE/RUN",
                   help="car, robot: the road's grade at the start (0.08: 8 %% uphill)")
    p.add_argument("--gnss-rate", type=float, default=SimOptions.gnss_rate, help="Hz")
    p.add_argument("--no-gnss-vel", action="store_true", help="fixes only, no gnss/vel")
    p.add_argument("--no-gnss-cov", action="store_true",
                   help="fixes and velocities without covariance")
    p.add_argument("--gnss-sigma-h", type=float, default=SimOptions.gnss_sigma_h,
                   help="horizontal position noise per axis, m")
    p.add_argument("--gnss-sigma-v", type=float, default=SimOptions.gnss_sigma_v,
                   help="vertical position noise, m")
    p.add_argument("--gnss-sigma-vel", type=float, default=SimOptions.gnss_sigma_vel,
                   help="velocity noise per axis, m/s")
    p.add_argument("--gnss-sigma-h-reported", type=float, default=None,
                   help="horizontal sigma gnss/fix reports, m, the vertical in proportion "
                        "(default: the true ones)")
    p.add_argument("--gnss-sigma-vel-reported", type=float, default=None,
                   help="velocity sigma per axis gnss/vel reports, m/s (default: the true one)")
    p.add_argument("--wheel-odometry", action="store_true",
                   help="also write wheel/odom (scale error, slips, encoder counts, latency)")
    p.add_argument("--wheel-scale-error", type=float, default=SimOptions.wheel_scale_error,
                   help="wheel odometry scale error, -")
    p.add_argument("--wheel-slip-interval", type=float,
                   default=SimOptions.wheel_slip_interval, metavar="S",
                   help="mean time between wheel slip events, s (inf: none)")
    p.add_argument("--gnss-latency", type=float, default=0.0, metavar="S",
                   help="mean delay of gnss/* after their epochs (receiver output latency), s")
    p.add_argument("--gnss-stamped-on-arrival", action="store_true",
                   help="gnss/fix and gnss/vel stamped when the driver reads them "
                        "(--gnss-latency after their epochs), as a driver stamping on arrival "
                        "does, and logged 0.1-1 ms later")
    p.add_argument("--antenna-lever-arm", type=float, nargs=3,
                   default=SimOptions.antenna_lever_arm, metavar=("X", "Y", "Z"),
                   help="GNSS antenna (with --antennas: the array's centre) from the IMU, "
                   "base_link FLU, m (default: 1.5 m above it)")
    p.add_argument("--antennas", type=int, choices=range(5), default=0, metavar="N",
                   help="raw GNSS (gnss/observations per antenna, gnss/ephemeris) of N = 1-4 "
                   "antennas from the gnss_simulator node, gnss/fix and gnss/vel from its "
                   "solution (--no-gnss-vel leaves gnss/vel out; the fixes' noise, covariance "
                   "and latency options are refused) (default 0: fix and velocity as truth "
                   "plus noise)")
    p.add_argument("--array", type=_array, default=SimOptions.array, metavar="LxW",
                   help="antenna array length (fore-aft) x width, m, centred 1.5 m above the "
                   "IMU (e.g. 2.7x1.2)")
    p.add_argument("--broadcast-residuals", action="store_true",
                   help="with --antennas: the simulated ionosphere, troposphere, orbits and "
                   "clocks differ from the broadcast models the receiver corrects with")
    p.add_argument("--out", required=True, help="new bag folder")


def _import_args(p):
    from ins_gnss_ros.trial.importers import IMPORTERS

    p.add_argument("kind", choices=sorted(IMPORTERS))
    p.add_argument("src", help="; ".join(f"{k}: {v[1]}" for k, v in sorted(IMPORTERS.items())))
    p.add_argument("--truth-pos", default=None,
                   help="ubx: RTKLIB .pos whose fixed epochs are truth")
    p.add_argument("--pos-geoid-separation", type=float, default=0.0,
                   help="ubx: geoid height N (m) added to the .pos heights when they are above "
                        "the geoid (hMSL), making them ellipsoidal")
    p.add_argument("--truth-float", action="store_true",
                   help="ubx: the .pos's RTK-float epochs are truth too (less accurate than "
                        "the fixed ones)")
    p.add_argument("--imu-csv", default=None,
                   help="ubx: the IMU log recorded with the stream (.csv beside its .csv.tag), "
                        "as imu/data_raw")
    p.add_argument("--out", required=True, help="new bag folder")


def _remap_arg(p):
    p.add_argument("--remap", action="append", default=[], metavar="FROM:=TO",
                   help="read the bag's topic FROM as TO (repeatable; e.g. /fix:=/gnss/fix, "
                        "/imu/data:=/imu/data_raw), as ros2 bag play --remap")


def _replay_args(p):
    _replay_options(p)
    _remap_arg(p)
    p.add_argument("bag")
    p.add_argument("--out", required=True, help="new output folder")
    p.add_argument("--rate", type=float, default=None,
                   help="real-time factor (with --processes); default: as fast as possible")
    p.add_argument("--processes", action="store_true",
                   help="run the nodes as processes on DDS with /clock (needs --rate)")
    p.add_argument("--offline", action="store_true",
                   help="offline filter path: the profile's imu_preprocessor and ekf "
                        "sections run without the node graph (no strapdown node)")
    p.add_argument("--faults", default=None, metavar="FILE",
                   help="fault specification (YAML) applied to the bag's messages on their way "
                        "to the nodes (in-process replay only)")
    p.add_argument("--satellites", default=None, metavar="N:LEN:PERIOD[:FIRST]",
                   help="in these windows only the N highest satellites stay in "
                        "gnss/observations, gnss/fix and gnss/vel are withheld (in-process "
                        "replay only)")


def _smooth_args(p):
    _remap_arg(p)
    p.add_argument("bag")
    p.add_argument("--config", required=True, help="params file (config/PROFILE.yaml)")
    p.add_argument("--out", required=True, help="new output folder")
    p.add_argument("--outages", default=None, help="LEN:PERIOD[:FIRST] s of GNSS withheld")
    p.add_argument("--point", default=None, metavar="X,Y,Z",
                   help="also record the solution of this body point (base_link FLU, m; an "
                        "antenna, a camera) at the IMU rate: point/state")
    p.add_argument("--export", default="", metavar="FORMATS",
                   help="also export the solutions: comma-separated csv, kml, pos")
    p.add_argument("--progress", action=argparse.BooleanOptionalAction, default=None,
                   help="progress bar (default: when stderr is a terminal)")


def _export_args(p):
    p.add_argument("out", help="replay or smooth output folder")
    p.add_argument("--formats", default="csv,kml,pos", help="comma-separated csv, kml, pos")


def _evaluate_args(p):
    p.add_argument("out", help="replay output folder")
    p.add_argument("--truth", default=None, help="bag with truth/state (default: the input bag)")
    p.add_argument("--json", action="store_true", help="print one JSON object")
    p.add_argument("--no-plots", action="store_true")
    p.add_argument("--skip", type=float, default=0.0,
                   help="leave the first S s (alignment, convergence) out of the statistics")
    p.add_argument("--truth-point", type=float, nargs=3, default=None, metavar=("X", "Y", "Z"),
                   help="the body point the truth positions refer to (base_link FLU, m), e.g. "
                        "the GNSS antenna of an RTK truth")
    p.add_argument("--truth-velocity-delay", type=float, default=0.0, metavar="S",
                   help="latency of the truth velocities, s")
    p.add_argument("--remove-offset", action="store_true",
                   help="take the mean position error out (a truth with a constant offset of "
                        "its own, e.g. RTK against a base of unknown coordinates)")
    p.add_argument("--point", type=float, nargs=3, default=None, metavar=("X", "Y", "Z"),
                   help="evaluate the trajectory of this body point (base_link FLU, m; a "
                        "smoothed run's point/state when it was recorded there)")
    p.add_argument("--aperture", type=float, nargs="+", default=(), metavar="S",
                   help="also the relative position error over windows of S s, linear trend "
                        "removed (SAR apertures)")


def _compare_args(p):
    p.add_argument("a", help="replay output folder (or bag folder)")
    p.add_argument("b", help="the other one")
    p.add_argument("--with-diagnostics", action="store_true", help="compare /diagnostics too")


def _batch_args(p):
    _replay_options(p)
    p.add_argument("--out", required=True, help="new folder for the runs and batch.json")
    p.add_argument("--scenario", default=None, help="Monte Carlo: simulate this scenario per seed")
    p.add_argument("--seeds", type=int, default=10, help="Monte Carlo: number of seeds")
    p.add_argument("--first-seed", type=int, default=0)
    p.add_argument("--duration", type=float, default=60.0, help="Monte Carlo: s")
    p.add_argument("--imu", choices=("data_raw", "delta"), default="data_raw")
    p.add_argument("--imu-grade", default=None)
    p.add_argument("--bags", nargs="+", default=None, help="replay these bags instead")
    p.add_argument("--scheduler", default=None, help="address of a running dask scheduler")
    p.add_argument("--workers", type=int, default=2, help="LocalCluster worker processes")


def _run_args(p):
    p.add_argument("--config", required=True, help="params file (config/PROFILE.yaml)")
    p.add_argument("--max-restarts", type=int, default=5, help="per node, then give up")


def _replay_options(p):
    p.add_argument("--config", required=True, help="params file (config/PROFILE.yaml)")
    p.add_argument("--outages", default=None, help="LEN:PERIOD[:FIRST] s of GNSS withheld")
    p.add_argument("--init-from-truth", action="store_true",
                   help="set the nodes' init.* parameters from the first truth/state")
    p.add_argument("--progress", action=argparse.BooleanOptionalAction, default=None,
                   help="progress bar (default: when stderr is a terminal)")


def main(argv=None) -> int:
    try:
        argv = sys.argv[1:] if argv is None else list(argv)
        # trial takes no option of its own but -h: its first other word names the subcommand.
        command = next((word for word in argv if not word.startswith("-")), None)
        # Parsing may import the simulators: a Ctrl-C then is an interruption like any other.
        args = build_parser(command).parse_args(argv)
        return SUBCOMMANDS[args.command][2](args)
    except KeyboardInterrupt:
        print("trial: interrupted", file=sys.stderr)
        return 130
    except Exception as err:  # noqa: BLE001 - the one place that turns errors into a status
        if os.environ.get("TRIAL_DEBUG"):
            raise
        from ins_gnss_ros.io import first_line

        bad_input = isinstance(err, (ValueError, LookupError, OSError))
        print(f"trial: error: {first_line(err)}", file=sys.stderr)
        return EXIT_BAD_INPUT if bad_input else 1


def _array(text: str) -> tuple:
    """``LxW`` (m) -> (L, W)."""
    try:
        length, width = (float(v) for v in text.lower().split("x"))
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected LENGTHxWIDTH in m, e.g. 2.7x1.2, got {text!r}")
    if not (length >= 0.0 and width >= 0.0):
        raise argparse.ArgumentTypeError(f"array sides must be >= 0 m, got {text!r}")
    return length, width


def _progress(args) -> bool:
    return sys.stderr.isatty() if args.progress is None else args.progress


def cmd_simulate(args) -> int:
    from ins_gnss_ros.trial.simulate import SimOptions, simulate

    path = simulate(args.scenario, args.duration, args.seed, args.out,
                    SimOptions(imu_grade=args.imu_grade, imu_topic=args.imu,
                               imu_rate=args.imu_rate, imu_stamp_jitter=args.imu_stamp_jitter,
                               imu_orientation_sigma=args.imu_orientation,
                               mag_iron=args.mag_iron, start_static=args.static,
                               start_grade=args.start_grade,
                               gnss_rate=args.gnss_rate, gnss_velocity=not args.no_gnss_vel,
                               gnss_covariance=not args.no_gnss_cov,
                               gnss_sigma_h=args.gnss_sigma_h, gnss_sigma_v=args.gnss_sigma_v,
                               gnss_sigma_vel=args.gnss_sigma_vel,
                               gnss_sigma_h_reported=args.gnss_sigma_h_reported,
                               gnss_sigma_vel_reported=args.gnss_sigma_vel_reported,
                               wheel_odometry=args.wheel_odometry,
                               wheel_scale_error=args.wheel_scale_error,
                               wheel_slip_interval=args.wheel_slip_interval,
                               gnss_latency=args.gnss_latency,
                               gnss_stamped_on_arrival=args.gnss_stamped_on_arrival,
                               antenna_lever_arm=tuple(args.antenna_lever_arm),
                               antennas=args.antennas,
                               array=args.array,
                               broadcast_residuals=args.broadcast_residuals))
    print(path)
    return 0


def cmd_import(args) -> int:
    from ins_gnss_ros.trial.importers import IMPORTERS

    function = IMPORTERS[args.kind][0]
    kwargs = ({"truth_pos": args.truth_pos, "geoid_separation": args.pos_geoid_separation,
               "imu_csv": args.imu_csv, "truth_float": args.truth_float}
              if args.kind == "ubx" else {})
    print(function(args.src, args.out, **kwargs))
    return 0


def cmd_replay(args) -> int:
    from ins_gnss_ros.trial.inputs import parse_remap

    if args.processes and args.rate is None:
        raise ValueError("--processes needs --rate (e.g. --rate 1)")
    if args.rate is not None and not args.processes:
        raise ValueError("--rate needs --processes (the in-process replay runs as fast as "
                         "possible)")
    for option, value in (("--faults", args.faults), ("--satellites", args.satellites)):
        if value is not None and (args.processes or args.offline):
            raise ValueError(f"{option} works with the in-process replay only (not with "
                             "--processes or --offline)")
    if args.offline:
        if args.processes or args.init_from_truth:
            raise ValueError("--offline runs no nodes: it takes neither --processes nor "
                             "--init-from-truth")
        from ins_gnss_ros.trial.offline import replay_offline

        summary = replay_offline(args.bag, args.config, args.out, outages=args.outages,
                                progress=_progress(args), remap=parse_remap(args.remap))
    else:
        if args.processes:
            from ins_gnss_ros.trial.processes import replay_processes as run
        else:
            from ins_gnss_ros.trial.replay import replay as run
        kwargs = {"rate": args.rate} if args.processes else {"faults": args.faults,
                                                             "satellites": args.satellites}
        summary = run(args.bag, args.config, args.out, outages=args.outages,
                      progress=_progress(args), init_from_truth=args.init_from_truth,
                      remap=parse_remap(args.remap), **kwargs)
    print(f"replayed {args.bag} ({summary['mode']}, {', '.join(summary['graph'])}):")
    _print_counts(summary)
    print(f"recorded {', '.join(summary['topics'])} into {args.out}")
    return 0


def _print_counts(summary) -> None:
    """A run's messages per topic (replay.json), and a warning per bag topic no node read."""
    from ins_gnss_ros.trial.run_folder import counts_table

    print("\n".join("  " + line for line in counts_table(summary["messages"])))
    for note in summary["installation"]:
        print(f"installation: {note}", file=sys.stderr)
    for note in summary["converted"]:
        print(f"converted: {note}", file=sys.stderr)
    for note in summary["unread_topics"]:
        print(f"warning: {note}", file=sys.stderr)


def cmd_smooth(args) -> int:
    from ins_gnss_ros.trial.inputs import parse_remap
    from ins_gnss_ros.trial.smooth import smooth

    point = None
    if args.point is not None:
        try:
            point = [float(x) for x in args.point.split(",")]
        except ValueError:
            point = []
        if len(point) != 3:
            raise ValueError(f"--point takes X,Y,Z in metres, got {args.point!r}")
    summary = smooth(args.bag, args.config, args.out, outages=args.outages, point=point,
                     exports=args.export, progress=_progress(args),
                     remap=parse_remap(args.remap))
    print(f"smoothed {args.bag} ({', '.join(summary['graph'])}):")
    _print_counts(summary)
    print("  " + ", ".join(f"{k} {v:.1f} s" for k, v in summary["timing_s"].items()))
    print(f"recorded {', '.join(summary['topics'])} into {args.out}")
    for path in summary["exports"]:
        print(f"exported {path}")
    return 0


def cmd_export(args) -> int:
    from ins_gnss_ros.trial.export import export_run

    for path in export_run(args.out, args.formats):
        print(path)
    return 0


def cmd_evaluate(args) -> int:
    from ins_gnss_ros.trial.evaluate import markdown_table
    from ins_gnss_ros.trial.report import evaluate_run

    evaluation, metrics = evaluate_run(args.out, args.truth, plots=not args.no_plots,
                                       skip_s=args.skip, truth_point=args.truth_point,
                                       truth_velocity_delay=args.truth_velocity_delay,
                                       remove_offset=args.remove_offset,
                                       point=args.point, apertures=args.aperture)
    if args.json:
        print(json.dumps(metrics, sort_keys=True))
    else:
        from ins_gnss_ros.trial.aperture import ApertureError, markdown_lines

        print(markdown_table(evaluation))
        if "aperture" in metrics:
            print("\n" + "\n".join(markdown_lines([ApertureError(**a)
                                                    for a in metrics["aperture"]])))
        print(f"\nreport: {metrics['report']}")
    return 0


def cmd_compare(args) -> int:
    from ins_gnss_ros.trial.compare import DEFAULT_SKIP, compare

    result = compare(args.a, args.b, skip=() if args.with_diagnostics else DEFAULT_SKIP)
    print("\n".join(result.lines()))
    return 0 if result.identical else 1


def cmd_batch(args) -> int:
    from ins_gnss_ros.trial.batch import run_batch

    result = run_batch(args.config, args.out, scheduler=args.scheduler, workers=args.workers,
                       scenario=args.scenario, seeds=args.seeds, first_seed=args.first_seed,
                       duration=args.duration, bags=args.bags, outages=args.outages,
                       init_from_truth=args.init_from_truth, imu=args.imu,
                       imu_grade=args.imu_grade)
    print(json.dumps(result["aggregate"], indent=2, sort_keys=True))
    print(f"batch: {result['path']}")
    return 0 if result["failed"] == 0 else 1


def cmd_run(args) -> int:
    from ins_gnss_ros.trial.profile import load_profile
    from ins_gnss_ros.trial.supervisor import Supervisor

    profile = load_profile(args.config)
    return Supervisor(profile, max_restarts=args.max_restarts).run()


#: Subcommand -> (help, function adding its arguments to its parser, function running it).
SUBCOMMANDS = {
    "simulate": ("write a simulated trial as a bag", _simulate_args, cmd_simulate),
    "import": ("convert recorded data into a bag", _import_args, cmd_import),
    "replay": ("run the node graph of a profile over a bag", _replay_args, cmd_replay),
    "smooth": ("post-process a bag: the profile's forward filter, then the RTS smoother",
               _smooth_args, cmd_smooth),
    "export": ("write a run's solutions as CSV, KML, RTKLIB .pos", _export_args, cmd_export),
    "evaluate": ("error statistics, plots and report of a replay", _evaluate_args, cmd_evaluate),
    "compare": ("are two replays' outputs identical, message by message", _compare_args,
                cmd_compare),
    "batch": ("many replays or Monte Carlo seeds on dask.distributed", _batch_args, cmd_batch),
    "run": ("start the profile's graph on real sensors, supervised", _run_args, cmd_run),
}

if __name__ == "__main__":
    sys.exit(main())
