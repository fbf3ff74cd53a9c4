"""The example machines' plants as built-in FMUs (entry point of cosim.builtins)."""

from __future__ import annotations


def register() -> None:
    from flexff.cosim.builtins import register_builtin
    from flexff.machines.drive import drive_from_options

    register_builtin("drive", (), drive_from_options,
                     "1-axis linear drive (machines.drive): effort F in, encoder x out")
