"""The generic loop blocks as built-in FMUs (entry point of cosim.builtins): registered by
name and path, imported only when a run builds one."""

from __future__ import annotations

from flexff.blocks.options import (
    GAIN_OPTIONS,
    PID_ANTI_WINDUP,
    PID_FORMS,
    PID_LOWPASS_ORDERS,
    PID_OPTIONS,
    SUM_OPTIONS,
)
from flexff.cosim.builtins import Option, register_builtin

PID = ("a PID per axis a (inputs a_ref, a, a_ff; outputs a_effort, a_fb): gains loop-shaped "
       "(crossover_hz, mass, damping, stiffness) or explicit (kp, ki, kd, "
       "derivative_filter_hz), optional notch and low-pass, anti-windup at effort_limit. "
       "axes: names (each per-axis option a number or a table {axis = number}) or tables "
       "{name, unit, effort_unit, per-axis options}. form \"series\": the loop-shaped series "
       "form, Tustin at the crossover, tunable scale kp_a, conditional integration and a "
       "first-order low-pass by default; \"parallel\": tunable kp_a, ki_a, kd_a, "
       "back-calculation and a second-order low-pass by default")


def _pid_options(form: str) -> tuple[str | Option, ...]:
    """The PID block's options, `form` the default form."""
    special = {"form": Option("form", "choice", form, choices=PID_FORMS),
               "anti_windup": Option("anti_windup", "choice", choices=PID_ANTI_WINDUP),
               "lowpass_order": Option("lowpass_order", "integer", choices=PID_LOWPASS_ORDERS),
               "lowpass_zeta": Option("lowpass_zeta", "number", positive=True),
               "effort_unit": Option("effort_unit", default="N"),
               "position_unit": Option("position_unit", default="m")}
    return tuple(special.get(key, key) for key in PID_OPTIONS)


def register() -> None:
    register_builtin("pid", _pid_options("series"),
                     "flexff.blocks.pid_options:pid_from_options", PID)
    register_builtin("pid-gains", _pid_options("parallel"),
                     "flexff.blocks.pid_options:pid_gains_from_options",
                     "the PID block of \"pid\" with form = \"parallel\" unless given: "
                     "tunable gains kp_a, ki_a, kd_a, explicit or loop-shaped")
    register_builtin("sum", SUM_OPTIONS, "flexff.blocks.sum_gain:sum_from_options",
                     "output = sum of signs[k] * inputs[k]")
    register_builtin("gain", GAIN_OPTIONS, "flexff.blocks.sum_gain:gain_from_options",
                     "output = gain * input (gain tunable)")
