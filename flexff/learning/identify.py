"""The rigid-body model identified from a dataset: what an engineer would deploy instead of
a learned feedforward.

The inverse dynamics with motor friction are linear in 41 parameters: F = W(pos, vel, acc)
theta. QR of the regressor's columns (STRUCTURE_SAMPLES, RANK_TOLERANCE) finds the identifiable
base parameters; ordinary least squares fits them once per tanh width (WIDTHS), with standard
uncertainties, the flexure dampings as one common scale where they cannot be told apart, and
jointly the motors' torque constants relative to one another (`gain_columns`). The
deployed parameter vector is the physical one nearest the nominal with exactly those base
parameters, or, where none exists, the nearest in force (bounded least squares), and the
report says by how much it differs.

Docs: "Learning", section The identified rigid-body model (docs/explanation/learning.md).
"""

from __future__ import annotations

import functools
import json
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import casadi as ca
import numpy as np
from scipy.optimize import lsq_linear

from flexff.controllers.features import motion_columns, nominal_model
from flexff.controllers.identified import (
    FRICTION_FIELDS,
    RIGID_BODY_FIELDS,
    write_identified,
)
from flexff.fmu.errors import InputError
from flexff.learning.batches import TRAIN, interior
from flexff.learning.dataset import Dataset, load_dataset
from flexff.learning.features import (
    FeatureConfig,
    feature_record,
    filter_labels,
    prepare_trajectory,
)
from flexff.learning.presets import edge_samples
from flexff.learning.samples import evaluate_samples
from flexff.learning.signal_processing import decimation
from flexff.plant.parameters import NOMINAL

STRUCTURE_SAMPLES = 500  # random workspace samples that reveal the base parameters
RANK_TOLERANCE = 1e-8  # |R_kk| below this (columns of unit norm): a dependent column
WIDTHS = (1e-3, 3e-3, 1e-2, 3e-2, 1e-1)  # candidate tanh widths w_stribeck [rad/s]
GAIN_PASSES = 3  # fits with the torque constants' columns at the last fit's force
CHANGES = 2  # the torque constants' changes estimated: motor 1's and 2's (gain_columns)
MAX_SAMPLES = 100_000  # more are taken evenly spaced: 29 base parameters need no more
REPORT = "identified.json"


def linear_names() -> tuple[str, ...]:
    """The flat parameters the force is linear in, in the order of preference."""
    return tuple(name for field in (*RIGID_BODY_FIELDS, *FRICTION_FIELDS)
                 for name in NOMINAL.flat_values(field))


@functools.cache
def _regressor_function(columns: tuple[int, ...], widths: int = 1) -> ca.Function:
    """(pos, vel, acc, w_stribeck) -> vec(dF/dtheta[columns]) (2 x len(columns), flattened)
    at each of `widths` tanh widths, one after another, F the force the motors must give
    (plant.model's `required_force`), the other parameters nominal; F is linear in theta, so
    this is its theta part. The widths share the kinematics, evaluated once."""
    model = nominal_model()
    names = NOMINAL.names()
    linear = linear_names()
    theta = ca.vertcat(*[model.p[names.index(linear[k])] for k in columns])
    width = model.p[names.index("w_stribeck")]
    pos, vel, acc = ca.SX.sym("pos", 2), ca.SX.sym("vel", 2), ca.SX.sym("acc", 2)
    jacobian = ca.jacobian(model.required_force(pos, vel, acc, model.p), theta)
    fixed = [n for n in names if n not in (*linear, "w_stribeck")]
    values = dict(zip(names, model.parameter_values()))
    jacobian = ca.substitute(jacobian, ca.vertcat(*[model.p[names.index(n)] for n in fixed]),
                             ca.DM([values[n] for n in fixed]))
    each = ca.SX.sym("w_stribeck", widths)
    out = ca.vertcat(*[ca.vec(ca.substitute(jacobian, width, each[k])) for k in range(widths)])
    return ca.Function("rigid_body_regressor", [pos, vel, acc, each], [out],
                       ["pos", "vel", "acc", "w_stribeck"], ["W"])


@functools.cache
def width_columns() -> tuple[tuple[int, ...], tuple[int, ...]]:
    """Indices into linear_names() of the regressor's columns that do not, and that do,
    depend on the tanh width (the Coulomb friction's)."""
    everything = tuple(range(len(linear_names())))
    function = _regressor_function(everything)
    symbols = function.sx_in()
    jacobian = ca.reshape(function(*symbols), 2, len(everything))
    width = symbols[3]
    varying = tuple(k for k in everything if ca.depends_on(jacobian[:, k], width))
    return tuple(k for k in everything if k not in varying), varying


