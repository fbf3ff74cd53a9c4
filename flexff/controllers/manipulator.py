"""The thesis's manipulator as one machine of cosim, registered like any user's (entry point
`manipulator` of `flexff.builtins`).

It registers the built-in FMUs plant, controller, rigid-body-feedforward and
learned-feedforward with their options, its short form (controllers.short_form) with its
machine description (controllers.manipulator_machine), the
reference kinds of the plane (plant.reference_kinds) and thesis-eval and thesis-hardware-eval
(plant.references), its signals' short names, the warning that a learned feedforward
extrapolates, and itself as the machine of exported models without a machine description
(learning.implicit_machine: their outputs, parameters and features). CasADi and onnx load
only where a plant, controller or model is checked or built.

Every option: "Run configuration", section Built-in FMUs (docs/reference/configuration.md,
generated from the registry).
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping
from typing import TYPE_CHECKING, Any

from flexff.controllers.plant_options import checked_plant_parameters, plant_parameter_names
from flexff.cosim.builtins import Option, OptionError, register_builtin
from flexff.cosim.inverse_models import register_inverse_model
from flexff.cosim.plugins import (
    register_metrics_warning,
    register_short_form,
    register_short_names,
)
from flexff.cosim.references import ReferenceKind, register_reference_kind
from flexff.fmu.network_runtime import RUNTIMES
from flexff.learning.implicit_machine import ImplicitMachine, register_implicit_machine
from flexff.plant.parameters import NOMINAL
from flexff.plant.signals import (
    CURRENT_FEEDFORWARD,
    CURRENTS,
    ENCODERS,
    FEEDBACK_FORCES,
    FEEDFORWARD_FORCES,
    FORCES,
    REFERENCE,
    TORQUES,
    TRUE_POSITION,
    TRUE_VELOCITY,
    names,
)
from flexff.plant.variants import VARIANTS

if TYPE_CHECKING:
    import casadi as ca
    import numpy as np

    from flexff.cosim.checks import TableChecker
    from flexff.cosim.schema import FmuConfig
    from flexff.fmu.system import System

FEEDFORWARD_MODES = ("step", "task", "precomputed")
# the manipulator's signals, kept under their short names in recordings (cosim.run)
SHORT_NAMES = names(REFERENCE, FEEDFORWARD_FORCES, CURRENTS, FEEDBACK_FORCES, FORCES, ENCODERS,
                    TRUE_POSITION, TRUE_VELOCITY, TORQUES)
# what a learned model outputs (learning.features' label levels): forces before the control
# allocation, or the motor currents after it (the controller's current feedforward)
MODEL_OUTPUTS = {"forces": FEEDFORWARD_FORCES, "currents": CURRENT_FEEDFORWARD}
# its part of a model card's usage text (learning.model_card.USAGE)
MODEL_USAGE = (": forces [N] or motor currents [A] (plus the nominal inverse dynamics, "
               "prior_parameters in place, when prior = rigid-body; for currents allocated at "
               "x_ref, y_ref as the controller allocates); with force_input, the last two inputs "
               "are that force with force_input's parameters (Fx_id, Fy_id)")


def register() -> None:
    """Register the manipulator's built-ins, short form, reference kinds, signals and
    metrics warning (cosim.builtins, cosim.references, cosim.plugins)."""
    from flexff.controllers.manipulator_machine import ILC_MODEL, manipulator_description
    from flexff.controllers.short_form import SHORT_FORM_TABLES, expand
    from flexff.plant.reference_kinds import plane_kinds
    from flexff.plant.references import thesis_evaluation, thesis_hardware_evaluation

    variant = Option("variant", "choice", "nominal", choices=tuple(VARIANTS))
    register_builtin("plant", (variant, Option("seed", "integer", check=_fmi_integer)),
                     _plant, "the flexure manipulator's plant", parameters=_plant_parameters,
                     start_options=("seed",))
    register_builtin("controller", (
        variant, Option("notch", "number-or-flag", positive=True),
        Option("encoders", "integer", 2, check=_encoders), Option("current_feedforward", "flag"),
        Option("crossover_hz", "number", positive=True)), controller_for,
        "the manipulator's feedback controller (controllers.feedback)")
    register_builtin("rigid-body-feedforward", (Option("identified", "file", check=_identified),),
                     _rigid_body, "the nominal (or identified) rigid-body feedforward")
    register_builtin("learned-feedforward", (
        Option("model", "file", required=True, suffix=".onnx", check=_model_card),
        Option("mode", "choice", "step", choices=FEEDFORWARD_MODES),
        Option("runtime", "choice", RUNTIMES[0], choices=RUNTIMES)), _learned,
        "an exported learned model, its network as generated C or in onnxruntime",
        reads_sources=True,
        metrics=feedforward_range)
    register_short_form("manipulator", SHORT_FORM_TABLES, expand, default=True,
                        describe=manipulator_description)
    register_reference_kind(ReferenceKind("thesis-eval", lambda _, step: thesis_evaluation(step)))
    register_reference_kind(ReferenceKind(
        "thesis-hardware-eval", lambda _, step: thesis_hardware_evaluation(step)))
    for kind in plane_kinds():
        register_reference_kind(kind)
    register_inverse_model(ILC_MODEL, "flexff.controllers.ilc_model:plant_inverse_model",
                           "the loop's plant's rigid-body inverse dynamics")
    register_short_names(SHORT_NAMES)
    register_metrics_warning(range_warning)
    register_implicit_machine(ImplicitMachine(
        MODEL_OUTPUTS, MODEL_USAGE, _model_parameters, REFERENCE, _feature_units,
        _reference_features))


# -- checks --------------------------------------------------------------------------------
def _fmi_integer(seed: int) -> None:
    if not -2**31 <= seed < 2**31:
        raise ValueError(f"{seed} does not fit a 32-bit FMI Integer")


def _encoders(encoders: int) -> None:
    from flexff.controllers.allocation import ENCODER_CHOICES  # CasADi

    if encoders not in ENCODER_CHOICES:
        raise ValueError(f"must be one of {ENCODER_CHOICES}, got {encoders}")


def _identified(path: Any) -> None:
    from flexff.controllers.identified import read_identified

    read_identified(path)


def _model_card(path: Any) -> None:
    from flexff.learning.model_card import read_card  # onnx: learned runs only

    read_card(path)


def _model_parameters(parameters: Mapping[str, float]) -> None:
    """A model card's prior_parameters or force_input: nominal plant parameters by name."""
    NOMINAL.with_values(**parameters)


