"""Summing junction and gain as discrete Systems (no state, direct feedthrough), free of any
machine: the small blocks that wire a user's loop together.

  sum:  output = sum_k signs[k] * inputs[k]      (options: inputs, output, signs)
  gain: output = gain * input, `gain` tunable    (options: input, output, gain)

They run at the run's step (a discrete system's sample time must equal it); blocks.builtins
registers them as the built-ins "sum" and "gain".
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

import casadi as ca

from flexff.blocks import options as opt
from flexff.fmu.system import Parameter, System, Variable


def _feedthrough(name: str, description: str, inputs: tuple[Variable, ...],
                 outputs: tuple[Variable, ...], parameters: tuple[Parameter, ...],
                 expression: ca.SX, u: ca.SX, p: ca.SX, step: float) -> System:
    x, w = ca.SX.sym("x", 0), ca.SX.sym("w", 0)
    return System(
        name=name, description=description, kind="discrete", states=(), inputs=inputs,
        outputs=outputs, parameters=parameters,
        initial_state=ca.Function("initial_state", [p], [ca.SX(0, 1)]),
        dynamics=ca.Function("dynamics", [x, u, p], [ca.SX(0, 1)]),
        output=ca.Function("output", [x, u, p, w], [expression]),
        sample_time=step)


def sum_system(inputs: Sequence[str], output: str, step: float,
               signs: Sequence[float] | None = None, unit: str = "") -> System:
    """output = sum of signs[k] * inputs[k] (signs default to all +1)."""
    signs = [1.0] * len(inputs) if signs is None else [float(s) for s in signs]
    if len(signs) != len(inputs):
        raise opt.OptionError(f"option 'signs' has {len(signs)} entries for {len(inputs)} "
                              "inputs: give one per input")
    if output in inputs:
        raise opt.OptionError(f"option 'output' {output!r} is also an input: rename it")
    u, p = ca.SX.sym("u", len(inputs)), ca.SX.sym("p", 0)
    total = sum((s * u[k] for k, s in enumerate(signs)), ca.SX(0))
    terms = " ".join(f"{'+' if s >= 0 else '-'} {abs(s):g} {n}" for s, n in zip(signs, inputs))
    return _feedthrough(
        f"sum_{output}", f"{output} = {terms}",
        tuple(Variable(n, unit, f"summed input {k + 1}") for k, n in enumerate(inputs)),
        (Variable(output, unit, "the sum"),), (), total, u, p, step)


def gain_system(input: str, output: str, step: float, gain: float = 1.0, unit: str = ""
                ) -> System:
    """output = gain * input, with `gain` a tunable parameter."""
    if output == input:
        raise opt.OptionError(f"option 'output' {output!r} equals the input: rename it")
    u, p = ca.SX.sym("u", 1), ca.SX.sym("p", 1)
    return _feedthrough(
        f"gain_{output}", f"{output} = gain * {input}", (Variable(input, unit, "input"),),
        (Variable(output, unit, "gain * input"),),
        (Parameter("gain", "", "the gain", gain),), p[0] * u[0], u, p, step)


def sum_from_options(options: Mapping[str, Any], step: float) -> System:
    """The `sum` block from a configuration's options (blocks.options.SUM_OPTIONS)."""
    opt.check_keys(options, opt.SUM_OPTIONS, "sum")
    inputs = opt.names(options, "inputs")
    signs = options.get("signs")
    if signs is not None and (isinstance(signs, str) or not isinstance(signs, Sequence)):
        raise opt.OptionError(f"option 'signs' must be a list of numbers, got {signs!r}")
    checked = None if signs is None else [
        opt.number({"signs": s}, "signs") for s in signs]
    return sum_system(inputs, opt.name(options, "output"), step,
                      None if checked is None else [float(s or 0.0) for s in checked],
                      opt.unit(options, "unit", ""))


def gain_from_options(options: Mapping[str, Any], step: float) -> System:
    """The `gain` block from a configuration's options (blocks.options.GAIN_OPTIONS)."""
    opt.check_keys(options, opt.GAIN_OPTIONS, "gain")
    return gain_system(opt.name(options, "input"), opt.name(options, "output"), step,
                       opt.number(options, "gain", 1.0) or 0.0, opt.unit(options, "unit", ""))
