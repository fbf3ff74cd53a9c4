"""The `flexff` command line: parses arguments and calls package functions, nothing more.

main() is the one place that turns a failure into one line on stderr and an exit code: 0 ok,
1 a run that failed (an FMU error, a full disk, an unreachable Dask scheduler, memory), 2 bad
input (InputError: a configuration, a path, an option, an unwritable output folder), 130
interrupted, 143 terminated (SIGTERM, handled as Ctrl-C is; 3 is kept for real-time
overruns); any other error is a bug: 1, its type and a hint to rerun with `flexff --debug`,
which prints the Python traceback.
"""

from __future__ import annotations

import argparse
import errno
import json
import os
import signal
import sys
import threading
import traceback
import warnings
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any, TextIO

from flexff.fmu.errors import InputError, RunError, Terminated
from flexff.fmu.fmi_version import FMI_VERSIONS
from flexff.fmu.network_runtime import RUNTIMES
from flexff.fmu.platforms import ALL, PLATFORMS
from flexff.plant.variants import VARIANTS

if TYPE_CHECKING:  # the command line loads numpy and the rest only in the command that runs
    from flexff.cosim.timing import Pacing

MODELS = ("lstm", "cnn-lstm", "tcn", "pgnn")  # learning.models, named here to keep torch unloaded
PRESETS = ("fast", "thesis")
TRAJECTORY_SETS = ("sim", "hardware")  # learning.dataset.SETS, named here to keep numpy unloaded
DEVICES = ("auto", "cpu", "cuda")  # learning.devices', named here to keep torch unloaded
EXCITATION = ("moves", "bang-bang", "spline", "multisine")  # learning.excitation's CLASSES,
EVERY_EXCITATION = (*EXCITATION, "sine", "random", "rest", "solo")  # and EVERY_CLASS
ITERATIONS, CUTOFF_HZ, GAIN = 10, 20.0, 1.0  # learning.ilc's defaults (keeps scipy unloaded)
INPUT_ERRORS = (FileNotFoundError, FileExistsError, IsADirectoryError, NotADirectoryError,
                PermissionError)  # OSErrors about paths the user gave: exit code 2, as are
INPUT_ERRNOS = (errno.EROFS, errno.ENAMETOOLONG, errno.ELOOP)  # these (others: 1)
LEARN = {"torch": "PyTorch", "onnxscript": "onnxscript"}  # the extra "learn" (pyproject.toml)
BUG_HINT = " (rerun with flexff --debug for the traceback)"  # an error that is not documented
KEPT = {  # what an interrupted command keeps, by command (and subcommand)
    "run": "the runs that finished keep their folders, an interrupted run its record up to "
           "where it stopped; no file is left half-written",
    "data collect": "the trajectories collected so far are kept: run the same command again "
                    "to resume",
    "data import": "the dataset folder was left as it was",
    "ilc": "the finished trials are kept: run the same command again to continue",
}


def _plant_info(args: argparse.Namespace) -> int:
    from flexff.plant.analysis import plant_info

    info = plant_info(args.variant)
    if args.json:
        print(json.dumps(info, indent=2))
        return 0
    print(f"plant variant: {info['variant']} (parasitic mode: {info['parasitic_mode']})")
    print(f"workspace radius: {info['workspace_radius_m']} m")
    for f, z in zip(info["natural_frequencies_hz"], info["damping_ratios"]):
        print(f"mode at the centre: {f:.4f} Hz, damping ratio {z:.4f}")
    for row in info["parameters"]:
        print(f"  {row['name']:<16} {row['value']:<12.6g} {row['unit']:<10} {row['description']}")
    return 0


def _output_file(path: str) -> None:
    """Check, before any work, that the file `path` can be written: its folder is made."""
    from flexff.cosim.run import output_folder

    if Path(path).is_dir():
        raise InputError(f"{path}: is a folder: give the name of the file to write")
    output_folder(Path(path).parent)


def _epochs(args: argparse.Namespace) -> dict[str, Any]:
    """--epochs as a setting override where given (0 too: the configuration refuses it)."""
    return {} if args.epochs is None else {"epochs": args.epochs}


def _evaluate_machine(args: argparse.Namespace, loop: Any) -> int:
    """evaluate --config LOOP.toml whose loop has a [machine]: the workflow on that machine."""
    from flexff.learning.machine_evaluate import evaluate_machine

    train, test = args.trajectories
    evaluate_machine(loop, args.output, args.models, args.preset, train, test, args.duration,
                     classes=args.classes, ilc_iterations=args.ilc_iterations,
                     ilc_cutoff_hz=args.ilc_cutoff, ilc_gain=args.ilc_gain, device=args.device,
                     **_epochs(args))
    print((Path(args.output) / "table.md").read_text())
    print(f"results in {args.output}/ (summary.json, table.md, errors.png, identified.json, "
          f"data/, runs/, models/, fmus/, ilc/ for the limit)")
    return 0


def _evaluate_logs(args: argparse.Namespace) -> int:
    """evaluate --data LOGS, a machine's dataset with no loop: force prediction on its test
    logs."""
    from flexff.learning.log_evaluate import evaluate_logs

    evaluate_logs(args.data, args.output, args.models, args.preset, device=args.device,
                  **_epochs(args))
    print((Path(args.output) / "table.md").read_text())
    print(f"relative 2-norm of the effort error on the test logs; results in {args.output}/ "
          f"(summary.json, table.md, identified.json, runs/, models/)")
    return 0


