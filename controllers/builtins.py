"""The generic loop blocks as built-in FMUs (entry point of cosim.builtins): registered by
name and path, imported only when a run builds one."""

from __future__ import annotations

from flexff.cosim.builtins import register_builtin


def register() -> None:
    register_builtin("pid", ("axes",), "flexff.controllers.blocks:pid_from_options",
                     "a PID per axis: axes = [{name, mass, crossover_hz, damping, stiffness, "
                     "notch_hz, lowpass_hz, effort_limit, unit, effort_unit}]")
