"""`flexff plant`: the built-in example's plant model (plant.analysis)."""

from __future__ import annotations

import argparse
import json

from flexff.cli.shared import Commands
from flexff.plant.variants import VARIANTS


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


def add_commands(commands: Commands) -> None:
    """Add `plant info`."""
    plant = commands.add_parser("plant", help="the built-in example's plant model (the "
                                              "thesis's flexure manipulator)")
    plant_commands = plant.add_subparsers(dest="plant_command", required=True)
    info = plant_commands.add_parser("info", help="parameters, natural frequencies, workspace")
    info.add_argument("--variant", choices=sorted(VARIANTS), default="nominal")
    info.add_argument("--json", action="store_true", help="print JSON instead of text")
    info.set_defaults(handler=_plant_info)