def _predict(args: argparse.Namespace) -> int:
    """predict RUN --data LOGS -o FILE.csv: each model's efforts per sample of the logs."""
    from flexff.learning.machine_features import preprocessing_text
    from flexff.learning.predict import predict_logs, write_predictions

    _output_file(args.output)
    predictions = predict_logs(args.run, args.data, args.split)
    print(preprocessing_text(predictions.preprocessing))
    written = write_predictions(predictions, args.output,
                                {"run": str(args.run), "data": str(args.data),
                                 "split": args.split})
    for name, errors in predictions.relative_error.items():
        print(f"{name}: " + ", ".join(f"{axis} {100 * e:.2f} %" for axis, e in errors.items()))
    print(f"relative 2-norm of the filtered effort error; wrote {', '.join(map(str, written))}")
    return 0


def _tune(args: argparse.Namespace) -> int:
    """tune LOOP: each axis's plant measured in the loop, the PID block's loop shape proposed."""
    from flexff.cosim.run import load_run_config
    from flexff.learning.pid_tune import tune_loop, tuning_table, write_tuning

    _output_file(args.output)
    tuning = tune_loop(load_run_config(args.config), args.phase_margin, args.seconds,
                       args.high_hz)
    print(tuning_table(tuning))
    print(f"wrote {write_tuning(tuning, args.output, args.config)} (the PID block's mass, "
          f"damping and crossover_hz per axis; margins around the identified model)")
    return 0


def _fmu_build(args: argparse.Namespace) -> int:
    from flexff.fmu.build import build_fmu

    if args.kind == "plant" and (args.task or args.runtime is not None):
        raise InputError("--task and --runtime are about an embedded network: the plant has "
                         "none")
    runtime = args.runtime or RUNTIMES[0]
    if args.kind != "onnx" and (args.graph is not None or args.every is not None):
        raise InputError("only fmu build onnx takes a graph file and --every (a learned "
                         "feedforward takes --model M.onnx and runs at the model's rate)")
    if args.kind == "onnx":
        from flexff.fmu.onnx_fmu import onnx_system

        if args.graph is None:
            raise InputError("fmu build onnx needs the graph: flexff fmu build onnx MODEL.onnx "
                             "-o M.fmu")
        system = onnx_system(args.graph, args.step, 1 if args.every is None else args.every,
                             args.task, runtime)
    elif args.kind in ("learned-feedforward", "feedforward"):
        from flexff.controllers.learned_feedforward import learned_feedforward_system

        if args.kind == "feedforward":
            print("flexff: warning: 'fmu build feedforward' is now 'fmu build "
                  "learned-feedforward' (the built-in's name in run configurations)",
                  file=sys.stderr)
        if args.model is None:
            raise InputError("fmu build learned-feedforward needs --model M.onnx (flexff "
                             "export)")
        from flexff.controllers.model_card import read_card

        if read_card(args.model).machine is not None:
            from flexff.controllers.machine_feedforward import learned_machine_feedforward_system

            system = learned_machine_feedforward_system(args.model, args.step, args.task,
                                                        runtime)
        else:
            system = learned_feedforward_system(args.model, args.step, task=args.task,
                                                runtime=runtime)
    else:
        from flexff.plant.system import plant_system

        system = plant_system(args.variant)
    if args.source_only and args.platform:
        raise InputError("--source-only builds no binaries: it takes no --platform")
    platforms = () if args.source_only else args.platform
    _output_file(args.output)
    print(f"wrote {build_fmu(system, args.output, args.fmi, platforms)}")
    return 0


def _fmu_info(args: argparse.Namespace) -> int:
    from flexff.fmu.info import fmu_summary, format_summary

    summary = fmu_summary(args.file)
    print(json.dumps(summary, indent=2) if args.json else format_summary(summary, args.all))
    return 0


def _fmu_validate(args: argparse.Namespace) -> int:
    """Exit 0 when no FMU has an error (warnings allowed), 1 when one has, 2 when a path is
    missing or unreadable."""
    from flexff.cosim.isolation import confine_checks
    from flexff.fmu.validation import TIMEOUT, validate_fmu

    if args.timeout is None:
        args.timeout = TIMEOUT
    if not args.timeout > 0:
        raise InputError(f"--timeout {args.timeout:g}: expected a positive number of seconds")
    status = 0
    for path in args.files:
        unusable = ("no such file" if not Path(path).exists() else
                    "not a file" if not Path(path).is_file() else
                    "not readable" if not os.access(path, os.R_OK) else None)
        if unusable is not None:
            print(f"flexff: error: {path}: {unusable}", file=sys.stderr)
            status = 2
            continue
        problems = validate_fmu(path, strict=args.strict, timeout=args.timeout,
                                confine=None if args.no_sandbox else confine_checks)
        errors = sum(p.severity == "error" for p in problems)
        counts = f"{errors} error(s), {len(problems) - errors} warning(s)"
        print(f"{path}: {'OK' if not problems else counts}")
        for problem in problems:
            effect = f" ({problem.in_run})" if problem.in_run else ""
            print(f"  - {problem.severity}{effect}: {problem}")
        if status != 2:
            status = max(status, int(errors > 0))
    return status


def _fmu_compare(args: argparse.Namespace) -> int:
    """Exit 0 when every FMU agrees, 1 when one differs or fails to run, 2 when a path is
    missing or not a usable FMU (the others are still compared)."""
    from flexff.cosim.compare import RTOL, compare_fmu

    if args.rtol is None:
        args.rtol = RTOL
    if not args.rtol > 0:
        raise InputError(f"--rtol {args.rtol:g}: expected a positive number")
    status = 0
    for path in args.files:
        try:
            comparison = compare_fmu(path)
        except (InputError, RunError) as error:
            print(f"flexff: error: {error}", file=sys.stderr, flush=True)
            status = max(status, 2 if isinstance(error, InputError) else 1)
            continue
        print(comparison.report(args.rtol), flush=True)
        if not comparison.agrees(args.rtol) and status == 0:
            status = 1
    return status


