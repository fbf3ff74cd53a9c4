"""An identified linear inverse model of any machine as data: per axis its terms and
parameters, evaluated on NumPy (`predict`) and as a CasADi Function (`casadi_function`) from
one definition of the regressor's columns, so that the feedforward FMU and the physics-guided
model's prior compute what the identification fitted (learning.linear_model fits it).

Each axis's columns are the prior's terms (cosim.machine.PRIOR_TERMS: inertia a, viscous v,
Coulomb tanh(v / w) or its two one-sided levels, offset 1) and its extra terms (expressions of
every axis's motion: cogging, gravity, coupling).
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import casadi as ca
import numpy as np

from flexff.cosim.machine import Machine, machine_table, parse_machine
from flexff.fmu.errors import InputError
from flexff.fmu.expressions import evaluate, to_casadi

FORMAT = "flexff-linear-model"

Motion = Mapping[str, np.ndarray]  # motion name (x, vx, ax of every axis) -> samples


def motion_of(machine: Machine, positions: Mapping[str, np.ndarray],
              velocities: Mapping[str, np.ndarray], accelerations: Mapping[str, np.ndarray]
              ) -> dict[str, np.ndarray]:
    """The motion names of every axis (x, vx, ax) -> samples, from per-axis arrays."""
    motion = {}
    for axis in machine.axes:
        for name, values in zip(axis.motion, (positions, velocities, accelerations)):
            motion[name] = np.asarray(values[axis.name], dtype=float)
    return motion


def term_names(machine: Machine, axis_index: int) -> list[str]:
    """The names of one axis's columns, in order."""
    axis = machine.axes[axis_index]
    names = []
    for term in machine.prior.terms:
        names += ["coulomb_positive", "coulomb_negative"] if term == "coulomb_asymmetric" \
            else [term]
    return names + list(machine.prior.extra.get(axis.name, {}))


def columns(machine: Machine, k: int, motion: Mapping[str, Any], width: float, backend: Any
             ) -> list[Any]:
    """One axis's regressor columns on NumPy arrays (backend np) or CasADi symbols (ca)."""
    axis = machine.axes[k]
    v, a = motion[axis.motion[1]], motion[axis.motion[2]]
    tanh = backend.tanh(v / width)
    one = v * 0 + 1
    by_term = {"inertia": [a], "viscous": [v], "coulomb": [tanh], "offset": [one],
               # one-sided levels, zero at rest: -> 1 moving forward, -> -1 moving back
               "coulomb_asymmetric": [0.5 * (tanh + tanh**2), 0.5 * (tanh - tanh**2)]}
    columns = [c for term in machine.prior.terms for c in by_term[term]]
    for term, expression in machine.prior.extra.get(axis.name, {}).items():
        key = f"machine.prior.extra.{axis.name}.{term}"
        value = evaluate(expression, motion, key) if backend is np else \
            to_casadi(expression, motion, key)
        columns.append(value * one)
    return columns


@dataclass(frozen=True)
class AxisFit:
    """One axis's identified parameters and how well the data determine them."""

    terms: list[str]
    parameters: list[float]
    std: list[float]
    width: float  # Coulomb tanh width [axis unit / s]
    condition: float  # of the column-scaled regressor
    rms: float  # residual [effort unit]
    relative_error: float  # ||F - W theta|| / ||F||

    def table(self) -> dict[str, dict[str, float]]:
        return {t: {"value": p, "std": s, "relative_std_percent":
                    100 * s / abs(p) if p else math.inf}
                for t, p, s in zip(self.terms, self.parameters, self.std)}


@dataclass(frozen=True)
class LinearModel:
    """A machine's identified inverse model: per axis its fit."""

    machine: Machine
    axes: dict[str, AxisFit]
    lead_s: float = 0.0  # the efforts' lead over the motion: the feedforward looks this far ahead

    def predict(self, motion: Motion) -> dict[str, np.ndarray]:
        """Each axis's effort along `motion` (motion_of)."""
        return {axis.name: np.column_stack(columns(self.machine, k, motion,
                                                    self.axes[axis.name].width, np))
                @ np.asarray(self.axes[axis.name].parameters)
                for k, axis in enumerate(self.machine.axes)}

    def casadi_function(self) -> ca.Function:
        """(positions, velocities, accelerations: one entry per axis) -> efforts."""
        n = len(self.machine.axes)
        pos, vel, acc = (ca.SX.sym(name, n) for name in ("pos", "vel", "acc"))
        motion: dict[str, ca.SX] = {}
        for k, axis in enumerate(self.machine.axes):
            motion.update(zip(axis.motion, (pos[k], vel[k], acc[k])))
        efforts = [ca.dot(ca.vertcat(*columns(self.machine, k, motion,
                                                self.axes[axis.name].width, ca)),
                          ca.DM(self.axes[axis.name].parameters))
                   for k, axis in enumerate(self.machine.axes)]
        return ca.Function("identified_inverse_model", [pos, vel, acc], [ca.vertcat(*efforts)],
                           ["pos", "vel", "acc"], ["effort"])

    def to_dict(self) -> dict[str, Any]:
        return {"format": FORMAT, "machine": machine_table(self.machine),
                "axes": {name: fit.__dict__ for name, fit in self.axes.items()},
                "lead_s": self.lead_s}

    def summary(self) -> str:
        """The parameters with their standard deviations, axis by axis."""
        lines = []
        for axis in self.machine.axes:
            fit = self.axes[axis.name]
            lines.append(f"axis {axis.name}: relative error {100 * fit.relative_error:.2f} %, "
                         f"rms {fit.rms:.4g} {axis.effort_unit}, condition {fit.condition:.3g}, "
                         f"Coulomb width {fit.width:.3g} {axis.unit}/s")
            for term, row in fit.table().items():
                lines.append(f"  {term:<22} {row['value']:>12.6g} +- {row['std']:.3g} "
                             f"({row['relative_std_percent']:.2g} %)")
        return "\n".join(lines)




def linear_model_from_dict(data: Mapping[str, Any], where: str) -> LinearModel:
    """A model as LinearModel.to_dict wrote it; InputError naming `where` otherwise."""
    try:
        if data.get("format") != FORMAT:
            raise ValueError(f"format {data.get('format')!r}")
        machine = parse_machine(data["machine"], where)
        axes = {name: AxisFit(**fit) for name, fit in data["axes"].items()}
        lead = float(data.get("lead_s", 0.0))
    except (ValueError, KeyError, TypeError, AttributeError) as error:
        raise InputError(f"{where}: not an identified linear model ({error}): identify one "
                         f"with flexff identify") from None
    return LinearModel(machine, axes, lead)