def regressor(pos: np.ndarray, vel: np.ndarray, acc: np.ndarray, width: float,
              columns: tuple[int, ...] | None = None) -> np.ndarray:
    """The regressor (2n, 41) of n samples (rows x then y of each sample): F = W theta; only
    the columns `columns` (indices into linear_names()) if given."""
    return regressors(pos, vel, acc, (width,), columns)[0]


def regressors(pos: np.ndarray, vel: np.ndarray, acc: np.ndarray, widths: tuple[float, ...],
               columns: tuple[int, ...] | None = None) -> list[np.ndarray]:
    """`regressor` at each of `widths`, in one pass over the samples."""
    columns = tuple(range(len(linear_names()))) if columns is None else columns
    n, k = len(pos), len(columns)
    values = evaluate_samples(_regressor_function(columns, len(widths)), pos, vel, acc,
                              np.tile(widths, (n, 1)))
    per_width = values.reshape(n, len(widths), k, 2)
    return [per_width[:, j].transpose(0, 2, 1).reshape(2 * n, k) for j in range(len(widths))]


def _by_width(rows: Callable[[tuple[float, ...], tuple[int, ...]], list[np.ndarray]]
              ) -> Callable[[float], np.ndarray]:
    """regressor_at(width) from rows(widths, columns), the regressor's `columns` at each of
    `widths`: the columns that the width does not change (38 of 41, all but the Coulomb
    torques') are evaluated once, not for every candidate width (on the hardware set that
    took a physics-guided run's data preparation from 94 s to 55 s), and the others at every
    candidate in one pass (their kinematics once: 2 s of a 10 s identification on 2 cores)."""
    fixed, varying = width_columns()
    constant = rows(WIDTHS[:1], fixed)[0]
    coulomb = dict(zip(WIDTHS, rows(WIDTHS, varying)))

    def at(width: float) -> np.ndarray:
        full = np.empty((len(constant), len(linear_names())))
        full[:, list(fixed)] = constant
        full[:, list(varying)] = coulomb[width]
        return full
    return at


@functools.cache
def _gain_function() -> ca.Function:
    """(pos, F) -> vec(dF_commanded / d(g1, g2)) (2 x 2, flattened) at the nominal
    parameters and commanded force F: the change of the force to command (plant.model's
    `commanded`) per relative change g of motor 1's and motor 2's torque constants, motor 3's
    changing by -(g1 + g2)."""
    model = nominal_model()
    names = NOMINAL.names()
    constants = [model.p[names.index(n)] for n in NOMINAL.flat_values("k_t")]
    pos, force = ca.SX.sym("pos", 2), ca.SX.sym("F", 2)
    jacobian = ca.jacobian(model.commanded(pos, force, model.p), ca.vertcat(*constants))
    jacobian = ca.substitute(jacobian, model.p, ca.DM(model.parameter_values()))
    relative = jacobian @ ca.diag(ca.DM(NOMINAL.k_t))
    columns = ca.horzcat(relative[:, 0] - relative[:, 2], relative[:, 1] - relative[:, 2])
    return ca.Function("gain_columns", [pos, force], [ca.vec(columns)], ["pos", "F"], ["G"])


def gain_columns(pos: np.ndarray, forces: np.ndarray) -> np.ndarray:
    """The regressor's columns (2n, 2) of the motors' relative torque constants at n samples
    of position and commanded force (n, 2 each), rows as `regressor`'s.

    The controller shares a force among the motors by their nominal torque constants; a
    motor a few percent weaker gives a few percent less of its share, which depends on the
    position. The force the motors give is linear in the constants at a given commanded
    force, so with G taken at the commanded force F_commanded = W theta + G g holds exactly
    (`_least_squares` takes it at the model's own). The changes' sum is fixed at zero: a
    change of all three alike scales every force, and so is one of the inertias and
    frictions. On the hardware stand-in (torque constants 3, 2 and 4 % low) the ILC forces of
    its training references less the true rigid-body model's (its tool's mass left out) left
    11 / 16 mN rms; these columns took that to 2.5 / 2.6 mN, with changes of -2.8, -1.8 and
    -3.7 %."""
    values = evaluate_samples(_gain_function(), pos, forces)
    return values.reshape(len(pos), 2, 2).transpose(0, 2, 1).reshape(2 * len(pos), 2)


