"""Identification for any machine: per axis an inverse model linear in its parameters,
effort = W(x, v, a) theta, fitted by least squares as robot identification does (Gautier,
Khalil): the regressor built from the same filtered motion as the labels, decimated,
parameters with standard deviations and the condition number of the column-scaled regressor.

Each axis's columns are the prior's terms (cosim.machine.PRIOR_TERMS: inertia a, viscous v,
Coulomb tanh(v / w) or its two one-sided levels, offset 1) and its extra terms (expressions of
every axis's motion: cogging, gravity, coupling). The Coulomb width w is the prior's, or the
one of WIDTHS (fractions of the axis's velocity limit) that leaves the smallest residual.
A column the data cannot tell from the others (relative singular value below RANK_TOLERANCE)
is refused, naming the term. The model evaluates on NumPy (`predict`) and as a CasADi Function
(`casadi_function`), the same terms, for the feedforward FMU and the physics-guided prior.
"""

from __future__ import annotations

import json
import math
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import casadi as ca
import numpy as np

from flexff.cosim.machine import Machine, parse_machine
from flexff.cosim.recording import atomic_write
from flexff.fmu.errors import InputError
from flexff.fmu.expressions import evaluate, to_casadi

WIDTHS = (0.001, 0.003, 0.01, 0.03)  # Coulomb tanh widths to try, fractions of the v limit
RANK_TOLERANCE = 1e-8  # smallest singular value of the scaled regressor, relative to the largest
FORMAT = "flexff-linear-model"

Motion = Mapping[str, np.ndarray]  # motion name (x, vx, ax of every axis) -> samples


class IdentificationError(InputError):
    """Data that cannot identify the model asked for; the message names the term."""


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


def _columns(machine: Machine, k: int, motion: Mapping[str, Any], width: float, backend: Any
             ) -> list[Any]:
    """One axis's regressor columns on NumPy arrays (backend np) or CasADi symbols (ca)."""
    axis = machine.axes[k]
    v, a = motion[axis.motion[1]], motion[axis.motion[2]]
    tanh = backend.tanh(v / width)
    one = v * 0 + 1
    by_term = {"inertia": [a], "viscous": [v], "coulomb": [tanh], "offset": [one],
               "coulomb_asymmetric": [0.5 * (1 + tanh), -0.5 * (1 - tanh)]}
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

    def predict(self, motion: Motion) -> dict[str, np.ndarray]:
        """Each axis's effort along `motion` (motion_of)."""
        return {axis.name: np.column_stack(_columns(self.machine, k, motion,
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
        efforts = [ca.dot(ca.vertcat(*_columns(self.machine, k, motion,
                                                self.axes[axis.name].width, ca)),
                          ca.DM(self.axes[axis.name].parameters))
                   for k, axis in enumerate(self.machine.axes)]
        return ca.Function("identified_inverse_model", [pos, vel, acc], [ca.vertcat(*efforts)],
                           ["pos", "vel", "acc"], ["effort"])

    def to_dict(self) -> dict[str, Any]:
        from flexff.cosim.machine import machine_table

        return {"format": FORMAT, "machine": machine_table(self.machine),
                "axes": {name: fit.__dict__ for name, fit in self.axes.items()}}

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


def identify_linear(machine: Machine, motion: Motion, efforts: Mapping[str, np.ndarray]
                    ) -> LinearModel:
    """Least squares of each axis's `efforts` on its regressor along `motion` (both already
    filtered alike and decimated: learning.machine_features.prepare does both)."""
    fits = {}
    for k, axis in enumerate(machine.axes):
        labels = np.asarray(efforts[axis.name], dtype=float)
        widths = ([machine.prior.coulomb_width] if machine.prior.coulomb_width
                  else [w * axis.limits.velocity for w in WIDTHS])
        if not any(t.startswith("coulomb") for t in machine.prior.terms):
            widths = widths[:1]
        candidates = [_fit(machine, k, motion, labels, width) for width in widths]
        fits[axis.name] = min(candidates, key=lambda f: f.rms)
    return LinearModel(machine, fits)


def _fit(machine: Machine, k: int, motion: Motion, labels: np.ndarray, width: float) -> AxisFit:
    terms = term_names(machine, k)
    w = np.column_stack(_columns(machine, k, motion, width, np))
    scale = np.linalg.norm(w, axis=0)
    if np.any(scale == 0):
        raise IdentificationError(f"axis {machine.axes[k].name}: the term "
                                  f"{terms[int(np.argmin(scale))]} is zero on every sample: the "
                                  f"data do not excite it; remove it or move the axis more")
    u, s, vt = np.linalg.svd(w / scale, full_matrices=False)
    if s[-1] < RANK_TOLERANCE * s[0]:
        weakest = terms[int(np.argmax(np.abs(vt[-1])))]
        raise IdentificationError(
            f"axis {machine.axes[k].name}: the data cannot tell {weakest} from the other terms "
            f"(condition {s[0] / max(s[-1], 1e-300):.3g}): excite the axis so that it differs, "
            f"or drop the term from machine.prior")
    theta_scaled = vt.T @ ((u.T @ labels) / s)
    theta = theta_scaled / scale
    residual = labels - w @ theta
    dof = max(len(labels) - len(terms), 1)
    variance = float(residual @ residual) / dof
    covariance = (vt.T / s**2) @ vt / np.outer(scale, scale) * variance
    norm = float(np.linalg.norm(labels))
    return AxisFit(terms, theta.tolist(), np.sqrt(np.diag(covariance)).tolist(), float(width),
                   float(s[0] / s[-1]), math.sqrt(float(np.mean(residual**2))),
                   float(np.linalg.norm(residual)) / norm if norm else math.inf)


def write_linear_model(model: LinearModel, out: str | Path) -> Path:
    """The model as JSON (read_linear_model reads it back)."""
    text = json.dumps(model.to_dict(), indent=2) + "\n"
    return atomic_write(out, lambda tmp: tmp.write_text(text, "utf-8"))


def read_linear_model(path: str | Path) -> LinearModel:
    """A model written by write_linear_model; InputError naming the file otherwise."""
    path = Path(path)
    try:
        data = json.loads(path.read_text("utf-8"))
        if data.get("format") != FORMAT:
            raise ValueError(f"format {data.get('format')!r}")
        machine = parse_machine(data["machine"], str(path))
        axes = {name: AxisFit(**fit) for name, fit in data["axes"].items()}
    except (OSError, ValueError, KeyError, TypeError) as error:
        raise InputError(f"{path}: not an identified linear model ({error}): identify one with "
                         f"flexff identify --machine") from None
    return LinearModel(machine, axes)
