"""The manipulator's closed loop for the tests: its three Systems, and the monolithic loop the
co-simulation is checked against.

The monolithic loop is plain CasADi on the Systems' own functions, no FMU: the feedforward's
output, the controller's output and update, the plant's output (encoders) and its dynamics
under the FMU wrapper's RK4 sub-steps, stepped in the master's order at every communication
point and accumulated over the run (mapaccum), so that the tests stay fast.
"""

import math
from collections.abc import Mapping

import casadi as ca
import numpy as np

from flexff.controllers.feedback import controller_system
from flexff.controllers.feedforward import rigid_body_feedforward_system
from flexff.fmu.system import System
from flexff.plant.signals import CURRENTS, FEEDBACK_FORCES, REFERENCE, TRUE_POSITION, names
from flexff.plant.system import plant_system
from tests.fmu_toys import rk4

STEP = 1e-3


def loop_systems(plant: str = "nominal", step: float = STEP) -> dict[str, System]:
    """The rigid-body feedforward, the nominal controller and the plant of variant `plant`."""
    return {"feedforward": rigid_body_feedforward_system(step),
            "controller": controller_system("nominal", step=step),
            "plant": plant_system(plant)}


def monolithic(systems: Mapping[str, System], reference: Mapping[str, np.ndarray],
               max_substep: float, use_feedforward: bool = True,
               plant_parameters: Mapping[str, float] | None = None,
               step: float = STEP) -> dict[str, np.ndarray]:
    """x, y, the currents and the feedback forces at every point of `reference` (its six
    signals sampled every `step` from t = 0), the plant's parameters at their start values
    but for `plant_parameters`."""
    ff, ctrl, plant = systems["feedforward"], systems["controller"], systems["plant"]
    given = dict(plant_parameters or {})
    p_plant = ca.DM([given.get(p.name, p.start) for p in plant.parameters])
    p_ctrl = ca.DM([p.start for p in ctrl.parameters])
    empty = ca.SX(0, 1)
    xp, xc = ca.SX.sym("xp", len(plant.states)), ca.SX.sym("xc", len(ctrl.states))
    ref = ca.SX.sym("ref", len(REFERENCE))
    force_ff = float(use_feedforward) * ff.output(empty, ref, empty, empty)
    encoders = plant.output(xp, ca.DM.zeros(len(CURRENTS)), p_plant, ca.DM.zeros(3))[:3]
    u = ca.vertcat(ref[:2], encoders, force_ff)  # the controller's inputs, in their order
    y = ctrl.output(xc, u, p_ctrl, empty)
    currents = y[:len(CURRENTS)]
    substeps = max(1, math.ceil(step / max_substep - 1e-12))
    x = rk4(lambda state: plant.dynamics(state, currents, p_plant), xp, step / substeps, substeps)
    state = ca.vertcat(xp, xc)
    advance = ca.Function("step", [state, ref], [ca.vertcat(x, ctrl.dynamics(xc, u, p_ctrl)),
                                                 ca.vertcat(xp[:2], y)])
    x0 = ca.vertcat(plant.initial_state(p_plant), ctrl.initial_state(p_ctrl))
    signals = np.vstack([np.asarray(reference[n], dtype=float) for n in names(REFERENCE)])
    _, out = advance.mapaccum(signals.shape[1])(x0, signals)
    return dict(zip(names(TRUE_POSITION, CURRENTS, FEEDBACK_FORCES), np.array(out)))
