"""The learned feedforward as a System, for any exported model: reference in, the ONNX model
inside, its effort out (the manipulator's F_ff or a current-level model's i1_ff..i3_ff, a
machine's `<axis>_ff`).

The FMU computes the model's inputs from the reference in generated C (the ports its card asks
for, controllers.model_ports), runs the graph at the model's own rate (as generated C or with
onnxruntime) and extrapolates in between; the linear skip (the card's linear_inputs) and a
physics-guided model's prior are added in generated C at every step. Modes: `step`,
`precomputed` (the manipulator's) and `task`. The network part is that of any ONNX graph as an
FMU (fmu.onnx_graph); the manipulator's features and prior are this module's.

Docs: "The learned feedforward FMU" (docs/explanation/learned-feedforward-fmu.md).
"""

from __future__ import annotations

import json
from collections.abc import Mapping
from pathlib import Path

import casadi as ca
import numpy as np

from flexff.controllers.allocation import motor_currents
from flexff.controllers.features import feature_names, reference_feature_function
from flexff.controllers.feedforward import feedforward_system, rigid_body_force
from flexff.controllers.machine_feedforward import machine_model_ports
from flexff.controllers.manipulator import MODEL_OUTPUTS
from flexff.controllers.model_ports import ModelPorts
from flexff.fmu.defaults import DEFAULT_STEP
from flexff.fmu.errors import InputError
from flexff.fmu.network_runtime import RUNTIMES, runtime_label
from flexff.fmu.onnx_graph import graph_network, read_graph
from flexff.fmu.system import System
from flexff.learning.model_card import ModelCard, read_card
from flexff.plant.signals import REFERENCE, names, reference_motion

REFERENCE_NAMES = list(names(REFERENCE))


def learned_feedforward_system(model: str | Path, step: float = DEFAULT_STEP,
                               reference: Mapping[str, np.ndarray] | None = None,
                               task: bool = False, runtime: str = RUNTIMES[0]) -> System:
    """The System of the feedforward FMU running any exported `model` (flexff export): the
    ports its card asks for (a machine's, controllers.machine_feedforward, or the
    manipulator's), its network at the model's rate, its linear skip and its prior added at
    every step. With `reference` (x_ref ... ay_ref at every step from t = 0) a manipulator's
    model is built in the precomputed mode for that reference; with `task` its network runs
    in its own task; `runtime` computes the graph ("c": generated C, or "onnxruntime")."""
    card = read_card(model)
    ports = machine_model_ports(card, model) if card.machine is not None else \
        _manipulator_ports(card, model)
    if reference is not None and not ports.precomputed:
        raise InputError(f"{model}: the precomputed mode takes the manipulator's reference; "
                         f"run this model in the step or the task mode")
    x, p = ca.SX.sym("x", 0), ca.SX.sym("p", 0)
    network = graph_network(read_graph(model, time_axis=True),
                            ca.Function("network_input", [x, ports.reference, p],
                                        [ports.features]),
                            model_period(card, step, model),
                            None if reference is None else _table(reference, step), task,
                            runtime, primed=ports.primed)
    if network.n_outputs != len(ports.outputs):
        raise InputError(f"{model}: the graph returns {network.n_outputs} values per step, the "
                         f"feedforward needs {len(ports.outputs)} "
                         f"({', '.join(v.name for v in ports.outputs)})")
    result = ca.SX.sym("r", network.n_outputs)
    effort = result + linear_skip(card, ports.features)
    if ports.prior is not None:
        effort = effort + ports.prior
    mode = "precomputed" if reference is not None else "task" if task else "step"
    return feedforward_system(
        "learned_feedforward",
        (f"learned feedforward{ports.of}: {card.model_kind} model at {card.sample_rate_hz:g} Hz "
         f"in {runtime_label(runtime)}{ports.added}, {mode} mode"),
        ports.reference, effort, step, result, ports.outputs, ports.inputs,
        extra={"flexff.feedforward.mode": mode, "flexff.feedforward.prior": card.prior,
               "flexff.network.runtime": runtime, **ports.metadata},
        network=network)


