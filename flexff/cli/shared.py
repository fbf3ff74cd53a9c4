"""What several command groups share: the choices named here to keep torch, numpy and scipy
unloaded until a command runs, the options more than one command takes, and output checks."""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import TypeAlias

from flexff.fmu.errors import InputError

# the `commands` sub-parser object each group adds its commands to
Commands: TypeAlias = "argparse._SubParsersAction[argparse.ArgumentParser]"

MODELS = ("lstm", "cnn-lstm", "tcn", "pgnn")  # learning.models, named here to keep torch unloaded
PRESETS = ("fast", "thesis")
TRAJECTORY_SETS = ("sim", "hardware")  # learning.dataset.SETS, named here to keep numpy unloaded
DEVICES = ("auto", "cpu", "cuda")  # learning.devices', named here to keep torch unloaded
EXCITATION = ("moves", "bang-bang", "spline", "multisine")  # learning.excitation's CLASSES,
EVERY_EXCITATION = (*EXCITATION, "sine", "random", "rest", "solo")  # and EVERY_CLASS
ITERATIONS, CUTOFF_SHARE, GAIN = 10, 0.15, 1.0  # learning.ilc's defaults (keeps scipy unloaded)


def output_file(path: str) -> None:
    """Check, before any work, that the file `path` can be written: its folder is made."""
    from flexff.cosim.run import output_folder

    if Path(path).is_dir():
        raise InputError(f"{path}: is a folder: give the name of the file to write")
    output_folder(Path(path).parent)


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


def ilc_options(command: argparse.ArgumentParser, prefix: str) -> None:
    """ILC's settings (learning.ilc), named `prefix`iterations, `prefix`cutoff, `prefix`gain;
    a loop's [machine.ilc] gives the defaults the options leave unset."""
    command.add_argument(f"{prefix}iterations", type=int, metavar="N",
                         help=f"ILC: learning trials after PID alone (default: [machine.ilc] "
                              f"iterations, else {ITERATIONS})")
    command.add_argument(f"{prefix}cutoff", type=float, metavar="HZ",
                         help=f"ILC: corner of the learning filter's zero-phase low-pass Q "
                              f"(default: [machine.ilc] cutoff_hz, else {CUTOFF_SHARE:g} "
                              f"times the loop's rate; the manipulator's description says "
                              f"20 Hz)")
    command.add_argument(f"{prefix}gain", type=float, metavar="G",
                         help=f"ILC: learning gain on the model's correction (default: "
                              f"[machine.ilc] gain, else {GAIN:g}; lower it where the "
                              f"iteration diverges)")


def device_option(command: argparse.ArgumentParser, what: str) -> None:
    command.add_argument("--device", default="auto", choices=DEVICES,
                         help=f"where to {what}: auto (CUDA when available, default), cpu or "
                              f"cuda (four training processes share each GPU)")
