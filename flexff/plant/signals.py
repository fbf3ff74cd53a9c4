"""The manipulator's signals, declared once: name, SI unit, description.

The FMUs (plant, controller, feedforwards), run configurations, recordings, datasets, features,
plots and reports take their names and units from here, and code that needs some of a
System's signals picks them by name (`pick`), not by position. They live on the plant's floor,
the lowest that knows the manipulator, so that every package above can import them.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import TYPE_CHECKING

from flexff.fmu.system import Variable

if TYPE_CHECKING:  # CasADi loads where a System is built, not where signals are named
    import casadi as ca

Signals = tuple[Variable, ...]


def _xy(stem: str, unit: str, what: str) -> Signals:
    """The x and y signals `{stem}` with `x`/`y` put where the stem has `{}`."""
    return tuple(Variable(stem.format(axis), unit, f"{what}, {axis}") for axis in "xy")


def _motors(stem: str, unit: str, what: str, suffix: str = "") -> Signals:
    return tuple(Variable(f"{stem}{k}{suffix}", unit, f"{what}, motor {k}") for k in (1, 2, 3))


POSITION_REFERENCE = _xy("{}_ref", "m", "reference position")
VELOCITY_REFERENCE = _xy("v{}_ref", "m/s", "reference velocity")
ACCELERATION_REFERENCE = _xy("a{}_ref", "m/s2", "reference acceleration")
REFERENCE = (*POSITION_REFERENCE, *VELOCITY_REFERENCE, *ACCELERATION_REFERENCE)
CURRENTS = _motors("i", "A", "commanded current (saturated inside the plant)")
ENCODERS = _motors("theta_s", "rad", "encoder angle (quantized to the encoder resolution)")
TORQUES = _motors("tau", "N*m", "motor torque after current saturation")
TRUE_POSITION = _xy("{}", "m", "true end-effector position (evaluation only)")
TRUE_VELOCITY = _xy("v{}", "m/s", "true end-effector velocity (evaluation only)")
FEEDFORWARD_FORCES = _xy("F{}_ff", "N", "feedforward end-effector force")
CURRENT_FEEDFORWARD = _motors("i", "A", "feedforward current, added after the control "
                              "allocation", "_ff")
FEEDBACK_FORCES = _xy("F{}_fb", "N", "feedback end-effector force")
FORCES = _xy("F{}", "N", "end-effector force the motors exert, feedback plus feedforward")


def names(*groups: Sequence[Variable]) -> tuple[str, ...]:
    """The names of the signals of `groups`, in order."""
    return tuple(v.name for group in groups for v in group)


AXES = names(TRUE_POSITION)  # the manipulator's tracked axes, x and y (against x_ref, y_ref)


def units(*groups: Sequence[Variable]) -> tuple[str, ...]:
    """The units of the signals of `groups`, in order."""
    return tuple(v.unit for group in groups for v in group)


def pick(vector: ca.SX, layout: Sequence[Variable], wanted: Sequence[Variable]) -> ca.SX:
    """The elements of `vector`, whose elements carry the signals of `layout` in that order,
    that carry the signals `wanted` (by name), in the order of `wanted`."""
    import casadi as ca

    index = {v.name: k for k, v in enumerate(layout)}
    missing = [v.name for v in wanted if v.name not in index]
    if missing:
        raise ValueError(f"signals {missing} are not among {list(index)}")
    return ca.vertcat(*[vector[index[v.name]] for v in wanted])


def reference_motion(reference: ca.SX) -> tuple[ca.SX, ca.SX, ca.SX]:
    """(position, velocity, acceleration) of a vector of the REFERENCE signals."""
    position, velocity, acceleration = (
        pick(reference, REFERENCE, part)
        for part in (POSITION_REFERENCE, VELOCITY_REFERENCE, ACCELERATION_REFERENCE))
    return position, velocity, acceleration
