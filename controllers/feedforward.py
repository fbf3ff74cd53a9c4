"""The classical rigid-body feedforward: eq. (2.4) on the nominal model, as a stateless System.

It is the baseline every learned feedforward is compared with: the force the nominal model
needs to follow the reference exactly, F = M a + C v + Q + D, with no knowledge of the
mismatch, friction or the parasitic mode of the real machine.
"""

from __future__ import annotations

import casadi as ca

from fmu.system import System, Variable
from plant.model import PlantModel

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


def rigid_body_feedforward_system(step: float = 1e-3) -> System:
    """Discrete, stateless System: reference (position, velocity, acceleration) -> F_ff."""
    if not step > 0:
        raise ValueError(f"step must be positive, got {step}")
    model = PlantModel("nominal")
    x, u, p, w = ca.SX.sym("x", 0), ca.SX.sym("u", 6), ca.SX.sym("p", 0), ca.SX.sym("w", 0)
    force = model.inverse_dynamics(u[0:2], u[2:4], u[4:6], model.parameter_values())
    return System(
        name="rigid_body_feedforward",
        description="rigid-body feedforward, eq. (2.4) on the nominal plant model",
        kind="discrete",
        states=(),
        inputs=REFERENCE_INPUTS,
        outputs=FORCE_OUTPUTS,
        parameters=(),
        initial_state=ca.Function("initial_state", [p], [ca.SX(0, 1)]),
        dynamics=ca.Function("dynamics", [x, u, p], [ca.SX(0, 1)]),
        output=ca.Function("output", [x, u, p, w], [force]),
        sample_time=step,
    )
