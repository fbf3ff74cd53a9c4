"""The example machines' plants as built-in FMUs (entry point of cosim.builtins): registered
by name and path, imported only when a run builds one."""

from __future__ import annotations

from flexff.cosim.builtins import register_builtin

STAGE_OPTIONS = ("axes",)  # machines.stage


def register() -> None:
    register_builtin("drive", (), "flexff.machines.drive:drive_from_options",
                     "1-axis linear drive (machines.drive): effort F in, encoder x out")
    register_builtin("stage", STAGE_OPTIONS, "flexff.machines.stage:stage_from_options",
                     "2-axis gantry stage (machines.stage): efforts Fx, Fy in, encoders x, y out")
