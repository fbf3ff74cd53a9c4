"""`flexff bench`: the speed benchmarks (flexff.bench, process_bench, training_bench)."""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path
from typing import Any

from flexff.cli.shared import PRESETS, Commands, output_file
from flexff.fmu.errors import InputError


def _bench(args: argparse.Namespace) -> int:
    if args.output:
        output_file(args.output)
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


def add_commands(commands: Commands) -> None:
    """Add `bench`."""
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
