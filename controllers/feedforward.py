"""The classical rigid-body feedforward: eq. (2.4) on the nominal model, as a stateless System.

It is the baseline every learned feedforward is compared with: the force the nominal model
needs to follow the reference exactly, F = M a + C v + Q + D, with no knowledge of the
mismatch, friction or the parasitic mode of the real machine.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import casadi as ca

from controllers.features import nominal_model
from fmu.system import System, Variable

REFERENCE_INPUTS = (
    Variable("x_ref", "m", "reference position, x"),
    Variable("y_ref", "m", "reference position, y"),
    Variable("vx_ref", "m/s", "reference velocity, x"),
    Variable("vy_ref", "m/s", "reference velocity, y"),
    Variable("ax_ref", "m/s2", "reference acceleration, x"),
    Variable("ay_ref", "m/s2", "reference acceleration, y"),
)
FORCE_OUTPUTS = (
    Variable("Fx_ff", "N", "feedforward end-effector force, x"),
    Variable("Fy_ff", "N", "feedforward end-effector force, y"),
)


def rigid_body_force(reference: ca.SX, parameters: Mapping[str, float] | None = None) -> ca.SX:
    """F = M a + C v + Q + D of the nominal model along the reference (x, y, vx, vy, ax, ay).

    `parameters` (flat plant parameter names, SI values) replace nominal values: a
    physics-guided model's identified motor friction adds its A^T tau_friction."""
    model = nominal_model()
    return model.inverse_dynamics(reference[0:2], reference[2:4], reference[4:6],
                                  model.parameter_values(**(parameters or {})))


def feedforward_system(name: str, description: str, reference: ca.SX, force: ca.SX,
                       step: float, result: ca.SX | None = None, **options: Any) -> System:
    """A discrete, stateless System from the reference signals to F_ff: `force` is an
    expression of the symbol `reference` (the six REFERENCE_INPUTS) and, for a System with an
    embedded network (`options["network"]`), of the network's `result`."""
    x, p, w = ca.SX.sym("x", 0), ca.SX.sym("p", 0), ca.SX.sym("w", 0)
    arguments = [x, reference, p, w, *([] if result is None else [result])]
    return System(
        name=name,
        description=description,
        kind="discrete",
        states=(),
        inputs=REFERENCE_INPUTS,
        outputs=FORCE_OUTPUTS,
        parameters=(),
        initial_state=ca.Function("initial_state", [p], [ca.SX(0, 1)]),
        dynamics=ca.Function("dynamics", [x, reference, p], [ca.SX(0, 1)]),
        output=ca.Function("output", arguments, [force]),
        sample_time=step,
        **options,
    )


def rigid_body_feedforward_system(step: float = 1e-3) -> System:
    """Discrete, stateless System: reference (position, velocity, acceleration) -> F_ff."""
    if not step > 0:
        raise ValueError(f"step must be positive, got {step}")
    reference = ca.SX.sym("u", len(REFERENCE_INPUTS))
    return feedforward_system(
        "rigid_body_feedforward", "rigid-body feedforward, eq. (2.4) on the nominal plant model",
        reference, rigid_body_force(reference), step)
