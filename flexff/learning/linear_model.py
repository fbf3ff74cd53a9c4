"""Identification for any machine: per axis an inverse model linear in its parameters,
effort = W(x, v, a) theta (learning.linear_prior's terms), fitted by least squares as robot
identification does (Gautier, Khalil): the regressor's columns filtered and decimated as the
labels are (`parallel_filter`), parameters with standard deviations sqrt(diag(s^2 (W^T W)^-1)),
the condition number of the column-scaled regressor and the relative error ||F - W theta|| /
||F||. The Coulomb width w is the prior's, or the one that leaves the smallest residual (the
best of WIDTHS, fractions of the axis's velocity limit, refined between its neighbours). A
column the data cannot tell from the columns before it (QR of the unit-norm columns in the
prior's order, |R_kk| below RANK_TOLERANCE) is refused, naming the term and the combination of
the others it equals. A fit that is unphysical or ill-determined is warned of in one line
naming the axis and the term (IdentificationWarning): an inertia that is not positive, a
friction term (POSITIVE_TERMS) clearly negative, or a condition number above CONDITION_LIMIT.
"""

from __future__ import annotations

import json
import math
import warnings
from collections.abc import Callable, Mapping, Sequence
from pathlib import Path

import numpy as np
from scipy.linalg import cholesky, solve_triangular
from scipy.optimize import minimize_scalar

from flexff.cosim.machine import Machine
from flexff.cosim.recording import atomic_write
from flexff.fmu.errors import InputError
from flexff.learning.linear_prior import (
    AxisFit,
    LinearModel,
    Motion,
    columns,
    linear_model_from_dict,
    term_names,
)
from flexff.learning.signal_processing import lowpass

WIDTHS = (0.001, 0.003, 0.01, 0.03)  # Coulomb tanh widths to try, fractions of the v limit
# the width's search between the best of WIDTHS' neighbours ends within this share of it: on the
# drive's loop (true width 1e-3 m/s between WIDTHS' 7.5e-4 and 2.5e-3) the best of WIDTHS left a
# relative error of 2.7 % and the Coulomb levels 4 % off; refined, 0.76 % and within 0.5 %
WIDTH_TOLERANCE = 0.01
# |R_kk| of the QR of the unit-norm columns: the sine of the angle between a column and the
# span of those before it; below this the column is a combination of them
RANK_TOLERANCE = 1e-8
CHOLESKY_FLOOR = 1e-5  # _triangular: below this diagonal of R, Householder's QR decides
# parallel_filter's defaults, measured on a drive (1 um encoder, 5 Hz corner, 30 draws of
# 0.3 N effort noise): the decimated rate in corner frequencies, where the filtered residual's
# samples are nearly independent as the standard deviations assume (the errors' rms in standard
# deviations 0.9-1.2 at 2, 1.3-1.7 at 4, 2.7-3.6 at the networks' model rate of 20), and the
# corner periods left out at each end of a trajectory, where the filtered motion and efforts
# disagree (noise-free: inertia 1.5 % off with none, parameters within 0.004 % with 2)
SAMPLES_PER_CUTOFF = 2.0
EDGE_PERIODS = 2.0

# terms whose parameter a physical axis has positive: an inertia, friction that opposes motion
POSITIVE_TERMS = ("inertia", "viscous", "coulomb", "coulomb_positive", "coulomb_negative")
NEGATIVE_STDS = 3.0  # a friction term warns below zero by more than this many deviations
NEGLIGIBLE = 1e-3  # and its effort at the velocity limit above this share of the efforts' rms
# the column-scaled regressor's condition number above which the fit warns: a drive's prior
# (with cogging, with and without offset) on a multisine gives 3.6 and 5.9, a term a share
# of 1e-3 from another 3.5e4 (tests/learning/test_linear_model.py's data)
CONDITION_LIMIT = 1e4

Filter = Callable[[np.ndarray], np.ndarray]  # (n, k) samples -> (m, k), along axis 0


class IdentificationWarning(UserWarning):
    """An identified model that is unphysical or ill-determined; the message names the term."""


class IdentificationError(InputError):
    """Data that cannot identify the model asked for; the message names the term."""


def regressor(machine: Machine, motion: Motion, width: float) -> dict[str, np.ndarray]:
    """Each axis's regressor W (n, p) along `motion` (linear_prior.motion_of), columns as
    linear_prior.term_names, at the Coulomb tanh width `width` [axis unit / s]."""
    return {axis.name: np.column_stack(np.broadcast_arrays(*columns(machine, k, motion,
                                                                    width, np)))
            for k, axis in enumerate(machine.axes)}


def reference_motion(machine: Machine, signals: Mapping[str, np.ndarray]) -> dict[str, np.ndarray]:
    """The motion of a trajectory's references (`<axis>_ref`, `v<axis>_ref`, `a<axis>_ref`):
    what a feedforward is computed on."""
    motion: dict[str, np.ndarray] = {}
    for axis in machine.axes:
        motion.update(zip(axis.motion, (np.asarray(signals[n], dtype=float)
                                        for n in (axis.reference, *axis.derivatives[:2]))))
    return motion