def _manipulator_ports(card: ModelCard, model: str | Path) -> ModelPorts:
    """The ports of a manipulator's model: the reference x_ref ... ay_ref in, the network's
    inputs the reference itself or its features, the rigid-body prior of a physics-guided
    model, the forces (or a current-level model's currents) out."""
    u = ca.SX.sym("u", len(REFERENCE_NAMES))
    if card.input_kind == "reference":
        expected, inputs = REFERENCE_NAMES, u
    else:
        expected = feature_names(card.feature_set, card.force_input is not None)
        inputs = reference_feature_function(card.feature_set, card.force_input)(u)
    if card.input_signals != expected:
        raise InputError(f"{model}: its input signals {card.input_signals} are not the "
                         f"{card.input_kind} signals {expected} the FMU computes")
    with_prior = card.prior == "rigid-body"
    added = (", the identified rigid-body force among its inputs"
             if card.force_input is not None else "")
    if with_prior:
        added = " plus the rigid-body feedforward" + (
            f" with identified {', '.join(card.prior_parameters)}"
            if card.prior_parameters else "")
    return ModelPorts(
        u, tuple(REFERENCE), inputs, _prior(u, card) if with_prior else None,
        tuple(MODEL_OUTPUTS[card.labels]), added=added,
        metadata={"flexff.feedforward.prior_parameters": json.dumps(card.prior_parameters),
                  "flexff.feedforward.force_input": json.dumps(card.force_input),
                  **{f"flexff.model.{k}": str(getattr(card, k))
                     for k in ("model_kind", "preset", "feature_set", "input_kind",
                               "sample_rate_hz", "labels")}},
        precomputed=True)


def _prior(reference: ca.SX, card: ModelCard) -> ca.SX:
    """The rigid-body prior of a physics-guided model along the reference; for a current-level
    one as the motor currents the controller would allocate for it at the reference position."""
    force = rigid_body_force(reference, card.prior_parameters)
    if card.labels == "forces":
        return force
    return motor_currents(force, reference_motion(reference)[0])


def linear_skip(card: ModelCard, inputs: ca.SX) -> ca.SX:
    """The network's linear skip beside the graph (the card's linear_inputs) on the model's
    `inputs`, added at every step of the loop; 0 for a model without one."""
    if card.linear_inputs is None:
        return ca.SX(0)
    return ca.mtimes(ca.DM(card.linear_inputs["weights"]), inputs) \
        + ca.DM(card.linear_inputs["bias"])


def model_period(card: ModelCard, step: float, model: str | Path) -> int:
    """Communication steps per model call: the step must divide the model's sample period."""
    rate = card.sample_rate_hz
    if not (step > 0 and rate * step > 0):  # a product that underflows to 0 too
        raise InputError(f"step ({step}) and the model's sample rate ({rate}) must be positive")
    ratio = 1.0 / (rate * step)
    if ratio < 1 - 1e-9 or abs(ratio - round(ratio)) > 1e-6:
        raise InputError(f"{model}: the model runs at {rate:g} Hz; the step {step:g} s must "
                         f"divide its period {1 / rate:g} s by a whole number")
    return round(ratio)


def _table(reference: Mapping[str, np.ndarray], step: float) -> np.ndarray:
    missing = [n for n in REFERENCE_NAMES if n not in reference]
    if missing:
        raise ValueError(f"the precomputed reference lacks {', '.join(missing)}")
    columns = [np.asarray(reference[n], dtype=float).ravel() for n in REFERENCE_NAMES]
    n = columns[0].size
    if any(c.size != n for c in columns) or n < 1:
        raise ValueError("the reference signals must have one and the same length")
    return np.column_stack([np.arange(n) * step, *columns])
