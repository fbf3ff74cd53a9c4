"""Identification for any machine: per axis an inverse model linear in its parameters,
effort = W(x, v, a) theta (controllers.linear_prior's terms), fitted by least squares as robot
identification does (Gautier, Khalil): the regressor's columns filtered and decimated as the
labels are, parameters with standard deviations and the condition number of the column-scaled
regressor. The Coulomb width w is the prior's, or the one of WIDTHS (fractions of the axis's
velocity limit) that leaves the smallest residual. A column the data cannot tell from the
others (relative singular value below RANK_TOLERANCE) is refused, naming the term.
"""

from __future__ import annotations

import json
import math
from collections.abc import Callable, Mapping, Sequence
from pathlib import Path

import numpy as np

from flexff.controllers.linear_prior import (
    AxisFit,
    LinearModel,
    Motion,
    columns,
    linear_model_from_dict,
    term_names,
)
from flexff.cosim.machine import Machine
from flexff.cosim.recording import atomic_write
from flexff.fmu.errors import InputError

WIDTHS = (0.001, 0.003, 0.01, 0.03)  # Coulomb tanh widths to try, fractions of the v limit
RANK_TOLERANCE = 1e-8  # smallest singular value of the scaled regressor, relative to the largest


class IdentificationError(InputError):
    """Data that cannot identify the model asked for; the message names the term."""


def identify_linear(machine: Machine, motion: Motion | Sequence[Motion],
                    efforts: Mapping[str, np.ndarray] | Sequence[Mapping[str, np.ndarray]],
                    filtered: Callable[[np.ndarray], np.ndarray] | None = None) -> LinearModel:
    """Least squares of each axis's `efforts` on its regressor along `motion` (one trajectory,
    or a list of them with their efforts). `filtered` (n, k) -> (m, k) is applied to each
    trajectory's regressor columns and to its efforts alike before they are stacked: the
    labels' own low-pass and decimation (parallel filtering: a term linear in its parameters
    keeps them through any linear filter, so a friction step smoothed in the labels is matched
    by its column smoothed the same way)."""
    motions = [motion] if isinstance(motion, Mapping) else list(motion)
    labels_list = [efforts] if isinstance(efforts, Mapping) else list(efforts)
    keep = filtered or (lambda values: values)
    fits = {}
    for k, axis in enumerate(machine.axes):
        labels = np.concatenate([keep(np.asarray(e[axis.name], dtype=float)[:, None])[:, 0]
                                 for e in labels_list])
        widths = ([machine.prior.coulomb_width] if machine.prior.coulomb_width
                  else [w * axis.limits.velocity for w in WIDTHS])
        if not any(t.startswith("coulomb") for t in machine.prior.terms):
            widths = widths[:1]

        def regressor(width: float, k: int = k) -> np.ndarray:
            return np.concatenate([keep(np.column_stack(columns(machine, k, m, width, np)))
                                   for m in motions])

        candidates = [_fit(machine, k, regressor(width), labels, width) for width in widths]
        fits[axis.name] = min(candidates, key=lambda f: f.rms)
    return LinearModel(machine, fits)


def _fit(machine: Machine, k: int, w: np.ndarray, labels: np.ndarray, width: float) -> AxisFit:
    terms = term_names(machine, k)
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
    except (OSError, ValueError) as error:
        raise InputError(f"{path}: not an identified linear model ({error}): identify one with "
                         f"flexff identify") from None
    return linear_model_from_dict(data, str(path))