def parallel_filter(rate_hz: float, cutoff_hz: float, filter_order: int = 4,
                    decimation: int | None = None, edge_periods: float = EDGE_PERIODS) -> Filter:
    """The labels' zero-phase low-pass, `edge_periods` corner periods left out at each end and
    decimation (default: SAMPLES_PER_CUTOFF samples per corner period), for identify_linear's
    `filtered`: regressor columns and efforts alike."""
    if decimation is not None and not (isinstance(decimation, int) and decimation >= 1):
        raise InputError(f"decimation: expected a whole number >= 1, got {decimation!r}")
    if not edge_periods >= 0:
        raise InputError(f"edge_periods: expected a number >= 0, got {edge_periods!r}")
    step = decimation or max(1, math.floor(rate_hz / (SAMPLES_PER_CUTOFF * cutoff_hz)))
    edge = math.ceil(edge_periods / cutoff_hz * rate_hz)

    def filtered(values: np.ndarray) -> np.ndarray:
        if len(values) <= 2 * edge + 3 * (filter_order + 1):
            raise InputError(f"a trajectory of {len(values)} samples is too short for the "
                             f"filter's edges ({edge} samples each): give longer ones")
        kept = lowpass(values, rate_hz, cutoff_hz, filter_order)[edge:len(values) - edge:step]
        return np.asarray(kept)
    return filtered


def identify_linear(machine: Machine, motion: Motion | Sequence[Motion],
                    efforts: Mapping[str, np.ndarray] | Sequence[Mapping[str, np.ndarray]],
                    filtered: Filter | None = None, lead_s: float = 0.0) -> LinearModel:
    """Least squares of each axis's `efforts` on its regressor along `motion` (one trajectory,
    or a list of them with their efforts). `filtered` (n, k) -> (m, k) is applied to each
    trajectory's regressor columns and to its efforts alike before they are stacked: the
    labels' own low-pass and decimation (parallel filtering: a term linear in its parameters
    keeps them through any linear filter, so a friction step smoothed in the labels is matched
    by its column smoothed the same way). `lead_s`: how long before the motion its efforts were
    commanded (learning.machine_features aligned them), kept for the feedforward."""
    motions = [motion] if isinstance(motion, Mapping) else list(motion)
    labels_list = [efforts] if isinstance(efforts, Mapping) else list(efforts)
    keep = filtered or (lambda values: values)
    for name in (n for a in machine.axes for n in a.motion):
        if not all(np.all(np.isfinite(m[name])) for m in motions):
            raise IdentificationError(f"{name}: the motion holds values that are not finite")
    fits = {}
    for k, axis in enumerate(machine.axes):
        raw = [np.asarray(e[axis.name], dtype=float) for e in labels_list]
        if not all(np.all(np.isfinite(e)) for e in raw):
            raise IdentificationError(f"{axis.name}: the efforts hold values that are not "
                                      f"finite")
        labels = np.concatenate([keep(e[:, None])[:, 0] for e in raw])
        widths = ([machine.prior.coulomb_width] if machine.prior.coulomb_width
                  else [w * axis.limits.velocity for w in WIDTHS])
        if not any(t.startswith("coulomb") for t in machine.prior.terms):
            widths = widths[:1]

        def fit_at(width: float, k: int = k, labels: np.ndarray = labels) -> AxisFit:
            stacked = np.concatenate([keep(np.column_stack(np.broadcast_arrays(
                *columns(machine, k, m, width, np)))) for m in motions])
            return _fit(machine, k, stacked, labels, width)

        fits[axis.name] = _smallest_residual(fit_at, widths)
        scale = float(np.sqrt(np.mean(labels**2)))
        for problem in fit_problems(axis.name, fits[axis.name], scale, axis.limits.velocity):
            warnings.warn(problem, IdentificationWarning, stacklevel=2)
    return LinearModel(machine, fits, lead_s)


def fit_problems(axis: str, fit: AxisFit, effort_rms: float, velocity: float) -> list[str]:
    """What makes one axis's fit suspect, a line each naming the term: an inertia that is not
    positive (a feedforward with it pushes against the motion, and ILC on it diverges); a
    friction term below zero by more than NEGATIVE_STDS standard deviations whose effort at
    the axis's `velocity` limit is not negligible beside the efforts' rms `effort_rms`; a
    condition number above CONDITION_LIMIT."""
    problems = []
    advice = (f"(relative error {fit.relative_error:.1%}): check the axis's effort sign and "
              f"units, its prior's terms, and that the excitation moves it")
    for term, value, std in zip(fit.terms, fit.parameters, fit.std):
        if term not in POSITIVE_TERMS:
            continue
        effort = abs(value) * (velocity if term == "viscous" else 1.0)
        if (value <= 0 if term == "inertia" else value < -NEGATIVE_STDS * std
                and effort > NEGLIGIBLE * effort_rms):
            problems.append(f"axis {axis}: the identified {term} is {value:.4g} (std "
                            f"{std:.2g}), but a {term} must be positive {advice}")
    if fit.condition > CONDITION_LIMIT:
        problems.append(f"axis {axis}: the regressor's condition number is {fit.condition:.3g} "
                        f"(above {CONDITION_LIMIT:g}): the data hardly tell the terms "
                        f"{', '.join(fit.terms)} apart, so their values are unreliable; excite "
                        f"the axis over more speeds and accelerations, or drop a term")
    return problems


