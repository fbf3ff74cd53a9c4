"""Any machine's model-based feedforward as a stateless System: the machine's reference
signals in (each axis's position, velocity, acceleration and jerk reference), `<axis>_ff` out,
the effort an inverse model of the axes' motion gives along the reference (the identified
linear model of learning's identification, or any CasADi function of the same form).
"""

from __future__ import annotations

import casadi as ca

from flexff.controllers.feedforward import feedforward_system
from flexff.cosim.machine import Machine
from flexff.fmu.errors import InputError
from flexff.fmu.system import System, Variable

DERIVATIVES = ("position", "velocity", "acceleration", "jerk")


def reference_variables(machine: Machine) -> tuple[Variable, ...]:
    """The FMU inputs: every axis's reference and its derivatives, with units."""
    variables = []
    for axis in machine.axes:
        for k, (name, what) in enumerate(zip((axis.reference, *axis.derivatives),
                                             DERIVATIVES)):
            unit = axis.unit if k == 0 else f"{axis.unit}/s" if k == 1 else f"{axis.unit}/s{k}"
            variables.append(Variable(name, unit, f"reference {what} of axis {axis.name}"))
    return tuple(variables)


def feedforward_variables(machine: Machine) -> tuple[Variable, ...]:
    """The FMU outputs: each axis's feedforward effort `<axis>_ff`."""
    return tuple(Variable(f"{a.name}_ff", a.effort_unit, f"feedforward effort of axis {a.name}")
                 for a in machine.axes)


def reference_motion(machine: Machine, reference: ca.SX) -> tuple[ca.SX, ca.SX, ca.SX]:
    """Positions, velocities and accelerations (one entry per axis) of the inputs' symbol."""
    n = len(machine.axes)
    return tuple(ca.vertcat(*(reference[4 * k + d] for k in range(n)))  # type: ignore[return-value]
                 for d in range(3))


def inverse_model_system(machine: Machine, inverse: ca.Function, step: float,
                         description: str) -> System:
    """The feedforward of `inverse` (positions, velocities, accelerations -> efforts, one
    entry per axis) along the reference, at the run's `step`."""
    n = len(machine.axes)
    if not step > 0:
        raise InputError(f"step must be positive, got {step}")
    if inverse.n_in() != 3 or any(inverse.size1_in(i) != n for i in range(3)) \
            or inverse.size1_out(0) != n:
        raise InputError(f"the inverse model takes {inverse.n_in()} inputs of "
                         f"{[inverse.size1_in(i) for i in range(inverse.n_in())]} values and "
                         f"gives {inverse.size1_out(0)}: the machine {machine.name!r} needs "
                         f"positions, velocities, accelerations of its {n} axes in, {n} efforts "
                         f"out")
    reference = ca.SX.sym("u", 4 * n)
    return feedforward_system("machine_feedforward", description, reference,
                              inverse(*reference_motion(machine, reference)), step,
                              outputs=feedforward_variables(machine),
                              inputs=reference_variables(machine))
