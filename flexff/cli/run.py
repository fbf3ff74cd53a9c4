"""`flexff run`, `config`, `results` and `ssp`: co-simulation runs, their configurations,
results and SSP files (cosim/, flexff.results)."""

from __future__ import annotations

import argparse
import sys
import warnings
from typing import TYPE_CHECKING, Any

from flexff.cli.shared import Commands, output_file
from flexff.fmu.errors import InputError

if TYPE_CHECKING:
    from flexff.cosim.timing import Pacing


def _run(args: argparse.Namespace) -> int:
    from flexff.cosim.batch import run_batch, sweep, sweep_axes
    from flexff.cosim.config import with_isolation, with_strict
    from flexff.cosim.executor import check_workers
    from flexff.cosim.run import load_run_config, output_folder, run_config
    from flexff.cosim.schema import RunConfig
    from flexff.fmu.description_faults import DescriptionWarning

    check_workers(args.workers)  # one configuration runs here, but a wrong count is wrong
    output_folder(args.output)
    configs = args.configs
    if args.sweep:
        if len(configs) != 1:
            raise InputError("--sweep takes exactly one configuration")
        configs = sweep(configs[0], sweep_axes(args.sweep))
    if args.strict:  # its refusals say what the warnings would have said
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", DescriptionWarning)
            configs = [with_strict(c if isinstance(c, RunConfig) else load_run_config(c))
                       for c in configs]
    if args.isolate or args.step_timeout is not None or args.no_sandbox:
        configs = [with_isolation(c if isinstance(c, RunConfig) else load_run_config(c),
                                  args.isolate, args.step_timeout, not args.no_sandbox)
                   for c in configs]
    if len(configs) == 1 and not args.sweep and args.scheduler is None:
        metrics = run_config(configs[0], args.output, pacing=_pacing(args), cpu=args.cpu)
        _print_result(args.configs[0], metrics, args.output)
        return 0
    if args.realtime:
        raise InputError("--realtime runs one configuration, in this process")
    status = 0
    for result in run_batch(configs, args.output, args.workers, args.scheduler,
                            subfolders=len(configs) > 1 or bool(args.sweep)):
        if result.ok and result.metrics is not None:
            _print_result(result.name, result.metrics, result.output_dir)
        else:
            print(f"{result.name}: FAILED: {result.error}", file=sys.stderr)
            status = 1
    return status


def _pacing(args: argparse.Namespace) -> Pacing | None:
    """The run's Pacing from --realtime and its options (None: as fast as it goes)."""
    options = {"--rt-factor": args.rt_factor, "--max-overruns": args.max_overruns,
               "--grace": args.grace, "--cpu": args.cpu}
    if not args.realtime:
        given = [name for name, value in options.items() if value is not None]
        if given:
            raise InputError(f"{', '.join(given)} apply to paced runs: add --realtime")
        return None
    from flexff.cosim.timing import Pacing

    return Pacing(rt_factor=1.0 if args.rt_factor is None else args.rt_factor,
                  max_overruns=args.max_overruns or 0, grace=args.grace or 0.0)


def _print_result(name: object, metrics: dict[str, Any], output: object) -> None:
    """One line per run, and a second where its learned feedforward extrapolates."""
    from flexff.cosim.metrics import metrics_axes
    from flexff.cosim.run import run_warnings

    tracking = ""
    axes = metrics_axes(metrics)
    if axes:  # the manipulator's x, y or a machine description's axes
        e2 = ", ".join(f"{metrics[a]['e2']:.4g}" for a in axes)
        einf = ", ".join(f"{metrics[a]['einf']:.4g}" for a in axes)
        tracking = (f"e2 = ({e2}) m/sqrt(s), einf = ({einf}) m, " if axes == ["x", "y"] else
                    f"e2 ({', '.join(axes)}) = ({e2}), einf = ({einf}) in the axes' units, ")
    print(f"{name}: {tracking}real-time factor {metrics['real_time_factor']:.0f} -> {output}")
    timing = metrics.get("realtime", {})
    if timing.get("target_real_time_factor"):
        tet = timing["tet_us"]
        print(f"  {name}: paced at {timing['target_real_time_factor']:g}x real time "
              f"(achieved {timing['achieved_real_time_factor']:.4g}x): TET p50 {tet['p50']:.1f}"
              f" us, p99 {tet['p99']:.1f} us, max {tet['max']:.1f} us of a "
              f"{timing['period_us']:.0f} us period, {timing['overruns']} overruns")
        for warning in (timing.get("process") or {}).get("warnings", []):
            print(f"  {name}: warning: {warning}")
    for warning in run_warnings(metrics):
        print(f"  {name}: {warning}")


def _config_example(args: argparse.Namespace) -> int:
    from flexff.cosim.example_configs import config_examples

    examples = config_examples()
    if args.name is None:
        print("\n".join(examples))
        return 0
    if args.name not in examples:
        raise InputError(f"no example {args.name!r}; examples: {', '.join(examples)}")
    print(examples[args.name], end="")
    return 0


