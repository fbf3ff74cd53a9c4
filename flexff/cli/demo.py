"""`flexff demo`: the whole pipeline on the embedded defaults (flexff.demo)."""

from __future__ import annotations

import argparse

from flexff.cli.shared import Commands, device_option


def _demo(args: argparse.Namespace) -> int:
    from flexff.cosim.run import output_folder
    from flexff.demo import run_demo

    output_folder(args.output)
    return run_demo(args.output, args.device)


def add_commands(commands: Commands) -> None:
    """Add `demo`."""
    demo = commands.add_parser("demo", help="the whole pipeline on the embedded defaults")
    demo.add_argument("-o", "--output", default="flexff-demo", help="output folder")
    device_option(demo, "train the networks on")
    demo.set_defaults(handler=_demo)
