"""The manipulator's model for the learning filter of iterative learning control: the rigid-body
inverse dynamics, with motor friction, of the loop's own plant, registered by the manipulator
(controllers.manipulator) as the inverse model "manipulator" that its description names
(`[machine.ilc] model`, controllers.manipulator_machine)."""

from __future__ import annotations

from typing import Any

import casadi as ca

from flexff.controllers.features import nominal_model
from flexff.cosim.schema import RunConfig
from flexff.plant.parameters import NOMINAL, PlantParameters
from flexff.plant.variants import VARIANTS


def plant_inverse_model(loop: RunConfig, recording: Any = None) -> ca.Function:
    """(pos, vel, acc) -> F [N] of the loop's plant (loop_plant_model); trial 0's recording
    is not needed: the model is the plant's own."""
    return model_inverse_dynamics(loop_plant_model(loop))


def loop_plant_parameters(loop: RunConfig) -> PlantParameters:
    """The true parameters of the loop's built-in plant: its variant's with the loop's values
    (the nominal ones for a plant FMU by path)."""
    plant = loop.builtin("plant")
    if plant is None:
        return NOMINAL
    known = set(PlantParameters.names())
    return VARIANTS[plant.options["variant"]].parameters.with_values(
        **{k: float(v) for k, v in plant.parameters.items() if k in known})


def loop_plant_model(loop: RunConfig) -> PlantParameters:
    """The parameters of the loop's plant model (loop_plant_parameters), its tool (where it has
    one) counted at the wrist, for below its mount's mode it moves with the wrist."""
    parameters = loop_plant_parameters(loop)
    plant = loop.builtin("plant")
    if plant is None or not VARIANTS[plant.options["variant"]].parasitic_mode:
        return parameters
    return parameters.with_values(m_ee=parameters.m_ee + parameters.m_tool)


def model_inverse_dynamics(parameters: PlantParameters) -> ca.Function:
    """(pos, vel, acc) -> F [N]: the rigid-body inverse dynamics, with motor friction, of a
    plant with `parameters`."""
    function = nominal_model().inverse_dynamics
    pos, vel, acc = ca.SX.sym("pos", 2), ca.SX.sym("vel", 2), ca.SX.sym("acc", 2)
    return ca.Function("model_inverse_dynamics", [pos, vel, acc],
                       [function(pos, vel, acc, ca.DM(parameters.vector()))])
