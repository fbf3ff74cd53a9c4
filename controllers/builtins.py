"""The generic loop blocks as built-in FMUs (entry point of cosim.builtins): registered by
name and path, imported only when a run builds one."""

from __future__ import annotations

from flexff.controllers.block_options import GAIN_OPTIONS, PID_OPTIONS, SUM_OPTIONS
from flexff.cosim.builtins import register_builtin


def register() -> None:
    register_builtin("pid", ("axes",), "flexff.controllers.blocks:pid_from_options",
                     "a PID per axis: axes = [{name, mass, crossover_hz, damping, stiffness, "
                     "notch_hz, lowpass_hz, effort_limit, unit, effort_unit}]")
    register_builtin("pid-gains", PID_OPTIONS, "flexff.controllers.blocks_pid:pid_from_options",
                     "a PID per axis with tunable gains kp_a, ki_a, kd_a (explicit or "
                     "loop-shaped), notch, low-pass, back-calculation or clamp anti-windup")
    register_builtin("sum", SUM_OPTIONS, "flexff.controllers.blocks_signal:sum_from_options",
                     "output = sum of signs[k] * inputs[k]")
    register_builtin("gain", GAIN_OPTIONS, "flexff.controllers.blocks_signal:gain_from_options",
                     "output = gain * input (gain tunable)")