def _example_names() -> list[str]:
    """The names of the example configurations (cosim/examples/*.toml), for --help."""
    from flexff.cosim.example_configs import config_examples

    return list(config_examples())


def _results_export(args: argparse.Namespace) -> int:
    from flexff.results import export_csv

    print(f"wrote {export_csv(args.folder)}")
    return 0


def _config_expand(args: argparse.Namespace) -> int:
    from flexff.cosim.config import expanded_text
    from flexff.cosim.run import load_run_config

    print(expanded_text(load_run_config(args.config)), end="")
    return 0


def _ssp_export(args: argparse.Namespace) -> int:
    from flexff.cosim.run import load_run_config
    from flexff.cosim.ssp import export_ssp

    output_file(args.output)
    print(f"wrote {export_ssp(load_run_config(args.config), args.output)}")
    return 0


def add_commands(commands: Commands) -> None:
    """Add `run`, `config example|expand`, `results export` and `ssp export`."""
    run = commands.add_parser("run", help="run co-simulations from TOML configurations or SSP "
                                          "files")
    run.add_argument("configs", nargs="+", metavar="CONFIG.toml|SYSTEM.ssp",
                     help="run configurations (TOML) or SSP 1.0 systems")
    run.add_argument("-o", "--output", required=True,
                     help="output folder (several configurations: one subfolder each)")
    run.add_argument("--workers", type=int, help="parallel local processes (default: CPUs)")
    run.add_argument("--scheduler", help="address of a Dask scheduler to run on instead")
    run.add_argument("--sweep", metavar="TABLE.KEY=V1,V2,...", action="append",
                     help="run one configuration once per value of a key; repeated, once per "
                          "combination of their values")
    run.add_argument("--realtime", action="store_true",
                     help="pace the steps to the wall clock and report task execution times "
                          "(TET) and overruns, as Simulink Real-Time does (tet.png, "
                          "metrics.json 'realtime')")
    run.add_argument("--isolate", action="store_true",
                     help="run every FMU in its own process, in a sandbox: a crash or a hang of "
                          "an FMU, or an attempt the sandbox stops, ends the run with an error "
                          "(exit code 1) and the record up to there")
    run.add_argument("--no-sandbox", action="store_true",
                     help="run isolated FMUs without their sandbox ([fmu.NAME] sandbox = false)")
    run.add_argument("--step-timeout", type=float, metavar="S",
                     help="stop a run whose isolated FMU takes longer than S seconds in one "
                          "call ([run] step_timeout)")
    run.add_argument("--strict", action="store_true",
                     help="refuse FMUs whose model description has faults that change no run "
                          "too ([fmu.NAME] strict = true); without it they run with a warning")
    run.add_argument("--rt-factor", type=float, metavar="F",
                     help="real-time factor of a paced run: 2 runs twice as fast (default 1)")
    run.add_argument("--max-overruns", type=int, metavar="N",
                     help="stop a paced run after N overruns, a network task's late results "
                          "included (exit code 3, record kept)")
    run.add_argument("--grace", type=float, metavar="S",
                     help="overruns in the first S seconds do not count for --max-overruns")
    run.add_argument("--cpu", type=int, metavar="K", help="pin a paced run to CPU K")
    run.set_defaults(handler=_run)

    config = commands.add_parser("config", help="run configurations")
    config_commands = config.add_subparsers(dest="config_command", required=True)
    example = config_commands.add_parser(
        "example", help="print an example configuration (no name: list them)",
        epilog="examples:\n" + "\n".join(f"  {n}" for n in _example_names()),
        formatter_class=argparse.RawDescriptionHelpFormatter)
    example.add_argument("name", nargs="?", metavar="NAME",
                         help="the example's name (listed below)")
    example.set_defaults(handler=_config_example)
    expand = config_commands.add_parser("expand", help="print a configuration in the general "
                                                       "form ([fmu.*], [[connection]], ...)")
    expand.add_argument("config", help="a run configuration (TOML) or SSP file")
    expand.set_defaults(handler=_config_expand)

    results = commands.add_parser("results", help="a run folder's results")
    results_commands = results.add_subparsers(dest="results_command", required=True)
    results_export = results_commands.add_parser(
        "export", help="write signals.csv beside a run's record (flexff.results.export_csv)")
    results_export.add_argument("folder", help="the run's folder (flexff run -o)")
    results_export.set_defaults(handler=_results_export)

    ssp = commands.add_parser("ssp", help="SSP 1.0 (System Structure and Parameterization)")
    ssp_commands = ssp.add_subparsers(dest="ssp_command", required=True)
    ssp_export = ssp_commands.add_parser(
        "export", help="write a run configuration as an .ssp file (FMUs, connections, "
                       "parameters, default experiment) for libcosim, FMPy, OMSimulator")
    ssp_export.add_argument("config", help="a run configuration (TOML)")
    ssp_export.add_argument("-o", "--output", required=True, help="the .ssp file to write")
    ssp_export.set_defaults(handler=_ssp_export)
