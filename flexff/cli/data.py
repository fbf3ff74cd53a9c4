"""`flexff data`: collect a dataset on a loop, or import a machine's logs (learning/)."""

from __future__ import annotations

import argparse
import sys

from flexff.cli.shared import TRAJECTORY_SETS, Commands, machine_options


def _data_collect(args: argparse.Namespace) -> int:
    from flexff.learning.collect import CollectionReport
    from flexff.learning.workflow import collect_data

    loop = None
    if args.config is not None:
        from flexff.cosim.run import load_run_config

        loop = load_run_config(args.config)
    train, test = args.trajectories
    report = collect_data(args.output, args.set, loop, args.workers, args.scheduler, args.draws,
                          train, test, args.duration, args.classes)
    if not isinstance(report, CollectionReport):  # a machine's dataset
        print(f"{report.description.name}: {len(report.trajectories)} trajectories -> "
              f"{report.path}")
        return 0
    for line in report.problems():
        print(line, file=sys.stderr)
    cancelled = f", {len(report.cancelled)} not run" if report.cancelled else ""
    print(f"{report.set_name}: {report.total} trajectories -> {report.path}: {len(report.ran)} "
          f"run, {len(report.skipped)} skipped (already there), {len(report.failed)} failed"
          f"{cancelled}, {report.seconds:.1f} s")
    if report.ran:
        top = max(report.ran, key=lambda o: o.max_current)
        print(f"largest commanded motor current: {top.max_current:.2f} A ({top.name})")
    if not report.ok:
        print("manifest.json not written: run the same command again to retry the failed "
              "trajectories", file=sys.stderr)
    return 0 if report.ok else 1


def _data_import(args: argparse.Namespace) -> int:
    from flexff.learning.workflow import import_data

    test = None if args.test is None else [n.strip() for n in args.test.split(",") if n.strip()]
    dataset = import_data(args.files, args.output, args.machine, args.rate, test)
    for t in dataset.trajectories:
        print(f"{t.name} ({t.split}): {len(t)} samples; derived, not measured: "
              f"{', '.join(t.derived) or 'nothing'}")
    print(f"{len(dataset.trajectories)} logs -> {dataset.path} at {dataset.sample_rate_hz:g} Hz"
          f" (test split: {', '.join(t.name for t in dataset.split('test'))})")
    return 0


def add_commands(commands: Commands) -> None:
    """Add `data collect` and `data import`."""
    data = commands.add_parser("data", help="training data")
    data_commands = data.add_subparsers(dest="data_command", required=True)
    collect = data_commands.add_parser(
        "collect", help="co-simulate a loop under PID on excitation trajectories into a dataset "
                        "folder: a loop with a [machine] on its own excitation, or the "
                        "manipulator on a trajectory set (resumes an interrupted collection)")
    collect.add_argument("--set", help=f"the manipulator's trajectory set: "
                                       f"{' or '.join(TRAJECTORY_SETS)}; a loop with a "
                                       f"[machine] gets its excitation")
    collect.add_argument("--config", metavar="CONFIG.toml|SYSTEM.ssp",
                         help="the loop to collect on (flexff's controller and any plant); "
                              "default: the set's built-in plant under PID")
    collect.add_argument("-o", "--output", required=True, help="the dataset folder")
    collect.add_argument("--workers", type=int,
                         help="parallel local processes, at least 1 (default: CPUs)")
    collect.add_argument("--scheduler", help="address of a Dask scheduler to run on instead")
    collect.add_argument("--draws", type=int, default=1, metavar="N",
                         help="draw the set's training trajectories N times (default 1: the set "
                              "as the thesis gives it; the test split stays the same)")
    machine_options(collect)
    collect.set_defaults(handler=_data_collect)
    imports = data_commands.add_parser(
        "import", help="turn logs of a real machine (CSV or MATLAB .mat) into a dataset folder")
    imports.add_argument("files", nargs="+", metavar="FILE",
                         help="logs, one trajectory each: with --machine, the columns its "
                              "[machine.log] names (a signal's own name where it names none); "
                              "without, the manipulator's: time, theta_s1..3, Fx, Fy "
                              "(optionally x_ref .. ay_ref)")
    imports.add_argument("--machine", metavar="DESC.toml",
                         help="a TOML file with a [machine] table (a description, or a run "
                              "configuration that holds the table itself): import that "
                              "machine's logs through its [machine.log] map into a machine "
                              "dataset (version 4)")
    imports.add_argument("-o", "--output", required=True, help="the dataset folder (new)")
    imports.add_argument("--rate", type=float, metavar="HZ",
                         help="the dataset's sample rate: the logs are resampled to it "
                              "(default: the logs' own)")
    imports.add_argument("--test", metavar="NAME,...",
                         help="the logs (file names without suffix) of the test split "
                              "(default: the last file)")
    imports.set_defaults(handler=_data_import)