def _bench(args: argparse.Namespace) -> int:
    if args.output:
        _output_file(args.output)
    if args.training:
        from flexff.training_bench import training_benchmark

        save = (lambda figures: Path(args.output).write_text(json.dumps(figures, indent=2))) \
            if args.output else None
        presets = (args.preset,) if args.preset else PRESETS
        return _print_json(training_benchmark(Path(args.training).resolve(), presets,
                                              bf16=not args.no_bf16, save=save), args.output)
    if args.processes:
        from flexff.process_bench import process_benchmark

        if not Path(args.processes).is_file():
            raise InputError(f"{args.processes}: no such FMU file (bench --processes FILE.fmu)")
        try:
            steps = [int(n) for n in args.process_steps.split(",")]
        except ValueError:
            raise InputError(f"--process-steps takes whole numbers separated by commas, got "
                             f"{args.process_steps!r}") from None
        return _print_json(process_benchmark(Path(args.processes).resolve(), steps,
                                             repeats=args.process_repeats,
                                             ecos_python=args.ecos_python), args.output)
    from flexff.bench import network_call_table, realtime_table, run_benchmarks

    models = None
    if args.models:
        models = {p.stem: p for p in sorted(Path(args.models).glob("*.onnx"))}
        if not models:
            raise InputError(f"no .onnx files in {args.models}")
    figures = run_benchmarks(steps=args.steps, models=models,
                             realtime_seconds=args.realtime_seconds)
    status = _print_json(figures, args.output)
    # the JSON is stdout's (for a pipe); the table is for whoever reads along
    print(network_call_table(figures["network_call"]), file=sys.stderr, flush=True)
    print(realtime_table(figures["realtime"]), file=sys.stderr, flush=True)
    return status


def _print_json(data: dict[str, Any], output: str | None) -> int:
    """Print `data` as JSON, and write it to `output` too where given."""
    text = json.dumps(data, indent=2)
    print(text)
    if output:
        with open(output, "w") as f:
            f.write(text + "\n")
    return 0


def _run(args: argparse.Namespace) -> int:
    from flexff.cosim.batch import run_batch, sweep
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
        axes: dict[str, list[Any]] = {}
        for text in args.sweep:
            key, values = _sweep_values(text)
            if key in axes:
                raise InputError(f"--sweep {key} is given twice: list its values once")
            axes[key] = values
        configs = sweep(configs[0], axes)
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


def _sweep_values(text: str) -> tuple[str, list[Any]]:
    """`table.key=v1,v2,...` -> (table.key, [values]), the values read as TOML."""
    import tomllib

    key, sep, values = text.partition("=")
    if not sep or not values:
        raise InputError(f"--sweep expects TABLE.KEY=V1,V2,..., got {text!r}")
    try:
        return key.strip(), tomllib.loads(f"v = [{values}]")["v"]
    except tomllib.TOMLDecodeError:
        raise InputError(f"--sweep values must be TOML values (strings quoted): {values!r}") \
            from None


def machine_options(parser: argparse.ArgumentParser) -> None:
    """The excitation of a loop with a [machine] (learning.excitation)."""
    parser.add_argument("--trajectories", type=int, nargs=2, default=[24, 6],
                        metavar=("TRAIN", "TEST"),
                        help="a [machine] loop: excitation trajectories (default 24 6)")
    parser.add_argument("--duration", type=float, default=20.0, metavar="S",
                        help="a [machine] loop: seconds per trajectory (default 20)")
    parser.add_argument("--classes", nargs="+", default=list(EXCITATION), metavar="CLASS",
                        choices=EVERY_EXCITATION,
                        help=f"a [machine] loop: the excitation's classes, in turn (default "
                             f"{' '.join(EXCITATION)}; also {', '.join(EVERY_EXCITATION[4:])})")


def _tracked_axes(metrics: dict[str, Any]) -> list[str]:
    """The axes a run's or trial's metrics hold: the manipulator's x, y or a machine's."""
    return [a for a, m in metrics.items() if isinstance(m, dict) and "e2" in m]


def _print_result(name: object, metrics: dict[str, Any], output: object) -> None:
    """One line per run, and a second where its learned feedforward extrapolates."""
    from flexff.cosim.run import range_warning

    tracking = ""
    axes = _tracked_axes(metrics)
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
    if warning := range_warning(metrics):
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

    _output_file(args.output)
    print(f"wrote {export_ssp(load_run_config(args.config), args.output)}")
    return 0


def _data_collect(args: argparse.Namespace) -> int:
    from flexff.learning.collect import run_collection
    from flexff.learning.loop import is_manipulator_loop

    config = None
    if args.config is not None:
        from flexff.cosim.run import load_run_config

        config = load_run_config(args.config)
        if not is_manipulator_loop(config):
            from flexff.learning.machine_collect import collect_machine

            train, test = args.trajectories
            data = collect_machine(config, args.output, train, test, args.duration,
                                   workers=args.workers, classes=args.classes)
            print(f"{data.description.name}: {len(data.trajectories)} trajectories -> "
                  f"{data.path}")
            return 0
    if args.set is None:
        raise InputError("data collect needs --set NAME, or --config LOOP.toml with a [machine]")
    report = run_collection(args.set, args.output, args.workers, args.scheduler, config=config,
                            draws=args.draws)
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
    from flexff.cosim.machine import load_machine
    from flexff.learning.logs import import_logs
    from flexff.learning.machine_logs import import_machine_logs

    test = None if args.test is None else [n.strip() for n in args.test.split(",") if n.strip()]
    dataset = (import_logs(args.files, args.output, args.rate, test) if args.machine is None
               else import_machine_logs(args.files, args.output, load_machine(args.machine),
                                        args.rate, test))
    for t in dataset.trajectories:
        print(f"{t.name} ({t.split}): {len(t)} samples; derived, not measured: "
              f"{', '.join(t.derived) or 'nothing'}")
    print(f"{len(dataset.trajectories)} logs -> {dataset.path} at {dataset.sample_rate_hz:g} Hz"
          f" (test split: {', '.join(t.name for t in dataset.split('test'))})")
    return 0


