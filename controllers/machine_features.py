"""Any machine's feedforward features, defined once for training (learning.machine_features
evaluates them on filtered measured motion) and for the feedforward FMU (generated into C on
the reference): per axis position, velocity, acceleration, optionally jerk, and directions of
motion tanh(v / w), w a fraction of the axis's velocity limit.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass

import casadi as ca

from flexff.cosim.machine import Machine

DIRECTION_WIDTHS = (0.003, 0.01, 0.03)  # tanh widths, fractions of each velocity limit


@dataclass(frozen=True)
class FeatureInputs:
    """The choices that define the features beside the machine: jerk or not, the widths."""

    jerk: bool = False
    direction_widths: tuple[float, ...] = DIRECTION_WIDTHS


def feature_names(machine: Machine, config: FeatureInputs) -> list[str]:
    """The features' names, axis by axis."""
    names = []
    for axis in machine.axes:
        names += list(axis.motion) + ([f"j{axis.name}"] if config.jerk else [])
        names += [f"dir_{axis.name}_{w:g}" for w in config.direction_widths]
    return names


def feature_units(machine: Machine, config: FeatureInputs) -> list[str]:
    """The features' units, as feature_names orders them (directions are pure numbers)."""
    units = []
    for axis in machine.axes:
        units += [axis.unit, f"{axis.unit}/s", f"{axis.unit}/s2"]
        units += [f"{axis.unit}/s3"] if config.jerk else []
        units += ["1"] * len(config.direction_widths)
    return units


def feature_function(machine: Machine, config: FeatureInputs) -> ca.Function:
    """(reference signals, axis by axis: position, velocity, acceleration, jerk) -> features."""
    return _feature_function(tuple(a.limits.velocity for a in machine.axes), config.jerk,
                             config.direction_widths)


@functools.lru_cache(maxsize=16)  # one Function, so evaluate_samples' map is built once
def _feature_function(velocity_limits: tuple[float, ...], jerk: bool,
                      widths: tuple[float, ...]) -> ca.Function:
    u = ca.SX.sym("u", 4 * len(velocity_limits))
    out = []
    for k, limit in enumerate(velocity_limits):
        position, velocity, acceleration, third = (u[4 * k + d] for d in range(4))
        out += [position, velocity, acceleration] + ([third] if jerk else [])
        out += [ca.tanh(velocity / (w * limit)) for w in widths]
    return ca.Function("machine_features", [u], [ca.vertcat(*out)], ["reference"], ["features"])


