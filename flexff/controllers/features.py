"""Network inputs computed from the wrist's motion: what a learned feedforward sees.

A function of (position, velocity, acceleration) only, the same for training data (the
filtered measured motion) and for deployment (the reference x_ref ... ay_ref). The full set
is the 21 coordinates of eq. (2.1) and their first and second time derivatives, exact by the
chain rule (qd = J v, qdd = J a + (dJ/dt) v, J = dq/dpos) rather than differentiated; the
compact set is (x, y, vx, vy, ax, ay). The directions set adds each motor's direction of
motion, tanh(theta_si_dot / w) at the velocity scales DIRECTION_WIDTHS, for its Coulomb
friction. Kinematics are the nominal model's: the feedforward knows nothing better. A
black-box network may take the identified rigid-body model's force along the motion as two
more inputs (FORCE_INPUTS, learning.features.FeatureConfig.force_input): the physics as an
input rather than as a prior. As a CasADi Function it is both evaluated in numpy (learning/)
and generated into C inside the feedforward FMU.
"""

from __future__ import annotations

import functools
from collections.abc import Mapping

import casadi as ca
import numpy as np

from flexff.fmu.errors import InputError
from flexff.learning.samples import evaluate_samples
from flexff.plant.kinematics import COORDINATE_NAMES, EE_INDEX, SHOULDER_INDEX
from flexff.plant.model import PlantModel
from flexff.plant.signals import REFERENCE, names, reference_motion, units

FEATURE_SETS = ("full", "compact", "directions")
# velocity scales of the motors' direction features [rad/s]: a basis that a network's linear
# part combines into the friction's own transition, whatever its width (the hardware
# stand-in's is 0.01 rad/s: least squares on these features alone misses its friction force,
# 23 mN rms along its evaluation reference, by under 0.33 mN). A step no smooth function of
# the full features holds: the hardware stand-in's TCN, trained on the identified model's own
# forces as noise-free labels, missed them by up to 13 mN at each motor reversal of its
# evaluation reference (e2 50 / 49x PID alone; with these features 169 / 138x)
DIRECTION_WIDTHS = (0.003, 0.01, 0.03)
COMPACT_NAMES = ("x", "y", "vx", "vy", "ax", "ay")  # the wrist's motion, in REFERENCE's units
# the identified rigid-body model's force (eq. 2.4, learning.identify's parameters) [N]: the
# last two inputs of a network with force inputs
FORCE_INPUTS = ("Fx_id", "Fy_id")
ForceParameters = Mapping[str, float]  # flat nominal-model parameters of the force inputs


def feature_names(feature_set: str, force_input: bool = False) -> list[str]:
    """Signal names of the features (and the FORCE_INPUTS after them), in column order."""
    force = list(FORCE_INPUTS) if force_input else []
    if feature_set == "compact":
        return list(COMPACT_NAMES) + force
    if feature_set in ("full", "directions"):
        full = (list(COORDINATE_NAMES) + [f"{n}_dot" for n in COORDINATE_NAMES]
                + [f"{n}_ddot" for n in COORDINATE_NAMES])
        return full + (_direction_names() if feature_set == "directions" else []) + force
    raise InputError(f"unknown feature set {feature_set!r}: choose one of "
                     f"{', '.join(FEATURE_SETS)}")


def feature_units(feature_set: str, force_input: bool = False) -> list[str]:
    """SI units of the features (and the FORCE_INPUTS after them), in column order."""
    force = ["N"] * len(FORCE_INPUTS) if force_input else []
    if feature_set == "compact":
        return list(units(REFERENCE)) + force
    base = ["rad" if n.startswith("theta") else "m" for n in COORDINATE_NAMES]
    directions = ["1"] * len(_direction_names()) if feature_set == "directions" else []
    return base + [f"{u}/s" for u in base] + [f"{u}/s2" for u in base] + directions + force


def _direction_names() -> list[str]:
    """The directions set's last columns: each motor's direction at each velocity scale."""
    return [f"tanh({COORDINATE_NAMES[k]}_dot/{w:g})" for w in DIRECTION_WIDTHS
            for k in SHOULDER_INDEX]


def motion_columns(feature_set: str) -> tuple[list[int], list[int], list[int]]:
    """Columns of the features holding (x, y), (vx, vy) and (ax, ay) of the wrist."""
    if feature_set == "compact":
        return [0, 1], [2, 3], [4, 5]
    n = len(COORDINATE_NAMES)
    pos = list(EE_INDEX[:2])
    return pos, [n + k for k in pos], [2 * n + k for k in pos]


@functools.cache
def nominal_model() -> PlantModel:
    """The nominal plant model (built once: its symbolic construction takes a moment)."""
    return PlantModel("nominal")


@functools.cache
def motion_function(feature_set: str) -> ca.Function:
    """CasADi Function (pos, vel, acc) -> features of one sample, nominal kinematics built in."""
    model = nominal_model()
    pos, vel, acc = ca.SX.sym("pos", 2), ca.SX.sym("vel", 2), ca.SX.sym("acc", 2)
    if feature_set == "compact":
        out = ca.vertcat(pos, vel, acc)
    elif feature_set in ("full", "directions"):
        q = model.coordinates(pos, model.parameter_values())
        jac = ca.jacobian(q, pos)
        qd = jac @ vel
        out = ca.vertcat(q, qd, jac @ acc + ca.jtimes(qd, pos, vel))
        if feature_set == "directions":
            motors = ca.vertcat(*[qd[k] for k in SHOULDER_INDEX])
            out = ca.vertcat(out, *[ca.tanh(motors / w) for w in DIRECTION_WIDTHS])
    else:
        feature_names(feature_set)  # raises with the list of known sets
    return ca.Function(f"features_{feature_set}", [pos, vel, acc], [out],
                       ["pos", "vel", "acc"], ["features"])


def reference_feature_function(feature_set: str, force: ForceParameters | None = None
                               ) -> ca.Function:
    """CasADi Function (the REFERENCE signals x_ref ... ay_ref, one sample) -> features, and
    with `force` the FORCE_INPUTS of the model with those parameters after them: what a
    learned feedforward computes from its inputs."""
    return _reference_function(feature_set,
                               None if force is None else tuple(sorted(force.items())))


@functools.cache
def _reference_function(feature_set: str, force: tuple[tuple[str, float], ...] | None
                        ) -> ca.Function:
    reference = ca.SX.sym("reference", len(REFERENCE))
    motion = reference_motion(reference)
    features = motion_function(feature_set)(*motion)
    if force is not None:
        model = nominal_model()
        features = ca.vertcat(features, model.inverse_dynamics(
            *motion, model.parameter_values(**dict(force))))
    return ca.Function(f"reference_features_{feature_set}", [reference], [features],
                       ["reference"], ["features"])


def motion_features(pos: np.ndarray, vel: np.ndarray, acc: np.ndarray,
                    feature_set: str) -> np.ndarray:
    """Features (n, n_features) of n samples of wrist position, velocity, acceleration (n, 2)."""
    return evaluate_samples(motion_function(feature_set), pos, vel, acc)


def reference_features(signals: Mapping[str, np.ndarray], feature_set: str,
                       force: ForceParameters | None = None) -> np.ndarray:
    """Features (with `force`, and the FORCE_INPUTS) computed from the reference x_ref ...
    ay_ref: what the feedforward sees."""
    reference = np.column_stack([np.asarray(signals[s], dtype=float).ravel()
                                 for s in names(REFERENCE)])
    return evaluate_samples(reference_feature_function(feature_set, force), reference)


