"""Motor friction identified from training data: the one fitted part of the pgnn's prior.

On the hardware stand-in most of the force the nominal rigid-body model misses is the
motors' friction. Its Coulomb part steps at every reversal of a shoulder, a step a network
sampled at 100 Hz, whose forces the feedforward FMU extrapolates between calls, does not
follow. The plant's friction model (plant.actuator.friction_torque: Coulomb on a tanh plus
viscous, per motor, mapped to the wrist by A^T) is linear in its Coulomb and viscous torques
for a given tanh width, so non-negative least squares identifies them from F - F_rigid on the
training samples, once per candidate width, and the width with the smallest residual is
kept. The prior is then the nominal inverse dynamics with these parameters
(learning.rigid), computed in the feedforward FMU at every 1 ms step.

Measured on the hardware stand-in (its plant: 7 mNm Coulomb and 0.2 mNm s/rad viscous per
motor, tanh width 0.01 rad/s, torque constants 2 to 4 % low): the training set gives 7.6, 6.1
and 6.0 mNm Coulomb at the width 0.01 rad/s, and a "viscous" 0, 42 and 38 mNm s/rad that takes
up other mismatch too. On the test trajectories the rigid-body model's error falls from 18 /
21 mN rms (x / y) to 5.3 / 11 mN with it. The pgnn's test MSE hardly moves (4.6e-6 to 4.4e-6,
seed 0: the network had learned the low-passed labels' friction), but in closed loop on the
hardware evaluation reference its e2 ratios went from 50 / 42, 54 / 44 and 50 / 49 (seeds 0 to
2) to 134 / 79, 79 / 74 and 74 / 88, on a circle and a spline nobody trained for alike: the
friction's steps now come at each reversal of the reference, not learned through a 1.8 Hz
filter and extrapolated between 100 Hz calls.
"""

from __future__ import annotations

import functools

import casadi as ca
import numpy as np
from scipy.optimize import nnls

from flexff.controllers.features import evaluate_samples, motion_columns, nominal_model
from flexff.learning.batches import TRAIN, interior
from flexff.learning.casadi_torch import frozen
from flexff.learning.rigid import rigid_forces
from flexff.plant.parameters import NOMINAL

LINEAR = tuple(NOMINAL.flat_values("tau_coulomb", "b_viscous"))  # tau_coulomb1 ... b_viscous3
WIDTHS = (1e-3, 3e-3, 1e-2, 3e-2, 1e-1)  # candidate tanh widths w_stribeck [rad/s]
MAX_SAMPLES = 100_000  # more are taken evenly spaced: 7 parameters need no more


def identify_friction(features: list[np.ndarray], forces: list[np.ndarray], feature_set: str,
                      edge: int = 0) -> dict[str, float]:
    """The motor friction parameters (LINEAR and w_stribeck, flat plant parameter names) that
    best explain F - F_rigid over the trajectories' samples (features (n, n_features) and
    forces (n, 2) in SI units), the first and last `edge` of each left out; at most
    MAX_SAMPLES of them, evenly spaced."""
    keep = [interior(len(x), edge) == TRAIN for x in features]
    x, f = (np.concatenate([a[k] for a, k in zip(arrays, keep)]) for arrays in (features, forces))
    stride = -(-len(x) // MAX_SAMPLES)
    x, f = x[::stride], f[::stride]
    residual = (f - rigid_forces(x, feature_set)).ravel()
    pos, vel, _ = motion_columns(feature_set)
    fits = []
    for width in WIDTHS:
        regressors = evaluate_samples(_regressor_function(width), x[:, pos], x[:, vel])
        design = regressors.reshape(-1, len(LINEAR), 2).transpose(0, 2, 1).reshape(-1, len(LINEAR))
        coefficients, norm = nnls(design, residual)
        fits.append((norm, width, coefficients))
    _, width, coefficients = min(fits, key=lambda fit: fit[0])
    return {**dict(zip(LINEAR, coefficients.tolist())), "w_stribeck": width}


@functools.cache
def _regressor_function(width: float) -> ca.Function:
    """(pos, vel) -> dF/d(LINEAR), column by column (2 x 6, flattened): the nominal inverse
    dynamics' force is linear in the friction torques, so this is its whole friction part."""
    model = nominal_model()
    names = NOMINAL.names()
    linear = ca.vertcat(*[model.p[names.index(name)] for name in LINEAR])
    pos, vel, acc = ca.SX.sym("pos", 2), ca.SX.sym("vel", 2), ca.SX.sym("acc", 2)
    force = model.inverse_dynamics(pos, vel, acc, model.p)
    regressors = ca.Function("friction_regressors", [pos, vel, model.p],
                             [ca.vec(ca.jacobian(force, linear))])
    return frozen(regressors, [2], [model.parameter_values(w_stribeck=width)])