def _smallest_residual(fit_at: Callable[[float], AxisFit], widths: list[float]) -> AxisFit:
    """The fit at the Coulomb width of the smallest residual: the best of `widths`, then a
    bounded search on the width's logarithm between its neighbours (to WIDTH_TOLERANCE)."""
    fits = [fit_at(width) for width in widths]
    k = min(range(len(fits)), key=lambda i: fits[i].rms)
    if len(widths) == 1:
        return fits[k]
    low, high = widths[max(k - 1, 0)], widths[min(k + 1, len(widths) - 1)]
    found = minimize_scalar(lambda log_width: fit_at(math.exp(log_width)).rms,
                            bounds=(math.log(low), math.log(high)), method="bounded",
                            options={"xatol": WIDTH_TOLERANCE})
    return min(fits[k], fit_at(math.exp(found.x)), key=lambda fit: fit.rms)


def _fit(machine: Machine, k: int, w: np.ndarray, labels: np.ndarray, width: float) -> AxisFit:
    axis, terms = machine.axes[k].name, term_names(machine, k)
    twice = sorted({t for t in terms if terms.count(t) > 1})
    if twice:
        raise IdentificationError(f"machine.prior.extra.{axis}.{twice[0]}: the name of a prior "
                                  f"term's column: rename it")
    n, p = w.shape
    if n <= p:
        raise IdentificationError(f"axis {axis}: {n} samples cannot determine {p} terms "
                                  f"({', '.join(terms)}): give more data")
    scale = np.linalg.norm(w, axis=0)
    if np.any(scale == 0):
        raise IdentificationError(f"axis {axis}: the term {terms[int(np.argmin(scale))]} is "
                                  f"zero on every sample: the data do not excite it; remove it "
                                  f"or move the axis more")
    r, projection, residual_norm = _triangular(w / scale, labels)
    dependent = np.flatnonzero(np.abs(np.diag(r)) < RANK_TOLERANCE)
    if dependent.size:
        j = int(dependent[0])
        combination = solve_triangular(r[:j, :j], r[:j, j]) * scale[j] / scale[:j]
        largest = float(np.max(np.abs(combination)))
        equal = " ".join(f"{c:+.4g} {terms[i]}" for i, c in enumerate(combination)
                         if abs(c) > 1e-6 * largest)
        raise IdentificationError(
            f"axis {axis}: on these data the term {terms[j]} equals {equal}: the data cannot "
            f"tell them apart; drop {terms[j]} from machine.prior, or excite the axis so that "
            f"they differ")
    theta = solve_triangular(r, projection) / scale
    r_inverse = solve_triangular(r, np.eye(p))
    std = residual_norm / math.sqrt(n - p) * np.sqrt(np.sum(r_inverse**2, axis=1)) / scale
    norm = float(np.linalg.norm(labels))
    return AxisFit(terms, theta.tolist(), std.tolist(), float(width), float(np.linalg.cond(r)),
                   residual_norm / math.sqrt(n), residual_norm / norm if norm else math.inf)


def _triangular(w: np.ndarray, labels: np.ndarray) -> tuple[np.ndarray, np.ndarray, float]:
    """R of the QR of `w` (n, p: unit-norm columns), Q^T labels and the residual's norm. By
    Cholesky QR twice, whose passes over the samples are matrix products (1e6 x 5, one
    thread: 0.04 s against 0.13 s for Householder's R alone), unless the columns are nearly
    dependent (a diagonal of R below CHOLESKY_FLOOR, or a Cholesky factor that fails): its R
    is accurate only while the condition number stays well below 1e8, so Householder's QR of
    [W, F] decides then."""
    try:
        r1 = cholesky(w.T @ w)
        q1 = w @ solve_triangular(r1, np.eye(len(r1)))
        r2 = cholesky(q1.T @ q1)
        q = q1 @ solve_triangular(r2, np.eye(len(r2)))
        r = r2 @ r1
        if np.min(np.abs(np.diag(r))) >= CHOLESKY_FLOOR:
            projection = q.T @ labels
            return r, projection, float(np.linalg.norm(labels - q @ projection))
    except np.linalg.LinAlgError:
        pass
    p = w.shape[1]
    augmented: np.ndarray = np.linalg.qr(  # type: ignore[assignment]  # mode "r": R alone
        np.column_stack([w, labels]), mode="r")
    return augmented[:p, :p], augmented[:p, p], abs(float(augmented[p, p]))


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
