"""Any machine's feedforward as a System: the machine's reference signals in (each axis's
position, velocity, acceleration and jerk reference), `<axis>_ff` out. Either the effort an
inverse model of the axes' motion gives along the reference (`inverse_model_system`: the
identified linear model, or any CasADi function of that form), or the ports of a learned model
exported by flexff (`machine_model_ports`, which controllers.learned_feedforward builds the FMU
around): its features computed from the reference in generated C (learning.feature_spec), a
physics-guided model's prior added, at rest too (a residual switched off there stepped at each
start and stop).
"""

from __future__ import annotations

from pathlib import Path

import casadi as ca

from flexff.controllers.feedforward import feedforward_system
from flexff.controllers.model_ports import ModelPorts
from flexff.cosim.machine import Machine, parse_machine
from flexff.fmu.errors import InputError
from flexff.fmu.system import System, Variable
from flexff.learning.feature_spec import FeatureInputs, feature_function
from flexff.learning.linear_prior import linear_model_from_dict
from flexff.learning.model_card import ModelCard

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


def ahead(reference: ca.SX, lead_s: float) -> ca.SX:
    """The inputs' symbol (per axis position, velocity, acceleration, jerk) `lead_s` ahead, by
    its Taylor series at constant jerk: where the effort commanded now acts (a held effort
    acts over the step after its sample; learning.machine_features aligned the labels so)."""
    if not lead_s:
        return reference
    out = []
    for k in range(reference.size1() // 4):
        p, v, a, j = (reference[4 * k + d] for d in range(4))
        t = lead_s
        out += [p + v * t + a * t**2 / 2 + j * t**3 / 6, v + a * t + j * t**2 / 2, a + j * t, j]
    return ca.vertcat(*out)


def reference_motion(machine: Machine, reference: ca.SX) -> tuple[ca.SX, ca.SX, ca.SX]:
    """Positions, velocities and accelerations (one entry per axis) of the inputs' symbol."""
    n = len(machine.axes)
    return tuple(ca.vertcat(*(reference[4 * k + d] for k in range(n)))  # type: ignore[return-value]
                 for d in range(3))


def inverse_model_system(machine: Machine, inverse: ca.Function, step: float,
                         description: str, lead_s: float = 0.0) -> System:
    """The feedforward of `inverse` (positions, velocities, accelerations -> efforts, one
    entry per axis) along the reference `lead_s` ahead, at the run's `step`."""
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
                              inverse(*reference_motion(machine, ahead(reference, lead_s))), step,
                              outputs=feedforward_variables(machine),
                              inputs=reference_variables(machine))


def machine_model_ports(card: ModelCard, model: str | Path) -> ModelPorts:
    """The ports of a machine's exported model (controllers.learned_feedforward builds the
    FMU around them): the machine's reference signals in, its features of the reference the
    card's lead ahead as the network's inputs, a physics-guided model's linear prior there,
    each axis's `<axis>_ff` out."""
    if card.machine is None or card.machine_features is None:
        raise InputError(f"{model}: its card describes no machine (metadata machine, "
                         f"machine_features): export it again with flexff export")
    machine = parse_machine(card.machine, f"{model}: metadata machine")
    inputs = FeatureInputs.from_settings(card.machine_features)
    reference = ca.SX.sym("u", 4 * len(machine.axes))
    looked_ahead = ahead(reference, float(card.machine_features.get("lead_s") or 0.0))
    prior = None
    if card.prior == "linear":  # a physics-guided model: its residual plus the prior
        assert card.machine_prior is not None  # the card's check
        linear = linear_model_from_dict(card.machine_prior, f"{model}: metadata machine_prior")
        prior = linear.casadi_function()(*reference_motion(machine, looked_ahead))
    return ModelPorts(
        reference, reference_variables(machine),
        feature_function(machine, inputs)(looked_ahead), prior,
        feedforward_variables(machine), of=f" of {machine.name}",
        metadata={"flexff.model.model_kind": card.model_kind,
                  "flexff.model.sample_rate_hz": str(card.sample_rate_hz)},
        primed=True)
