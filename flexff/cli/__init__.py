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
import os
import signal
import sys
import threading
import traceback
import warnings
from collections.abc import Callable, Sequence
from typing import TextIO

from flexff.cli import bench, data, demo, evaluation, fmu, learning, plant, run
from flexff.fmu.errors import InputError, RunError, Terminated

GROUPS = (plant.add_commands, fmu.add_commands, run.add_commands, data.add_commands,
          learning.add_commands, bench.add_commands, evaluation.add_commands, demo.add_commands)

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


def build_parser() -> argparse.ArgumentParser:
    """The parser of every command, each group's added by its module."""
    parser = argparse.ArgumentParser(
        prog="flexff", description="Learned feedforward control for a machine's loop, as FMI "
                                   "co-simulation: describe the loop's FMUs and axes (or import "
                                   "its logs), collect data, identify, train, and build the "
                                   "feedforward FMU. The thesis's flexure manipulator is the "
                                   "built-in example and default.")
    parser.add_argument("--debug", action="store_true",
                        help="show the Python traceback of an error (sets FLEXFF_DEBUG=1)")
    commands = parser.add_subparsers(dest="command", required=True)
    for add_commands in GROUPS:  # in this order in --help and the reference
        add_commands(commands)
    return parser


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