def _train(args: argparse.Namespace) -> int:
    """One run into OUTPUT, or with several --seed or a --scheduler one run per seed into
    OUTPUT/seedN, side by side (learning.workers); prints the metrics as JSON."""
    from flexff.learning.machine_dataset import is_machine_dataset

    if is_machine_dataset(args.data):
        return _train_machine(args)
    overrides = {"labels": args.labels, **_epochs(args),
                 **({"force_input": True} if args.force_input else {}),
                 **({"cuda_graphs": True} if args.cuda_graphs else {})}
    seeds = args.seed or [0]
    if len(seeds) == 1 and args.scheduler is None:
        from flexff.learning.train import train

        metrics = train(args.model, args.preset, args.data, args.output, resume=args.resume,
                        force=args.force, checkpoint_every=args.checkpoint_every,
                        **overrides, seed=seeds[0], device=args.device)
        print(json.dumps(metrics, indent=2, default=str))
        return 0
    from flexff.learning.workers import TrainJob, train_parallel

    if args.resume or args.force or args.checkpoint_every is not None:
        raise InputError("--resume, --force and --checkpoint-every go with one seed trained "
                         "here; several seeds resume what their folders hold")
    if len(set(seeds)) != len(seeds):
        raise InputError(f"--seed: each seed once, got {seeds}")
    jobs = [TrainJob(args.model, args.preset, Path(args.data), Path(args.output) / f"seed{s}",
                     {**overrides, "seed": s}, label=f"seed{s}") for s in seeds]
    results = train_parallel(jobs, scheduler=args.scheduler, device=args.device)
    print(json.dumps(results, indent=2, default=str))
    return 0


def _train_machine(args: argparse.Namespace) -> int:
    """train on a machine's dataset: one seed, on features with the friction widths of its
    prior identified on it (the prior itself for pgnn)."""
    from flexff.learning.machine_dataset import load_machine_dataset
    from flexff.learning.machine_evaluate import learned_features
    from flexff.learning.machine_identify import identify_dataset
    from flexff.learning.machine_train import fit_machine
    from flexff.learning.presets import make_config

    if len(args.seed or [0]) > 1 or args.scheduler is not None or args.labels != "forces" \
            or args.force_input:
        raise InputError("a machine's dataset trains one seed here, on its efforts, without "
                         "--force-input (its physics is the pgnn's prior)")
    data = load_machine_dataset(args.data)
    config = make_config(args.model, args.preset, seed=(args.seed or [0])[0],
                         device=args.device, **_epochs(args))
    identified = identify_dataset(data)
    metrics = fit_machine(config, data.description, data.sample_rate_hz, data.trajectories,
                          data.digest, Path(args.output), learned_features(identified),
                          resume=args.resume, force=args.force,
                          checkpoint_every=args.checkpoint_every,
                          prior=identified if args.model == "pgnn" else None)
    print(json.dumps(metrics, indent=2, default=str))
    return 0


def _export(args: argparse.Namespace) -> int:
    from flexff.learning.export import export

    _output_file(args.output)
    print(f"wrote {export(args.run, args.output, inputs=args.inputs)}")
    return 0


def _identify(args: argparse.Namespace) -> int:
    from flexff.cosim.run import output_folder
    from flexff.learning.evaluate import preprocessing
    from flexff.learning.identify import REPORT, identify, relative_gains, write_identification
    from flexff.learning.machine_dataset import is_machine_dataset

    output_folder(args.output)  # a folder, as for every command: made, or refused, first
    if is_machine_dataset(args.data):
        from flexff.learning.linear_model import write_linear_model
        from flexff.learning.machine_dataset import load_machine_dataset
        from flexff.learning.machine_identify import dataset_features, identify_dataset

        data = load_machine_dataset(args.data)
        features, settings = dataset_features(data)
        print(settings)
        model = identify_dataset(data, features)
        print(model.summary())
        print(f"wrote {write_linear_model(model, Path(args.output) / REPORT)}")
        return 0

    identification = identify(args.data, preprocessing(args.env))
    path = write_identification(identification, args.output)
    rows = identification.rows()
    width = max(len(row["base"]) for row in rows)
    print(f"{'base parameter':<{width}} {'value':>12} {'std':>10}  unit")
    for row in rows:
        std = f"{row['std']:10.3g}" if row["estimated"] else f"{'(nominal)':>10}"
        print(f"{row['base']:<{width}} {row['value']:12.5g} {std}  {row['unit']}")
    print(f"motor friction tanh width w_stribeck: {identification.w_stribeck:g} rad/s; "
          f"{identification.samples} samples")
    relative = " / ".join(f"{k:.4f}" for k in relative_gains(identification.gains))
    print(f"torque constants relative to one another (motors 1 / 2 / 3): {relative}")
    for label, (x, y) in (("residual", identification.residual_rms),
                          ("nominal model's error", identification.nominal_rms),
                          ("forces", identification.label_rms)):
        print(f"{label}: {x:.3g} / {y:.3g} N rms (x / y)")
    print(f"wrote {path} (use it with [feedforward] kind = \"rigid-body\", identified = "
          f"\"{path}\")")
    return 0


