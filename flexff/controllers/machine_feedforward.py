"""Any machine's feedforward as a System: the machine's reference signals in (each axis's
position, velocity, acceleration and jerk reference), `<axis>_ff` out. Either the effort an
inverse model of the axes' motion gives along the reference (`inverse_model_system`: the
identified linear model, or any CasADi function of that form), or a learned model exported by
flexff (`learned_machine_feedforward_system`): its features computed from the reference in
generated C (learning.feature_spec), its ONNX graph run as the manipulator's learned
feedforward runs it (controllers.learned_feedforward: step or task mode, extrapolated between
the model's calls); a physics-guided model's residual plus its prior, at rest too (a
residual switched off there stepped at each start and stop).
"""

from __future__ import annotations

from pathlib import Path

import casadi as ca

from flexff.controllers.feedforward import feedforward_system
from flexff.controllers.learned_feedforward import linear_skip, model_period
from flexff.controllers.model_card import read_card
from flexff.cosim.machine import Machine, parse_machine
from flexff.fmu.defaults import DEFAULT_STEP
from flexff.fmu.errors import InputError
from flexff.fmu.network_runtime import RUNTIMES, runtime_label
from flexff.fmu.onnx_graph import graph_network, read_graph
from flexff.fmu.system import System, Variable
from flexff.learning.feature_spec import FeatureInputs, feature_function
from flexff.learning.linear_prior import linear_model_from_dict

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


def learned_machine_feedforward_system(model: str | Path, step: float = DEFAULT_STEP,
                                       task: bool = False, runtime: str = RUNTIMES[0]
                                       ) -> System:
    """The System of the feedforward FMU running `model`, a machine's exported model; with
    `task` its network runs in its own task; `runtime` computes the graph ("c" or
    "onnxruntime")."""
    card = read_card(model)
    if card.machine is None or card.machine_features is None:
        raise InputError(f"{model} is a model of the manipulator: build it with `flexff fmu "
                         f"build learned-feedforward`")
    machine = parse_machine(card.machine, f"{model}: metadata machine")
    inputs = FeatureInputs.from_settings(card.machine_features)
    reference = ca.SX.sym("u", 4 * len(machine.axes))
    looked_ahead = ahead(reference, float(card.machine_features.get("lead_s") or 0.0))
    x, p = ca.SX.sym("x", 0), ca.SX.sym("p", 0)
    features = feature_function(machine, inputs)(looked_ahead)
    network = graph_network(read_graph(model, time_axis=True),
                            ca.Function("network_input", [x, reference, p], [features]),
                            model_period(card, step, model), None, task, runtime,
                            primed=True)
    if network.n_outputs != len(machine.axes):
        raise InputError(f"{model}: the graph returns {network.n_outputs} values per step, the "
                         f"machine {machine.name!r} has {len(machine.axes)} axes")
    result = ca.SX.sym("r", network.n_outputs)
    effort = result + linear_skip(card, features)
    if card.prior == "linear":  # a physics-guided model: its residual plus the prior
        assert card.machine_prior is not None  # the card's check
        prior = linear_model_from_dict(card.machine_prior, f"{model}: metadata machine_prior")
        effort = effort + prior.casadi_function()(*reference_motion(machine, looked_ahead))
    mode = "task" if task else "step"
    return feedforward_system(
        "learned_feedforward",
        f"learned feedforward of {machine.name}: {card.model_kind} model at "
        f"{card.sample_rate_hz:g} Hz in {runtime_label(runtime)}, {mode} mode",
        reference, effort, step, result, outputs=feedforward_variables(machine),
        inputs=reference_variables(machine),
        extra={"flexff.feedforward.mode": mode, "flexff.feedforward.prior": card.prior,
               "flexff.network.runtime": runtime, "flexff.model.model_kind": card.model_kind,
               "flexff.model.sample_rate_hz": str(card.sample_rate_hz)},
        network=network)
