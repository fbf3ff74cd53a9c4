"""The manipulator's machine description (cosim.machine), as its short form gives it: the axes x
and y of the loop that controllers.short_form expands to, described as any user's machine is.

Each axis's measured position is the controller's kinematic map, the 2-encoder forward
kinematics of the plant's encoder outputs (plant.kinematics, as an expression); its true
position the plant's; its feedforward input the controller's F<axis>_ff and its effort the
force the controller commands, F<axis> (feedback plus feedforward: the learned models' labels).
The excitation limits are the square inside the workspace disc and the thesis's fastest
training circle (radius R_MAX, one turn a second); the physics prior the default terms and the
flexures' stiffness; ILC learns through the plant's own rigid-body model (controllers.ilc_model),
reseeding its noise each trial. `flexff config expand` writes it out.
"""

from __future__ import annotations

import math
from typing import Any

from flexff.cosim.machine import DEFAULT_PRIOR_TERMS
from flexff.plant.kinematics import forward_kinematics_2_text
from flexff.plant.parameters import NOMINAL
from flexff.plant.signals import ENCODERS, FEEDFORWARD_FORCES, FORCES, TRUE_POSITION, names

PLANT, CONTROLLER = "plant", "controller"  # the short form's instance names
CIRCLE_RADIUS = 0.045  # m: learning.trajectories.R_MAX, the largest training circle
CIRCLE_HZ = 1.0  # the fastest training circle's turns per second (learning.trajectories)
ILC_MODEL = "manipulator"  # the registered inverse model of ILC's learning filter
ILC_CUTOFF_HZ = 20.0  # Q's corner: half the hardware tool mode's frequency


def manipulator_description() -> dict[str, Any]:
    """The [machine] table of the manipulator's short form."""
    theta_s1, theta_s2 = (f"{PLANT}.{n}" for n in names(ENCODERS)[:2])
    measured = forward_kinematics_2_text(NOMINAL, theta_s1, theta_s2)
    half_side = NOMINAL.workspace_radius / math.sqrt(2.0)
    omega = 2.0 * math.pi * CIRCLE_HZ
    axes = [{"name": axis, "unit": "m", "measured": position,
             "true": f"{PLANT}.{true}", "feedforward": f"{CONTROLLER}.{feedforward}",
             "effort": f"{CONTROLLER}.{effort}", "effort_unit": "N",
             "range": [-half_side, half_side], "velocity": omega * CIRCLE_RADIUS,
             "acceleration": omega**2 * CIRCLE_RADIUS}
            for axis, position, true, feedforward, effort in zip(
                "xy", measured, names(TRUE_POSITION), names(FEEDFORWARD_FORCES), names(FORCES))]
    # the flexure joints pull the wrist back to the centre: a stiffness term per axis beside
    # the default terms (without it a linear model explains almost none of the commanded force)
    prior = {"terms": list(DEFAULT_PRIOR_TERMS), "extra": {axis: {"stiffness": axis}
                                                          for axis in "xy"}}
    # ILC's learning filter on the plant's own rigid-body model, its noise drawn anew each
    # trial; the noise floor against the plant measuring exactly
    ilc = {"model": ILC_MODEL, "cutoff_hz": ILC_CUTOFF_HZ, "seed": f"{PLANT}.seed"}
    exact = {f"{PLANT}.noise_std": 0.0, f"{PLANT}.encoder_quantization": 0.0}
    return {"name": "manipulator", "axis": axes, "prior": prior, "ilc": ilc, "exact": exact}