def _evaluate(args: argparse.Namespace) -> int:
    from flexff.cosim.run import load_run_config, output_folder
    from flexff.learning.evaluate import evaluate
    from flexff.learning.loop import is_manipulator_loop
    from flexff.learning.machine_dataset import is_machine_dataset

    loop = None if args.config is None else load_run_config(args.config)
    machine = loop is not None and not is_manipulator_loop(loop)
    logs = loop is None and args.data is not None and is_machine_dataset(args.data)
    if logs and any(v is not None for v in (args.ilc_iterations, args.ilc_cutoff,
                                            args.ilc_gain)):
        raise InputError("--ilc-iterations, --ilc-cutoff and --ilc-gain set the ILC of a loop: "
                         "leave them out for imported logs (no loop runs)")
    if (machine or logs) and (args.currents or args.ilc_labels or args.force_input):
        raise InputError("--currents, --ilc-labels and --force-input are for the manipulator's "
                         f"environments: leave them out for "
                         f"{'a machine' if machine else 'imported logs'}")
    output_folder(args.output)
    if machine:
        return _evaluate_machine(args, loop)
    if logs:
        return _evaluate_logs(args)
    evaluate(args.env, args.output, args.preset, args.models, args.data, args.epochs, loop=loop,
             scheduler=args.scheduler, currents=args.currents, device=args.device,
             ilc_labels=None if args.ilc_labels is None else
             [kind for kind in args.ilc_labels if kind != "none"], force_input=args.force_input,
             ilc_iterations=args.ilc_iterations, ilc_cutoff_hz=args.ilc_cutoff,
             ilc_gain=args.ilc_gain)
    print((Path(args.output) / "table.md").read_text())
    print(f"results in {args.output}/ (summary.json, table.md, paths.png, errors.png, "
          f"forces.png, the .onnx models, ilc/ for the limit, held-out/ for the test split's "
          f"references)")
    return 0


def _ilc(args: argparse.Namespace) -> int:
    from flexff.cosim.run import load_run_config
    from flexff.learning.ilc import NOISE_FLOOR, RESULT, ilc

    state = ilc(load_run_config(args.config), args.output, args.iterations, args.cutoff,
                gain=args.gain)
    for trial in state["trials"]:
        axes = _tracked_axes(trial)
        e2 = ", ".join(f"{trial[a]['e2']:.4g}" for a in axes)
        ratio = ", ".join(f"{trial[a]['e2_ratio']:.4g}" for a in axes)
        unit = " m/sqrt(s)" if axes == ["x", "y"] else f" ({', '.join(axes)})"
        print(f"trial {trial['trial']}: e2 = ({e2}){unit}, PID alone / trial = ({ratio})")
    print(f"best: trial {state['best']}; its feedforward force -> {args.output}/{RESULT} "
          f"(ilc.json, e2.png beside it)")
    if floor := state[NOISE_FLOOR]:
        print(f"noise floor: e2 = ({', '.join(f'{v:.4g}' for v in floor.values())}) "
              f"({', '.join(floor)}), what the measurement's noise and quantization add; no "
              f"feedforward goes below it")
    return 0


