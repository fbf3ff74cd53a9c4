"""The example machines' plants as built-in FMUs (entry point of cosim.builtins): registered
by name and path, imported only when a run builds one."""

from __future__ import annotations

from flexff.cosim.builtins import register_builtin


def register() -> None:
    register_builtin("drive", (), "flexff.machines.drive:drive_from_options",
                     "1-axis linear drive (machines.drive): effort F in, encoder x out")
