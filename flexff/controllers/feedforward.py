"""The classical rigid-body feedforward: eq. (2.4) on the nominal model, as a stateless System.

It is the baseline every learned feedforward is compared with: the force the nominal model
needs to follow the reference exactly, F = M a + C v + Q + D, with no knowledge of the
mismatch, friction or the parasitic mode of the real machine.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

import casadi as ca

from flexff.controllers.features import nominal_model
from flexff.fmu.defaults import DEFAULT_STEP
from flexff.fmu.errors import InputError
from flexff.fmu.system import System, Variable
from flexff.plant.signals import FEEDFORWARD_FORCES, REFERENCE, reference_motion


def rigid_body_force(reference: ca.SX, parameters: Mapping[str, float] | None = None) -> ca.SX:
    """F = M a + C v + Q + D of the nominal model along the reference (x, y, vx, vy, ax, ay).

    `parameters` (flat plant parameter names, SI values) replace nominal values: a
    physics-guided model's identified motor friction adds its A^T tau_friction, its motors'
    identified torque constants scale each one's share (plant.model's `commanded`)."""
    model = nominal_model()
    return model.inverse_dynamics(*reference_motion(reference),
                                  model.parameter_values(**(parameters or {})))


def feedforward_system(name: str, description: str, reference: ca.SX, force: ca.SX,
                       step: float, result: ca.SX | None = None,
                       outputs: Sequence[Variable] = FEEDFORWARD_FORCES,
                       inputs: Sequence[Variable] = REFERENCE, **options: Any) -> System:
    """A discrete, stateless System from the reference signals to F_ff (or to other
    `outputs`: a current-level model's i1_ff..i3_ff; another machine's `inputs` and
    `outputs`): `force` is an expression of the symbol `reference` (the `inputs`) and, for a
    System with an embedded network (`options["network"]`), of the network's `result`."""
    x, p, w = ca.SX.sym("x", 0), ca.SX.sym("p", 0), ca.SX.sym("w", 0)
    arguments = [x, reference, p, w, *([] if result is None else [result])]
    return System(
        name=name,
        description=description,
        kind="discrete",
        states=(),
        inputs=tuple(inputs),
        outputs=tuple(outputs),
        parameters=(),
        initial_state=ca.Function("initial_state", [p], [ca.SX(0, 1)]),
        dynamics=ca.Function("dynamics", [x, reference, p], [ca.SX(0, 1)]),
        output=ca.Function("output", arguments, [force]),
        sample_time=step,
        **options,
    )


def rigid_body_feedforward_system(step: float = DEFAULT_STEP,
                                  parameters: Mapping[str, float] | None = None) -> System:
    """Discrete, stateless System: reference (position, velocity, acceleration) -> F_ff;
    `parameters` (flat plant parameter names: identified ones, controllers.identified)
    replace nominal values."""
    if not step > 0:
        raise InputError(f"step must be positive, got {step}")
    reference = ca.SX.sym("u", len(REFERENCE))
    which = "identified" if parameters else "nominal"
    return feedforward_system(
        "rigid_body_feedforward", f"rigid-body feedforward, eq. (2.4) on the {which} plant model",
        reference, rigid_body_force(reference, parameters), step)