def _demo(args: argparse.Namespace) -> int:
    from flexff.cosim.run import output_folder
    from flexff.demo import run_demo

    output_folder(args.output)
    return run_demo(args.output, args.device)


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="flexff", description="Learned feedforward control for a machine's loop, as FMI "
                                   "co-simulation: describe the loop's FMUs and axes (or import "
                                   "its logs), collect data, identify, train, and build the "
                                   "feedforward FMU. The thesis's flexure manipulator is the "
                                   "built-in example and default.")
    parser.add_argument("--debug", action="store_true",
                        help="show the Python traceback of an error (sets FLEXFF_DEBUG=1)")
    commands = parser.add_subparsers(dest="command", required=True)

    plant = commands.add_parser("plant", help="the built-in example's plant model (the "
                                              "thesis's flexure manipulator)")
    plant_commands = plant.add_subparsers(dest="plant_command", required=True)
    info = plant_commands.add_parser("info", help="parameters, natural frequencies, workspace")
    info.add_argument("--variant", choices=sorted(VARIANTS), default="nominal")
    info.add_argument("--json", action="store_true", help="print JSON instead of text")
    info.set_defaults(handler=_plant_info)

    fmu = commands.add_parser("fmu", help="build, validate and compare FMUs")
    fmu_commands = fmu.add_subparsers(dest="fmu_command", required=True)
    build = fmu_commands.add_parser("build", help="build an FMU")
    build.add_argument("kind", choices=["plant", "learned-feedforward", "onnx", "feedforward"],
                       help="the plant, a learned feedforward from an exported ONNX model, or "
                            "any ONNX graph of fixed-size float tensors")
    build.add_argument("graph", nargs="?", help="onnx: the .onnx file")
    build.add_argument("--variant", choices=sorted(VARIANTS), default="nominal",
                       help="plant variant")
    build.add_argument("--model", help="learned-feedforward: the .onnx file (flexff export)")
    build.add_argument("--step", type=float, default=1e-3,
                       help="learned-feedforward, onnx: communication step [s] (default 0.001)")
    build.add_argument("--every", type=int,
                       help="onnx: communication steps between calls of the graph, its results "
                            "extrapolated linearly in between (default 1)")
    build.add_argument("--task", action="store_true",
                       help="learned-feedforward, onnx: run the network in its own task (a "
                            "thread of the FMU), its result used one call period later, as "
                            "Simulink Real-Time's multitasking does")
    build.add_argument("--runtime", choices=RUNTIMES,
                       help="learned-feedforward, onnx: what computes the network: c (default) "
                            "compiles it into the FMU as generated C, whose sources then build "
                            "anywhere alone; onnxruntime bundles the graph and onnxruntime's "
                            "library")
    build.add_argument("--fmi", type=int, choices=FMI_VERSIONS, default=FMI_VERSIONS[0],
                       help="the FMI version of the co-simulation FMU: 2 (default) or 3 (3.0, "
                            "computing bit for bit what the 2.0 FMU does)")
    build.add_argument("--platform", action="append", choices=[*PLATFORMS, ALL],
                       help="build the binaries for this platform, by its cross-compiler where "
                            "it is not this machine's (repeat it for several; all: every one; "
                            "default: this machine's)")
    build.add_argument("--source-only", action="store_true",
                       help="no binaries: the sources alone, for the importer to compile")
    build.add_argument("-o", "--output", required=True, help="the .fmu file to write")
    build.set_defaults(handler=_fmu_build)
    validate = fmu_commands.add_parser("validate", help="fmpy's validation plus our own checks")
    validate.add_argument("files", nargs="+", help=".fmu files")
    validate.add_argument("--strict", action="store_true",
                          help="warnings are errors: the description's faults that a run "
                               "warns of (as a strict run refuses them), and a restored FMU "
                               "state that reproduces the outputs within the FMU's tolerance "
                               "but not bit for bit")
    validate.add_argument("--timeout", type=float,
                          help="seconds the run of one FMU may take before it counts as hung "
                               "(default: a minute, fmu.validation.TIMEOUT)")
    validate.add_argument("--no-sandbox", action="store_true",
                          help="run the FMU's code without the sandbox of an isolated run "
                               "(default: in it)")
    validate.set_defaults(handler=_fmu_validate)

    fmu_info = fmu_commands.add_parser(
        "info", help="what an FMU declares: ports, dependencies, default experiment, "
                     "interfaces, platforms")
    fmu_info.add_argument("file", help="an .fmu file")
    fmu_info.add_argument("--all", action="store_true", help="list local variables too")
    fmu_info.add_argument("--json", action="store_true", help="print JSON instead of text")
    fmu_info.set_defaults(handler=_fmu_info)

    compare = fmu_commands.add_parser(
        "compare", help="run each FMU alone on its default experiment in flexff and in FMPy; "
                        "the largest difference per output")
    compare.add_argument("files", nargs="+", help=".fmu files")
    compare.add_argument("--rtol", type=float,
                         help="relative difference within which an output agrees (default: "
                              "cosim.compare.RTOL, 1e-9)")
    compare.set_defaults(handler=_fmu_compare)

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

    train = commands.add_parser("train", help="train a feedforward model on a dataset folder")
    train.add_argument("--model", required=True, choices=MODELS, help="the network")
    train.add_argument("--preset", default="fast", choices=PRESETS,
                       help="fast: minutes on a laptop CPU; "
                            "thesis: the thesis's network sizes (GPU)")
    train.add_argument("--data", required=True,
                       help="a dataset folder (flexff data collect or data import)")
    train.add_argument("-o", "--output", required=True, help="the run folder to write")
    train.add_argument("--epochs", type=int, help="override the preset's number of epochs")
    train.add_argument("--labels", default="forces", choices=("forces", "currents"),
                       help="what the model learns and feeds forward: the efforts the loop "
                            "commands (default; a machine's axes' efforts, the manipulator's "
                            "wrist force Fx, Fy), or, on the manipulator, the motor currents "
                            "i1..i3, added after the control allocation")
    train.add_argument("--force-input", action="store_true",
                       help="give a black-box network the force of the rigid-body model "
                            "identified on the training split as two more inputs")
    existing = train.add_mutually_exclusive_group()
    existing.add_argument("--resume", action="store_true",
                          help="continue the unfinished run in the run folder from its last "
                               "checkpoint (same settings and data)")
    existing.add_argument("--force", action="store_true",
                          help="train into a run folder that is not empty, starting afresh "
                               "(a finished run's files stay until the new ones are complete)")
    train.add_argument("--checkpoint-every", type=int, metavar="N",
                       help="epochs between checkpoints (default: the preset's)")
    train.add_argument("--seed", type=int, action="append", metavar="S",
                       help="the training seed (default 0); repeated, one run per seed into "
                            "OUTPUT/seedS, side by side (flexff export takes them as an "
                            "ensemble)")
    train.add_argument("--scheduler", help="address of a Dask scheduler to train on (its "
                                           "workers see this file system)")
    _device_option(train, "train on")
    train.add_argument("--cuda-graphs", action="store_true",
                       help="on CUDA, replay each training step from a CUDA graph (2.8 to 6 "
                            "times faster an epoch on an H200; off by default, see the GPU "
                            "how-to)")
    train.set_defaults(handler=_train)

    export = commands.add_parser("export", help="export a training run (or an ensemble of "
                                                "runs) to ONNX")
    export.add_argument("run", nargs="+", help="the run folder (flexff train); several runs "
                                               "of one model kind give one graph of their mean")
    export.add_argument("-o", "--output", required=True, help="the .onnx file to write")
    export.add_argument("--inputs", default="features", choices=("features", "reference"),
                        help="graph inputs: the SI features, or the reference signals "
                             "(x_ref .. ay_ref) with the features computed in the graph")
    export.set_defaults(handler=_export)

    identification = commands.add_parser(
        "identify", help="identify a dataset's physics prior by least squares (a machine's "
                         "terms, or the manipulator's rigid-body model)")
    identification.add_argument("data", help="a dataset folder (its training split is used)")
    identification.add_argument("-o", "--output", required=True,
                                help="the folder to write identified.json into (made if "
                                     "missing; an existing folder is written into)")
    identification.add_argument("--env", default="hardware", choices=("sim", "hardware"),
                                help="a manipulator dataset: preprocess as flexff evaluate's "
                                     "environment does: hardware (the thesis's: encoders "
                                     "counted, 1.8 Hz; for measured or noisy encoders) or sim "
                                     "(ideal encoders); a machine's dataset derives its own")
    identification.set_defaults(handler=_identify)

    bench = commands.add_parser("bench", help="speed benchmarks, printed as JSON (the "
                                "network's time per call also as a table, on stderr)")
    bench.add_argument("--steps", type=int, default=20000, help="steps per timed loop")
    bench.add_argument("-o", "--output", help="also write the JSON to this file")
    bench.add_argument("--processes", metavar="FILE.fmu",
                       help="instead: whole processes side by side on this FMU (flexff run, "
                            "fmpy.simulate_fmu, Ecos where installed), each writing its "
                            "default record")
    bench.add_argument("--training", metavar="DATA",
                       help="instead: the trainings' start-up and seconds per epoch on this "
                            "dataset folder (a sim or hardware set), each model of both "
                            "presets, on CUDA where available and on the CPU")
    bench.add_argument("--no-bf16", action="store_true",
                       help="with --training: leave out the bf16 autocast runs on CUDA")
    bench.add_argument("--preset", choices=PRESETS,
                       help="with --training: this preset alone (default: both)")
    bench.add_argument("--process-steps", default="200000,2000000", metavar="N,N",
                       help="with --processes: the run lengths in steps (of 1 ms)")
    bench.add_argument("--process-repeats", type=int, default=3, metavar="R",
                       help="with --processes: runs of each tool, alternated")
    bench.add_argument("--ecos-python", metavar="PYTHON",
                       help="with --processes: an interpreter with ecospy (default: this one)")
    bench.add_argument("--realtime-seconds", type=float, metavar="S",
                       help="pace only the first S seconds of the 100 s hardware evaluation "
                            "in the real-time figures, the record on and off among them "
                            "(default: all of it)")
    bench.add_argument("--models", help="a folder of exported .onnx models (e.g. flexff "
                                        "evaluate's) for the feedforward figures; default: "
                                        "untrained exports of each model kind")
    bench.set_defaults(handler=_bench)

    evaluation = commands.add_parser(
        "evaluate", help="collect, train, export, co-simulate the loop with each feedforward "
                         "and report its tracking against PID alone (on the manipulator, the "
                         "thesis's Table 5.2 or 6.2); with --data of imported logs, each "
                         "model's effort prediction")
    evaluation.add_argument("--env", default="sim", choices=("sim", "hardware"),
                            help="the manipulator's environment, without --config or --data: "
                                 "sim (Table 5.2) or hardware (Table 6.2)")
    evaluation.add_argument("--config", metavar="CONFIG.toml|SYSTEM.ssp",
                            help="collect and evaluate on this loop (flexff's controller and "
                                 "any plant) instead of the environment's plant")
    evaluation.add_argument("-o", "--output", required=True, help="the output folder")
    evaluation.add_argument("--preset", default="fast", choices=PRESETS)
    evaluation.add_argument("--models", nargs="+", default=list(MODELS), choices=MODELS)
    evaluation.add_argument("--currents", nargs="+", default=[], metavar="KIND",
                            choices=MODELS,
                            help="the manipulator: also the current-level model of these kinds: "
                                 "labels i1..i3, fed forward after the control allocation")
    evaluation.add_argument("--ilc-labels", nargs="+", metavar="KIND",
                            choices=(*MODELS, "none"),
                            help="also these kinds trained on the force iterative learning "
                                 "control learns on each training reference (2 trials each); "
                                 "default: pgnn on --env hardware, where --models has it; "
                                 "none: no ILC labels"),
    evaluation.add_argument("--force-input", nargs="+", default=[], metavar="KIND",
                            choices=[m for m in MODELS if m != "pgnn"],
                            help="also these black-box kinds with the identified rigid-body "
                                 "force as two more inputs (on the ILC labels too where "
                                 "--ilc-labels names the kind)")
    evaluation.add_argument("--data", help="a collected dataset folder to use; a machine's "
                                           "imported logs alone: each model's force "
                                           "prediction on the test logs")
    evaluation.add_argument("--epochs", type=int, help="override the preset's number of epochs")
    evaluation.add_argument("--scheduler", help="address of a Dask scheduler to collect and "
                                                "train on (its workers see this file system)")
    _device_option(evaluation, "train the networks on")
    machine_options(evaluation)
    _ilc_options(evaluation, "--ilc-")
    evaluation.set_defaults(handler=_evaluate)

    prediction = commands.add_parser(
        "predict", help="each trained model's predicted effort per sample of a machine's logs "
                        "beside the measured one (raw and filtered), as CSV, JSON and PNG")
    prediction.add_argument("run", help="flexff evaluate's output folder (identified.json, "
                                        "runs/) or one training run folder")
    prediction.add_argument("--data", required=True,
                            help="a machine dataset folder (flexff data import --machine)")
    prediction.add_argument("-o", "--output", required=True,
                            help="the CSV file to write (its .json and .png beside it)")
    prediction.add_argument("--split", default="all", choices=("all", "train", "test"),
                            help="the dataset's trajectories to predict (default all)")
    prediction.set_defaults(handler=_predict)

    tune = commands.add_parser(
        "tune", help="measure each axis's plant in a loop (a chirp) and propose its PID "
                     "block's mass, damping and crossover_hz for a phase margin, as TOML")
    tune.add_argument("config", metavar="CONFIG.toml|SYSTEM.ssp",
                      help="the loop with a [machine] (its PID closed while measuring)")
    tune.add_argument("-o", "--output", required=True, help="the TOML file to write")
    tune.add_argument("--phase-margin", type=float, default=40.0, metavar="DEG",
                      help="the phase margin to keep (default 40)")
    tune.add_argument("--seconds", type=float, default=8.0, metavar="S",
                      help="the chirp's length per axis (default 8)")
    tune.add_argument("--high-hz", type=float, metavar="HZ",
                      help="the chirp's highest frequency, the highest crossover proposed "
                           "(default 5 %% of the loop's rate)")
    tune.set_defaults(handler=_tune)

    learning = commands.add_parser(
        "ilc", help="iterative learning control on a run's one reference: the best feedforward "
                    "force for it, as a CSV table a run can use (resumes an interrupted one)")
    learning.add_argument("config", metavar="CONFIG.toml|SYSTEM.ssp",
                          help="the loop and its reference (flexff's controller, any plant; "
                               "its own feedforward is replaced)")
    learning.add_argument("-o", "--output", required=True, help="the output folder")
    _ilc_options(learning, "--")
    learning.set_defaults(handler=_ilc)

    demo = commands.add_parser("demo", help="the whole pipeline on the embedded defaults")
    demo.add_argument("-o", "--output", default="flexff-demo", help="output folder")
    _device_option(demo, "train the networks on")
    demo.set_defaults(handler=_demo)
    return parser


