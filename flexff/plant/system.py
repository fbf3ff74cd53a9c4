"""The plant described for fmu/: named signals, tunable parameters and CasADi functions."""

from __future__ import annotations

from functools import cache

import casadi as ca

from flexff.fmu.system import Parameter, System, Variable
from flexff.plant.model import PlantModel
from flexff.plant.variants import Variant

_STATE_INFO = {
    "q_x": ("m", "end-effector x position"), "q_y": ("m", "end-effector y position"),
    "qd_x": ("m/s", "end-effector x velocity"), "qd_y": ("m/s", "end-effector y velocity"),
    "tool_dx": ("m", "tool deflection from the wrist, x"),
    "tool_dy": ("m", "tool deflection from the wrist, y"),
    "tool_vx": ("m/s", "tool deflection rate, x"), "tool_vy": ("m/s", "tool deflection rate, y"),
}


def _state(name: str) -> Variable:
    unit, description = _STATE_INFO[name]
    return Variable(name, unit, description)


def plant_system(variant: Variant | str = "nominal") -> System:
    """The plant of one variant as a continuous System with every physical parameter tunable.

    Parameters the variant's equations do not use (the tool of the nominal plant, the
    workspace radius) are left out; `x_start`, `y_start` set the initial rest position.
    """
    model = PlantModel(variant)
    x, i, w = ca.SX.sym("x", model.n_states), ca.SX.sym("i", 3), ca.SX.sym("w", 3)
    start = ca.SX.sym("start", 2)
    outputs = [model.forward_dynamics(x, i, model.p), model.output(x, i, model.p, w)]
    used = {sym.name() for sym in ca.symvar(ca.vertcat(*outputs))}
    symbols, rows = ca.vertsplit(model.p), model.variant.parameters.describe()
    kept = ca.vertcat(*[s for s in symbols if s.name() in used])
    full = ca.vertcat(*[s if s.name() in used else row[1] for s, row in zip(symbols, rows)])
    rows = [row for row in rows if row[0] in used]
    p = ca.vertcat(kept, start)
    parameters = tuple(Parameter(n, u, d, float(v), positive) for n, v, u, d, positive in rows)
    parameters += (Parameter("x_start", "m", "initial end-effector x position (at rest)",
                             fixed=True),
                   Parameter("y_start", "m", "initial end-effector y position (at rest)",
                             fixed=True))
    return System(
        name=f"plant_{model.variant.name}",
        description=f"flexure manipulator plant, {model.variant.name} variant: Lagrangian "
                    "dynamics in minimal coordinates, current saturation, encoders",
        kind="continuous",
        states=tuple(_state(n) for n in model.state_names),
        inputs=model.inputs,
        outputs=model.outputs,
        parameters=parameters,
        initial_state=ca.Function("initial_state", [p], [model.initial_state(start, full)]),
        dynamics=ca.Function("dynamics", [x, i, p], [model.forward_dynamics(x, i, full)]),
        output=ca.Function("output", [x, i, p, w], [model.output(x, i, full, w)]),
        n_noise=3,
        max_substep=1e-3,
    )


@cache
def plant_parameters(variant: str) -> tuple[Parameter, ...]:
    """The plant FMU's parameters of one variant (plant_system's, built once per process: the
    configuration checks ask for them per key)."""
    return plant_system(variant).parameters