# -- a learned model's features ------------------------------------------------------------
def _feature_units(feature_set: str, force_input: bool) -> list[str]:
    from flexff.controllers.features import feature_units  # CasADi

    return feature_units(feature_set, force_input)


def _reference_features(feature_set: str, force_input: Mapping[str, float] | None
                        ) -> ca.Function:
    from flexff.controllers.features import reference_feature_function  # CasADi

    return reference_feature_function(feature_set, force_input)


def _plant_parameters(checker: TableChecker, options: Mapping[str, Any],
                      parameters: Mapping[str, Any], where: str,
                      start: tuple[float, ...] | None) -> dict[str, Any]:
    known = plant_parameter_names(options["variant"])
    for key in parameters:
        if key not in known:
            raise checker.error(f"{where}.parameters.{key}", f"unknown plant parameter (known: "
                                                            f"{', '.join(known)})")
    return checked_plant_parameters(checker, parameters, options["variant"],
                                    f"{where}.parameters", start or (0.0, 0.0))


# -- factories -----------------------------------------------------------------------------
def _plant(options: Mapping[str, Any], step: float) -> System:
    from flexff.plant.system import plant_system

    return plant_system(options["variant"])


def controller_for(options: Mapping[str, Any], step: float) -> System:
    """The feedback controller of a built-in controller's options, sampled at `step`."""
    from flexff.controllers.feedback import DEFAULTS, controller_system, parasitic_mode_hz

    variant, crossover = options["variant"], options.get("crossover_hz")
    notch, encoders = options.get("notch"), options.get("encoders", 2)
    if notch is False and DEFAULTS[variant].notch:
        # the variant's defaults would add the notch: design without it at its crossover
        return controller_system("nominal", crossover or DEFAULTS[variant].crossover_hz, None,
                                 encoders, step, options.get("current_feedforward", False))
    notch_hz = parasitic_mode_hz() if notch is True else (notch or None)
    return controller_system(variant, crossover, notch_hz, encoders, step,
                             options.get("current_feedforward", False))


def _rigid_body(options: Mapping[str, Any], step: float) -> System:
    from flexff.controllers.feedforward import rigid_body_feedforward_system
    from flexff.controllers.identified import read_identified

    identified = read_identified(options["identified"]) if "identified" in options else None
    return rigid_body_feedforward_system(step, identified)


def _learned(options: Mapping[str, Any], step: float, sources: Mapping[str, Any]) -> System:
    from flexff.controllers.learned_feedforward import learned_feedforward_system

    reference = None
    if options["mode"] == "precomputed":
        reference = {n: sources[n] for n in names(REFERENCE) if n in sources}
        if len(reference) != len(REFERENCE):
            raise OptionError("mode", "the precomputed mode needs a [reference] to precompute "
                                      "the feedforward over")
    return learned_feedforward_system(options["model"], step, reference,
                                      options["mode"] == "task", options["runtime"])


# -- metrics -------------------------------------------------------------------------------
def feedforward_range(fmu: FmuConfig, reference: Mapping[str, np.ndarray], step: float
                      ) -> dict[str, Any]:
    """{"feedforward_range": where the reference leaves the learned model's training range}
    (controllers.training_range): {"margin", "outside": [features, farthest first]}, or None
    for a model exported without its range."""
    from flexff.controllers.training_range import MARGIN, training_range_excess  # onnx, SciPy

    excess = training_range_excess(fmu.options["model"], reference, step)
    if excess is None:
        return {"feedforward_range": None}
    return {"feedforward_range": {"margin": MARGIN,
                                  "outside": [dataclasses.asdict(e) for e in excess]}}


def range_warning(metrics: Mapping[str, Any]) -> str | None:
    """A line saying the learned feedforward extrapolates in this run (its metrics'
    `feedforward_range`), or None."""
    outside = (metrics.get("feedforward_range") or {}).get("outside")
    if not outside:
        return None
    worst = outside[0]
    return (f"warning: the reference leaves the learned model's training range in "
            f"{len(outside)} features (worst: {worst['signal']}, {worst['spans']:.2g} spans "
            f"beyond): the feedforward extrapolates; train on motion like this reference")