def relative_gains(changes: np.ndarray) -> np.ndarray:
    """The three motors' torque constants over the nominal ones from the changes (g1, g2)."""
    return 1.0 + np.array([changes[0], changes[1], -changes[0] - changes[1]])


@dataclass(frozen=True)
class BaseParameters:
    """beta = theta[independent] + combination @ theta[dependent] (indices into linear_names)."""

    independent: tuple[int, ...]
    dependent: tuple[int, ...]
    combination: np.ndarray  # (len(independent), len(dependent))

    def of(self, theta: np.ndarray) -> np.ndarray:
        """The base parameters of a full parameter vector theta (in linear_names' order)."""
        theta = np.asarray(theta, dtype=float)
        beta: np.ndarray = theta[list(self.independent)] + self.combination @ theta[
            list(self.dependent)]
        return beta

    @property
    def matrix(self) -> np.ndarray:
        """B with beta = B theta (base parameters x linear_names)."""
        groups = np.zeros((len(self.independent), len(self.independent) + len(self.dependent)))
        groups[:, list(self.independent)] = np.eye(len(self.independent))
        groups[:, list(self.dependent)] = self.combination
        return groups

    def nearest(self, beta: np.ndarray, theta: np.ndarray) -> np.ndarray:
        """The full parameter vector with base parameters `beta` nearest to `theta`, each
        change relative to its entry of `theta` (SI units where that is zero): a group's
        change spread over its members, so that none of them turns negative for a change of
        the group that the others take up."""
        scale = _scale(theta)
        change = np.linalg.pinv(self.matrix * scale) @ (beta - self.matrix @ theta)
        nearest: np.ndarray = theta + scale * change
        return nearest

    def physical(self, beta: np.ndarray, theta: np.ndarray, metric: np.ndarray) -> np.ndarray:
        """The physical parameter vector (positive masses, inertias and stiffnesses, no
        negative damping or friction) whose base parameters come nearest to `beta` in the
        norm of `metric` (R of the base regressor's QR: the rms force difference on the
        data), the one nearest `theta` among equals: `nearest` where that is physical."""
        nearest = self.nearest(beta, theta)
        lower = _lower_bounds(theta)
        if np.all(nearest >= lower):
            return nearest
        scale = _scale(theta)
        weight = 1e-6 * np.linalg.norm(metric @ self.matrix) / np.sqrt(len(theta))
        system = np.vstack([metric @ self.matrix * scale, weight * np.eye(len(theta))])
        target = np.concatenate([metric @ (beta - self.matrix @ theta), np.zeros(len(theta))])
        change = lsq_linear(system, target, bounds=((lower - theta) / scale, np.inf)).x
        physical: np.ndarray = theta + scale * change
        return physical

    def labels(self) -> list[str]:
        """Each base parameter as its formula, e.g. `j_up1 + 0.0238*m_up1 + j_rotor1`."""
        names = linear_names()
        out = []
        for row, lead in zip(self.combination, self.independent):
            terms = [names[lead]]
            for c, j in zip(row, self.dependent):
                if abs(c) > 1e-12:
                    terms.append(names[j] if abs(c - 1) < 1e-9 else f"{c:.6g}*{names[j]}")
            out.append(" + ".join(terms).replace("+ -", "- "))
        return out


def _scale(theta: np.ndarray) -> np.ndarray:
    """Each parameter's scale for relative changes: its value, 1 (SI) where that is 0."""
    scale: np.ndarray = np.where(theta != 0, np.abs(theta), 1.0)
    return scale


def _lower_bounds(theta: np.ndarray) -> np.ndarray:
    """The smallest physical value of each linear parameter: a millionth of `theta` for
    those that must be positive (PlantParameters' metadata), zero for the others."""
    positive = {name: must for name, *_, must in NOMINAL.describe()}
    must = np.array([positive[n] for n in linear_names()])
    lower: np.ndarray = np.where(must, 1e-6 * np.abs(theta), 0.0)
    return lower


