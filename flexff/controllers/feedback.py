"""The feedback controller as a discrete System: encoders -> position error -> PID (+ notch) per
axis -> end-effector force (+ feedforward) -> control allocation -> motor currents (+ current
feedforward, with `current_feedforward`: a current-level learned model's i1_ff..i3_ff, added
after the allocation; without it the controller has no such inputs). It outputs the currents,
the feedback force and the force it commands (Fx, Fy: feedback plus feedforward, the
effort of the manipulator's machine description and the learned models' labels).

Outputs depend directly on the inputs: the master sets the inputs of step k, reads the currents
and then steps, which advances the PID states with the same error. The filter shapes are fixed
at build time (crossover, notch, step); the proportional gains kp_x, kp_y are tunable
parameters that scale each axis's output (the state update does not depend on them), so a
loop-gain study needs no rebuild.
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass, replace

import casadi as ca
import numpy as np

from flexff.blocks.loop_shaping import PIDDesign, StateSpace, design_pid
from flexff.controllers.allocation import measured_position, motor_currents
from flexff.controllers.axis_plant import axis_plant
from flexff.fmu.defaults import DEFAULT_STEP
from flexff.fmu.errors import InputError
from flexff.fmu.system import Parameter, System, Variable
from flexff.plant.analysis import plant_info
from flexff.plant.kinematics import shoulder_angles
from flexff.plant.parameters import NOMINAL
from flexff.plant.signals import (
    CURRENT_FEEDFORWARD,
    CURRENTS,
    ENCODERS,
    FEEDBACK_FORCES,
    FEEDFORWARD_FORCES,
    FORCES,
    POSITION_REFERENCE,
    pick,
)

AXES = ("x", "y")


@dataclass(frozen=True)
class ControllerDefaults:
    """Crossover [Hz] and whether a notch sits on the parasitic mode, per plant variant."""

    crossover_hz: float
    notch: bool


# the thesis: 2.66 Hz on the simulation model, 2 Hz with a notch on the hardware (sec. 4.1-4.2)
DEFAULTS = {
    "nominal": ControllerDefaults(crossover_hz=2.66, notch=False),
    "hardware": ControllerDefaults(crossover_hz=2.0, notch=True),
}

# encoder inputs start at the angles of the centre pose, where the controller is at rest
HOME_ANGLES = tuple(float(a) for a in shoulder_angles(NOMINAL, 0.0, 0.0))
ENCODER_INPUTS = tuple(replace(v, start=a) for v, a in zip(ENCODERS, HOME_ANGLES))
INPUTS = (*POSITION_REFERENCE, *ENCODER_INPUTS, *FEEDFORWARD_FORCES)
OUTPUTS = (*CURRENTS, *FEEDBACK_FORCES, *FORCES)  # FORCES: the effort, the labels


def parasitic_mode_hz() -> float:
    """Frequency [Hz] of the hardware plant's parasitic (tool mount) mode at the centre.

    It stands for the resonance one would read off a measured frequency response.
    """
    return float(plant_info("hardware")["natural_frequencies_hz"][2])


def controller_design(variant: str = "nominal", crossover_hz: float | None = None,
                      notch_hz: float | None = None, step: float = DEFAULT_STEP) -> PIDDesign:
    """The per-axis PID design of a variant; None picks the variant's crossover and notch."""
    try:
        defaults = DEFAULTS[variant]
    except KeyError:
        raise InputError(f"unknown controller variant {variant!r}: choose one of "
                         f"{', '.join(DEFAULTS)}") from None
    if notch_hz is None and defaults.notch:
        notch_hz = parasitic_mode_hz()
    if crossover_hz is None:
        crossover_hz = defaults.crossover_hz
    return design_pid(crossover_hz, step, notch_hz, plant=axis_plant())


def controller_system(variant: str = "nominal", crossover_hz: float | None = None,
                      notch_hz: float | None = None, encoders: int = 2,
                      step: float = DEFAULT_STEP, current_feedforward: bool = False) -> System:
    """Discrete feedback controller (sample time `step`) with the signals of plant.signals;
    `current_feedforward` adds the inputs i1_ff..i3_ff [A] to the allocated currents."""
    design = controller_design(variant, crossover_hz, notch_hz, step)
    ss = design.discrete
    n = ss.A.shape[0]
    inputs = (*INPUTS, *CURRENT_FEEDFORWARD) if current_feedforward else INPUTS
    x, u = ca.SX.sym("x", 2 * n), ca.SX.sym("u", len(inputs))
    p, w = ca.SX.sym("p", len(AXES)), ca.SX.sym("w", 0)
    theta, force_ff = pick(u, inputs, ENCODERS), pick(u, inputs, FEEDFORWARD_FORCES)
    pos = measured_position(theta, encoders)
    error = pick(u, inputs, POSITION_REFERENCE) - pos
    states = [x[k * n:(k + 1) * n] for k in range(len(AXES))]
    force_fb = ca.vertcat(*[p[k] / design.kp * _output(ss, states[k], error[k])
                            for k in range(len(AXES))])
    force = force_fb + force_ff
    currents = motor_currents(force, pos)
    if current_feedforward:
        currents = currents + pick(u, inputs, CURRENT_FEEDFORWARD)
    x_next = ca.vertcat(*[_update(ss, states[k], error[k]) for k in range(len(AXES))])
    # strict JSON for the modelDescription annotation: a margin without a limit becomes null
    numbers = {k: v if math.isfinite(v) else None for k, v in design.summary().items()}
    design_numbers = {"variant": variant, "encoders": encoders, "step": step,
                      **({"current_feedforward": True} if current_feedforward else {}), **numbers}
    return System(
        name=f"controller_{variant}",
        description=f"PID{' + notch' if design.notch_hz else ''} per axis with control "
                    f"allocation ({encoders}-encoder forward kinematics)"
                    f"{' and current feedforward' if current_feedforward else ''}, designed "
                    f"for a {design.crossover_hz:g} Hz crossover",
        kind="discrete",
        states=tuple(Variable(f"c{axis}{k + 1}", "", f"controller state {k + 1}, {axis} axis "
                              f"(PID first, then notch)") for axis in AXES for k in range(n)),
        inputs=inputs,
        outputs=OUTPUTS,
        parameters=tuple(Parameter(f"kp_{axis}", "N/m", f"proportional gain, {axis} axis",
                                   start=design.kp, positive=True) for axis in AXES),
        initial_state=ca.Function("initial_state", [p], [ca.SX.zeros(2 * n, 1)]),
        dynamics=ca.Function("dynamics", [x, u, p], [x_next]),
        output=ca.Function("output", [x, u, p, w], [ca.vertcat(currents, force_fb, force)]),
        sample_time=step,
        extra={"design": json.dumps(design_numbers)},
    )


def _output(ss: StateSpace, x: ca.SX, e: ca.SX) -> ca.SX:
    return ca.DM(ss.C) @ x + float(ss.D[0, 0]) * e


def _update(ss: StateSpace, x: ca.SX, e: ca.SX) -> ca.SX:
    return ca.DM(ss.A) @ x + ca.DM(np.ravel(ss.B)) * e