def _ilc_options(command: argparse.ArgumentParser, prefix: str) -> None:
    """ILC's settings (learning.ilc), named `prefix`iterations, `prefix`cutoff, `prefix`gain;
    a loop's [machine.ilc] gives the defaults the options leave unset."""
    command.add_argument(f"{prefix}iterations", type=int, metavar="N",
                         help=f"ILC: learning trials after PID alone (default: [machine.ilc] "
                              f"iterations, else {ITERATIONS})")
    command.add_argument(f"{prefix}cutoff", type=float, metavar="HZ",
                         help=f"ILC: corner of the learning filter's zero-phase low-pass Q "
                              f"(default: [machine.ilc] cutoff_hz, else {CUTOFF_HZ:g} on "
                              f"the manipulator, 0.15 times the rate on a loop with a "
                              f"[machine])")
    command.add_argument(f"{prefix}gain", type=float, metavar="G",
                         help=f"ILC: learning gain on the model's correction (default: "
                              f"[machine.ilc] gain, else {GAIN:g}; lower it where the "
                              f"iteration diverges)")


def _device_option(command: argparse.ArgumentParser, what: str) -> None:
    command.add_argument("--device", default="auto", choices=DEVICES,
                         help=f"where to {what}: auto (CUDA when available, default), cpu or "
                              f"cuda (four training processes share each GPU)")


