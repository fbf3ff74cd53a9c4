"""`flexff fmu`: build, inspect, validate and compare FMUs (fmu/, cosim.compare)."""

from __future__ import annotations

import argparse
import json
import os
import sys
from pathlib import Path

from flexff.cli.shared import Commands, output_file
from flexff.fmu.defaults import DEFAULT_STEP
from flexff.fmu.errors import InputError, RunError
from flexff.fmu.fmi_version import FMI_VERSIONS
from flexff.fmu.network_runtime import RUNTIMES
from flexff.fmu.platforms import ALL, PLATFORMS
from flexff.plant.variants import VARIANTS


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
        system = learned_feedforward_system(args.model, args.step, task=args.task,
                                            runtime=runtime)
    else:
        from flexff.plant.system import plant_system

        system = plant_system(args.variant)
    if args.source_only and args.platform:
        raise InputError("--source-only builds no binaries: it takes no --platform")
    platforms = () if args.source_only else args.platform
    output_file(args.output)
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


def add_commands(commands: Commands) -> None:
    """Add `fmu build`, `fmu validate`, `fmu info` and `fmu compare`."""
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
    build.add_argument("--step", type=float, default=DEFAULT_STEP,
                       help=f"learned-feedforward, onnx: communication step [s] (default "
                            f"{DEFAULT_STEP:g})")
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
