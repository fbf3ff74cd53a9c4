"""Any machine's feedforward features, defined once for training (learning.machine_features
evaluates them on filtered measured motion) and for the feedforward FMU (generated into C on
the reference): per axis position, velocity, acceleration, optionally jerk, directions of
motion tanh(v / w), w a fraction of the axis's velocity limit, and with `terms` whether it
moves at all, tanh(v / w)^2 (one-sided friction), and the description's own terms
(machine.prior.extra: cogging, gravity, coupling): what the user knows of the machine, given
to every network as the identified model is given it.
"""

from __future__ import annotations

import functools
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import casadi as ca

from flexff.cosim.machine import Machine
from flexff.fmu.expressions import Expression, to_casadi

DIRECTION_WIDTHS = (0.003, 0.01, 0.03)  # tanh widths, fractions of each velocity limit


@dataclass(frozen=True)
class FeatureInputs:
    """The choices that define the features beside the machine: jerk or not, the widths."""

    jerk: bool = False
    direction_widths: tuple[float, ...] = DIRECTION_WIDTHS
    terms: bool = True  # whether moving, and the description's extra terms

    @classmethod
    def from_settings(cls, settings: Mapping[str, Any]) -> FeatureInputs:
        """The choices as a run's machine_features settings hold them (runs from before the
        terms had none)."""
        return cls(settings["jerk"], tuple(settings["direction_widths"]),
                   settings.get("terms", False))


def feature_names(machine: Machine, config: FeatureInputs) -> list[str]:
    """The features' names, axis by axis."""
    names = []
    for axis in machine.axes:
        names += list(axis.motion) + ([f"j{axis.name}"] if config.jerk else [])
        names += [f"dir_{axis.name}_{w:g}" for w in config.direction_widths]
        if config.terms:
            names += [f"moving_{axis.name}_{w:g}" for w in config.direction_widths]
            names += [f"{term}_{axis.name}" for term in machine.prior.extra.get(axis.name, {})]
    return names


def feature_units(machine: Machine, config: FeatureInputs) -> list[str]:
    """The features' units, as feature_names orders them (directions are pure numbers, an
    extra term's unit is what its expression gives: "1" here)."""
    units = []
    for axis in machine.axes:
        units += [axis.unit, f"{axis.unit}/s", f"{axis.unit}/s2"]
        units += [f"{axis.unit}/s3"] if config.jerk else []
        units += ["1"] * len(config.direction_widths)
        if config.terms:
            units += ["1"] * (len(config.direction_widths)
                              + len(machine.prior.extra.get(axis.name, {})))
    return units


def feature_function(machine: Machine, config: FeatureInputs) -> ca.Function:
    """(reference signals, axis by axis: position, velocity, acceleration, jerk) -> features."""
    extra = tuple(tuple(machine.prior.extra.get(a.name, {}).items()) if config.terms else ()
                  for a in machine.axes)
    return _feature_function(tuple(a.limits.velocity for a in machine.axes),
                             tuple(a.motion for a in machine.axes), config.jerk,
                             config.direction_widths, config.terms, extra)


@functools.lru_cache(maxsize=16)  # one Function, so evaluate_samples' map is built once
def _feature_function(velocity_limits: tuple[float, ...], motions: tuple[tuple[str, ...], ...],
                      jerk: bool, widths: tuple[float, ...], terms: bool,
                      extra: tuple[tuple[tuple[str, Expression], ...], ...]) -> ca.Function:
    u = ca.SX.sym("u", 4 * len(velocity_limits))
    symbols = {name: u[4 * k + d] for k, names in enumerate(motions)
               for d, name in enumerate(names)}
    out = []
    for k, limit in enumerate(velocity_limits):
        position, velocity, acceleration, third = (u[4 * k + d] for d in range(4))
        out += [position, velocity, acceleration] + ([third] if jerk else [])
        directions = [ca.tanh(velocity / (w * limit)) for w in widths]
        out += directions
        if terms:
            out += [d**2 for d in directions]
            out += [to_casadi(expression, symbols, f"machine.prior.extra.{motions[k][0]}.{name}")
                    for name, expression in extra[k]]
    return ca.Function("machine_features", [u], [ca.vertcat(*out)], ["reference"], ["features"])