def _failure(error: BaseException, command: str, debug: bool = False) -> tuple[int, str]:
    """The exit code and the line on stderr for an error that stopped `command`: bad input
    (InputError, an OSError about a path) 2, a run that failed (RunError, an OSError such as a
    full disk, MemoryError) 1, a package of the extra "learn" missing (training, export) 1 and
    what to install, anything else, a bug, 1 and how to see its traceback."""
    from flexff.cosim.timing import OverrunError

    if isinstance(error, KeyboardInterrupt):  # the run says what it kept, else KEPT does
        kept = str(error) or KEPT.get(command)
        if isinstance(error, Terminated):
            return 143, "flexff: terminated" + (f"; {kept}" if kept else "")
        return 130, "flexff: interrupted" + (f"; {kept}" if kept else "")
    if isinstance(error, OverrunError):
        return 3, f"flexff: error: {error}"
    if isinstance(error, MemoryError):
        return 1, f"flexff: error: out of memory{f' ({error})' if str(error) else ''}"
    if isinstance(error, OSError):
        code = 2 if isinstance(error, INPUT_ERRORS) or error.errno in INPUT_ERRNOS else 1
        message = error.strerror or str(error)
        if error.filename is not None:
            message = f"{error.filename}: {message}"
        return code, f"flexff: error: {message}"
    if isinstance(error, (InputError, RunError)):
        return (2 if isinstance(error, InputError) else 1), f"flexff: error: {error}"
    missing = (error.name or "").split(".")[0] if isinstance(error, ModuleNotFoundError) else ""
    if missing in LEARN:
        return 1, (f"flexff: error: flexff {command} needs {LEARN[missing]}: "
                   "pip install 'flexff[learn]'")
    return 1, f"flexff: error: {type(error).__name__}: {error}{'' if debug else BUG_HINT}"


def _show_warning(message: Warning | str, category: type[Warning], filename: str, lineno: int,
                  file: TextIO | None = None, line: str | None = None) -> None:
    """A warning as one line on stderr, as errors are (the traceback's place: --debug)."""
    print(f"flexff: warning: {message}", file=sys.stderr)


def main(argv: Sequence[str] | None = None) -> int:
    """Run the command of `argv` (default: sys.argv); return its exit code, never raise."""
    warnings.showwarning = _show_warning
    try:
        args = build_parser().parse_args(argv)
    except SystemExit as done:  # --help, or a usage error argparse has printed
        return int(done.code or 0)
    if args.debug:
        os.environ["FLEXFF_DEBUG"] = "1"  # worker processes inherit it (cosim.batch)
    handler: Callable[[argparse.Namespace], int] = args.handler
    main_thread = threading.current_thread() is threading.main_thread()
    previous = signal.signal(signal.SIGTERM, _terminate) if main_thread else None
    try:
        return handler(args)
    except (Exception, KeyboardInterrupt) as error:
        debug = os.environ.get("FLEXFF_DEBUG") == "1"
        if debug:
            traceback.print_exc()
        command = " ".join(filter(None, (args.command, getattr(args, "data_command", None))))
        code, line = _failure(error, command, debug)
        print(line, file=sys.stderr)
        return code
    finally:
        if main_thread:
            signal.signal(signal.SIGTERM, previous)


def _terminate(number: int, frame: object) -> None:
    """SIGTERM's handler: end the command as Ctrl-C does (flexff.fmu.errors.Terminated)."""
    raise Terminated


if __name__ == "__main__":
    raise SystemExit(main())