@functools.cache
def base_parameters() -> BaseParameters:
    """The structurally identifiable combinations, from the regressor at random samples of
    the workspace (fixed seed: the same every time)."""
    rng = np.random.default_rng(0)
    radius = NOMINAL.workspace_radius * np.sqrt(rng.uniform(size=STRUCTURE_SAMPLES))
    angle = rng.uniform(0.0, 2 * np.pi, STRUCTURE_SAMPLES)
    pos = np.column_stack([radius * np.cos(angle), radius * np.sin(angle)])
    vel, acc = rng.normal(0.0, 0.1, pos.shape), rng.normal(0.0, 1.0, pos.shape)
    raw = regressor(pos, vel, acc, WIDTHS[len(WIDTHS) // 2])
    scale = np.linalg.norm(raw, axis=0)
    w = raw / scale
    r = np.linalg.qr(w, mode="r")
    keep = np.abs(np.diag(r)) > RANK_TOLERANCE
    independent = tuple(int(k) for k in np.flatnonzero(keep))
    dependent = tuple(int(k) for k in np.flatnonzero(~keep))
    coefficients = np.linalg.lstsq(w[:, independent], w[:, dependent], rcond=None)[0]
    combination = coefficients * scale[list(dependent)] / scale[list(independent)][:, None]
    return BaseParameters(independent, dependent, combination)


@dataclass(frozen=True)
class Identification:
    """The identified base parameters, their standard uncertainties and the fit."""

    values: np.ndarray  # base parameters (BaseParameters order)
    std: np.ndarray  # their standard uncertainties (0 where not estimated)
    estimated: tuple[bool, ...]  # False: the data cannot tell it; its nominal value is kept
    w_stribeck: float  # the tanh width of the Coulomb friction kept [rad/s]
    residual_rms: tuple[float, float]  # rms of F - W1 beta, x and y [N]
    label_rms: tuple[float, float]  # rms of the forces themselves [N]
    nominal_rms: tuple[float, float]  # rms of F - F_nominal (the nominal model's error) [N]
    samples: int
    metric: np.ndarray  # R of the QR of the base regressor / sqrt(rows): |metric @ d_beta|
    # is the rms force (both axes) that a change d_beta of the base parameters makes
    gains: np.ndarray = field(default_factory=lambda: np.zeros(CHANGES))  # changes (g1, g2)
    # of the motors' torque constants (gain_columns; 0 where not estimated)
    gains_std: np.ndarray = field(default_factory=lambda: np.zeros(CHANGES))
    data: Mapping[str, Any] = field(default_factory=dict)  # what it was identified on

    def parameters(self) -> dict[str, float]:
        """The flat plant parameters to deploy: those nearest the nominal ones with the
        identified base parameters, or, where those are not physical, the physical ones
        nearest to them (BaseParameters.physical)."""
        theta = base_parameters().physical(self.values, _nominal_theta(), self.metric)
        constants = np.asarray(NOMINAL.k_t) * relative_gains(self.gains)
        return {**dict(zip(linear_names(), theta.tolist())), "w_stribeck": self.w_stribeck,
                **dict(zip(NOMINAL.flat_values("k_t"), constants.tolist()))}

    def rows(self) -> list[dict[str, Any]]:
        """One row per base parameter: its formula, unit, value, standard uncertainty."""
        base = base_parameters()
        units = {row[0]: row[2] for row in NOMINAL.describe()}
        names = linear_names()
        return [{"name": names[lead], "base": label, "unit": units[names[lead]],
                 "value": float(v), "std": float(s) if estimated else None,
                 "estimated": estimated}
                for lead, label, v, s, estimated in zip(base.independent, base.labels(),
                                                        self.values, self.std, self.estimated)]

    def deployed_misfit(self) -> float:
        """The rms force [N] by which the deployed parameters' model differs from the
        identified one on the samples: 0 unless the identified base parameters have no
        physical parameter vector."""
        theta = np.array([self.parameters()[n] for n in linear_names()])
        change = base_parameters().matrix @ theta - self.values
        return float(np.linalg.norm(self.metric @ change))

    def report(self) -> dict[str, Any]:
        """The identification as plain data (what identified.json holds beside the
        deployable parameters)."""
        return {"data": dict(self.data), "base_parameters": self.rows(),
                "w_stribeck": self.w_stribeck,
                "torque_constants_relative": relative_gains(self.gains).tolist(),
                "torque_constant_changes_std": self.gains_std.tolist(),  # of g1, g2
                "samples": self.samples,
                "residual_rms_n": dict(zip("xy", self.residual_rms)),
                "label_rms_n": dict(zip("xy", self.label_rms)),
                "nominal_model_rms_n": dict(zip("xy", self.nominal_rms)),
                "deployed_misfit_rms_n": self.deployed_misfit(),
                "method": "ordinary least squares on the base parameters (QR of the "
                          "regressor at random workspace samples, fixed order); std: "
                          "sqrt(diag(s^2 (W1^T W1)^-1)), independent residuals assumed"}


def identify_motion(pos: np.ndarray, vel: np.ndarray, acc: np.ndarray,
                    forces: np.ndarray) -> Identification:
    """Least squares of the base parameters from n samples of motion (n, 2 each) and the
    end-effector force that produced it (n, 2) [SI]: the tanh width of the smallest residual
    among the candidates, then the base parameters at that width, those the data cannot tell
    at their nominal values (`_essential`)."""
    if len(pos) < len(linear_names()):
        raise InputError(f"{len(pos)} samples cannot determine {len(linear_names())} "
                         f"parameters: give more data")
    return _least_squares(_by_width(lambda widths, columns: regressors(pos, vel, acc, widths,
                                                                      columns)), forces,
                          lambda force: gain_columns(pos, force))


def _least_squares(regressor_at: Callable[[float], np.ndarray], forces: np.ndarray,
                   gains_at: Callable[[np.ndarray], np.ndarray]) -> Identification:
    """identify_motion on the regressor `regressor_at(width)` (2n, 41) of n samples whose
    forces (n, 2) are given, with the torque constants' columns `gains_at(force)` (2n, 2) at
    the model's force, GAIN_PASSES times: taken at the labels, whose noise they would share,
    they explained the noise (hardware stand-in's collected set: motor 2 12 % strong, its
    true 1 %)."""
    base = base_parameters()
    labels = np.asarray(forces, dtype=float).reshape(-1)
    independent = list(base.independent)
    count = len(independent)

    def fit(width: float) -> tuple[float, float, np.ndarray]:
        w = regressor_at(width)
        return _residual_norm(w[:, independent], labels), width, w

    # min over a generator holds two regressors (2n x 41) at most, not one per width
    _, width, full = min((fit(width) for width in WIDTHS), key=lambda f: f[0])
    rigid = full[:, independent]
    nominal = np.concatenate([base.of(_nominal_theta()), np.zeros(CHANGES)])
    model = rigid @ np.linalg.lstsq(rigid, labels, rcond=None)[0]
    for _ in range(GAIN_PASSES):
        columns = np.hstack([rigid, gains_at(model.reshape(-1, 2))])
        beta, free, residual, covariance = _common_damping(
            columns, labels, nominal, *_essential(columns, labels, nominal))
        model = labels - residual
    std = np.zeros(len(beta))
    std[free] = np.sqrt(np.clip(np.diag(covariance), 0.0, None))
    return Identification(
        values=beta[:count], std=std[:count], estimated=tuple(bool(k) for k in free[:count]),
        w_stribeck=width, residual_rms=_axis_rms(residual), label_rms=_axis_rms(labels),
        nominal_rms=_axis_rms(labels - full @ _nominal_theta()), samples=len(labels) // 2,
        metric=np.linalg.qr(rigid, mode="r") / np.sqrt(len(labels)),
        gains=beta[count:], gains_std=std[count:])


def _residual_norm(w: np.ndarray, labels: np.ndarray) -> float:
    """The norm of the least-squares residual of labels = w beta."""
    beta, *_ = np.linalg.lstsq(w, labels, rcond=None)
    return float(np.linalg.norm(labels - w @ beta))


def _essential(w: np.ndarray, labels: np.ndarray, nominal: np.ndarray
               ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Least squares of the base parameters (regressor `w`), dropping one at a time the one
    whose share of the forces (the norm of its column times its value) is smallest, while
    that share is below the norm of the residual: such a parameter cannot be told from what
    the model leaves unexplained (measured on the hardware stand-in: the inertias, 0.2 % of
    the forces of its slow motion, and the dampings, 0.03 %, under a 2 % residual, took up
    its noise and unmodelled tool mode as a wrist inertia of 12 kg m^2 and negative
    dampings), and keeps its nominal value. Returns the base parameters, which were
    estimated (a mask), the residual and the covariance of the estimated ones.

    Each fit solves the triangular factor of one QR decomposition of [w, labels], not w's
    rows: the same least squares (the rows' part orthogonal to w's columns is a constant),
    in a fraction of the time (the hardware set's 2e5 rows: 0.3 s a fit, about 20 fits a
    call)."""
    count = w.shape[1]
    triangle = np.asarray(np.linalg.qr(np.column_stack([w, labels]), mode="r"))
    reduced, projected = triangle[:count, :count], triangle[:count, count]
    column_norms = np.linalg.norm(w, axis=0)
    free = np.ones(len(nominal), dtype=bool)
    while True:
        known = reduced[:, ~free] @ nominal[~free]
        estimate, *_ = np.linalg.lstsq(reduced[:, free], projected - known, rcond=None)
        beta = nominal.copy()
        beta[free] = estimate
        residual = labels - w @ beta
        share = np.where(free, column_norms * np.abs(beta), np.inf)
        weakest = int(np.argmin(share))
        if share[weakest] >= np.linalg.norm(residual):
            break
        free[weakest] = False
    dof = max(len(labels) - int(free.sum()), 1)
    variance = float(residual @ residual) / dof
    covariance = variance * np.linalg.pinv(w[:, free].T @ w[:, free])
    return beta, free, residual, covariance


def _common_damping(w: np.ndarray, labels: np.ndarray, nominal: np.ndarray, beta: np.ndarray,
                    free: np.ndarray, residual: np.ndarray, covariance: np.ndarray
                    ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """`_essential`'s fit, where it did not estimate every flexure damping on its own, with
    the dampings estimated instead as one common scale of their nominal values, jointly with
    the other parameters it estimated, where that scale comes out positive and well
    determined (over three standard uncertainties).

    One by one the dampings cannot be told apart (those few it keeps take up the others'
    force: three times the nominal dampings on slow circles, 1 mN of noise, gave elbows of
    4.8 to 5.1 times theirs and the rest nominal); together they can, and only jointly with
    the Coulomb frictions, which on a circle at constant speed push as a damping does. The
    hardware stand-in's dampings are three times the nominal ones: fitted after the others
    the scale came out 1.35 +- 0.05, jointly 3.0 +- 0.13, the Coulomb torques 7.2 mNm instead
    of 7.3 (the stand-in's 7.0), and the identified feedforward's e2 on the evaluation
    reference 2.7 / 3.6 um/sqrt(s) with nominal dampings, 2.2 / 2.8 with the stand-in's."""
    labels_of = base_parameters().labels()  # the torque constants' columns follow them
    damping = np.array([k < len(labels_of) and labels_of[k].startswith("d_")
                        for k in range(len(beta))])
    if free[damping].all():
        return beta, free, residual, covariance
    estimated = np.flatnonzero(free & ~damping)
    kept = ~free & ~damping
    shape = w[:, damping] @ nominal[damping]  # the nominal dampings' force
    x = np.column_stack([w[:, estimated], shape])
    target = labels - w[:, kept] @ nominal[kept]  # what the kept ones leave
    solution, *_ = np.linalg.lstsq(x, target, rcond=None)
    joint_residual = target - x @ solution
    variance = float(joint_residual @ joint_residual) / max(len(labels) - x.shape[1], 1)
    joint = variance * np.linalg.pinv(x.T @ x)
    scale, spread = solution[-1], float(np.sqrt(joint[-1, -1]))
    if not scale > 3 * spread:
        return beta, free, residual, covariance
    beta = beta.copy()
    beta[estimated] = solution[:-1]
    beta[damping] = scale * nominal[damping]
    # the estimated ones in base-parameter order: each an entry of the solution, the
    # dampings all the scale times their nominal value
    order = np.flatnonzero(free | damping)
    rows = np.zeros((len(order), x.shape[1]))
    for row, k in enumerate(order):
        if damping[k]:
            rows[row, -1] = nominal[k]
        else:
            rows[row, list(estimated).index(k)] = 1.0
    return beta, free | damping, joint_residual, rows @ joint @ rows.T


def _nominal_theta() -> np.ndarray:
    """The nominal values of linear_names()."""
    values = dict(zip(NOMINAL.names(), NOMINAL.vector()))
    return np.array([values[n] for n in linear_names()])


def _axis_rms(rows: np.ndarray) -> tuple[float, float]:
    pairs = rows.reshape(-1, 2)
    x, y = np.sqrt(np.mean(pairs**2, axis=0))
    return float(x), float(y)


def identify(data: str | Path, features: FeatureConfig | None = None,
             edge_periods: float = 0.0) -> Identification:
    """Identify the base parameters on the training split of the dataset folder `data`,
    preprocessed as `features` says (default: the thesis's preprocessing), without the
    training noise, `edge_periods` of the filter's corner at each end left out (as training
    does, learning.presets.TrainConfig), at most MAX_SAMPLES samples evenly spaced."""
    features = features or FeatureConfig()
    dataset = load_dataset(data)
    trajectories = dataset.split("train")
    if not trajectories:
        raise InputError(f"{dataset.path}: the 'train' split is empty: mark some trajectories "
                         f"'train' in manifest.json or collect more data")
    rate = dataset.sample_rate_hz
    model_rate = rate / decimation(rate, features.model_rate_hz)
    compact = replace(features, feature_set="compact")
    pairs = [prepare_trajectory(t, rate, compact) for t in trajectories]
    edge = edge_samples(edge_periods, features.cutoff_hz, model_rate)
    return replace(identify_samples([x for x, _ in pairs], [f for _, f in pairs], compact,
                                    model_rate, edge),
                   data=identified_on(dataset, features, edge_periods))


def identify_samples(features: list[np.ndarray], forces: list[np.ndarray],
                     config: FeatureConfig, rate_hz: float, edge: int) -> Identification:
    """Identify on trajectories prepared with `config` at `rate_hz`: features (n, n_features)
    of its feature set and forces (n, 2) in SI units, the first and last `edge` samples of
    each (learning.presets.edge_samples) left out, at most MAX_SAMPLES of them, evenly spaced (what
    `identify` and the physics-guided model's prior in learning.manipulator_data share).

    The regressor passes through the labels' filter (learning.features.filter_labels),
    trajectory by trajectory, before the samples are taken (unless `config.filtered_prior`
    is off): the model is linear in its
    parameters, so the filtered force is the filtered regressor times them, where the
    regressor of the filtered motion steps with the Coulomb friction at each motor reversal
    and the filtered force does not (hardware stand-in: residual 4.1 / 6.6 mN against 4.6 /
    7.2 mN, identified feedforward e2 192 / 98 against 158 / 77)."""
    keep = [interior(len(x), edge) == TRAIN for x in features]
    count = sum(int(k.sum()) for k in keep)
    if count < len(linear_names()):
        raise InputError(f"{count} samples cannot determine {len(linear_names())} "
                         f"parameters: give more data")
    stride = -(-count // MAX_SAMPLES)
    taken = [np.flatnonzero(k)[::stride] for k in keep]  # per trajectory, about evenly spaced
    pos, vel, acc = motion_columns(config.feature_set)

    def rows(widths: tuple[float, ...], columns: tuple[int, ...]) -> list[np.ndarray]:
        taken_rows: list[list[np.ndarray]] = [[] for _ in widths]
        for x, samples in zip(features, taken):  # each width's columns side by side
            w = np.hstack([at_width.reshape(len(x), 2 * len(columns)) for at_width in
                           regressors(x[:, pos], x[:, vel], x[:, acc], widths, columns)])
            if config.filtered_prior:  # column by column
                w = filter_labels(w, rate_hz, config)
            for part, taken_part in zip(np.hsplit(w[samples], len(widths)), taken_rows):
                taken_part.append(part.reshape(-1, len(columns)))
        return [np.concatenate(part) for part in taken_rows]

    positions = np.concatenate([x[k][:, pos] for x, k in zip(features, taken)])
    return _least_squares(_by_width(rows), np.concatenate([f[k] for f, k in zip(forces, taken)]),
                          lambda force: gain_columns(positions, force))


def identified_on(dataset: Dataset, features: FeatureConfig, edge_periods: float
                  ) -> dict[str, Any]:
    """What an identification on `dataset` with `features` and `edge_periods` records of its
    data: a file with the same record need not be identified again."""
    plain: dict[str, Any] = json.loads(json.dumps({
        "path": str(Path(dataset.path).resolve()), "set": dataset.set,
        "sha256": dataset.digest,
        "features": feature_record(replace(features, feature_set="compact"), edge_periods)}))
    return plain


def write_identification(identification: Identification, out: str | Path) -> Path:
    """Write identified.json into the folder `out`: the deployable parameters, the base
    parameters with their uncertainties, the fit and what it was identified on."""
    return write_identified(Path(out) / REPORT, identification.parameters(),
                            identification.report())
