"""The prior of the physics-guided model: eq. (2.4) on the nominal plant, with motor friction.

F_prior = M a + C v + Q + D - A^T tau_friction from the wrist position, velocity and
acceleration held in the features, the nominal model's inverse dynamics with some of its
parameters replaced (`parameters`: flat plant parameter names, the motor friction identified
from the training data by learning.friction; none: the nominal model, which has no friction).
Nothing in it is trained by gradient descent: the network beside it learns only the remainder
F - F_prior, the epsilon of eq. (2.5). Evaluated in numpy (CasADi, float64) when preparing
training data and as a torch module (the same CasADi expression replayed op by op) inside
the exported model.
"""

from __future__ import annotations

import functools
from collections.abc import Mapping

import casadi as ca
import numpy as np
import torch
from torch import nn

from flexff.controllers.allocation import motor_currents
from flexff.controllers.features import evaluate_samples, motion_columns, nominal_model
from flexff.learning.casadi_torch import TorchFunction, frozen

Parameters = Mapping[str, float]  # flat nominal-model parameters replaced in the prior


def rigid_function(parameters: Parameters | None = None) -> ca.Function:
    """CasADi Function (pos, vel, acc) -> F [N] of the nominal model, its parameters (with
    `parameters` in place) built in."""
    return _frozen_inverse_dynamics(tuple(sorted((parameters or {}).items())))


@functools.cache
def _frozen_inverse_dynamics(parameters: tuple[tuple[str, float], ...]) -> ca.Function:
    model = nominal_model()
    return frozen(model.inverse_dynamics, [3], [model.parameter_values(**dict(parameters))])


def rigid_forces(features: np.ndarray, feature_set: str,
                 parameters: Parameters | None = None) -> np.ndarray:
    """F_prior (n, 2) [N] for features (n, n_features) in SI units."""
    pos, vel, acc = motion_columns(feature_set)
    return evaluate_samples(rigid_function(parameters), features[:, pos], features[:, vel],
                            features[:, acc])


def rigid_currents(features: np.ndarray, feature_set: str) -> np.ndarray:
    """The nominal rigid-body force as motor currents (n, 3) [A]: allocated at the features'
    position as the controller allocates (controllers.allocation), the baseline of a
    current-level model."""
    pos, vel, acc = motion_columns(feature_set)
    return evaluate_samples(_allocated(), features[:, pos], features[:, vel], features[:, acc])


@functools.cache
def _allocated() -> ca.Function:
    position, velocity, acceleration = (ca.SX.sym(n, 2) for n in ("pos", "vel", "acc"))
    force = rigid_function()(position, velocity, acceleration)
    return ca.Function("rigid_currents", [position, velocity, acceleration],
                       [motor_currents(force, position)])


class RigidBodyForce(nn.Module):
    """Torch module: SI features (..., n_features) -> F_prior (..., 2) [N]."""

    def __init__(self, feature_set: str, parameters: Parameters | None = None) -> None:
        super().__init__()
        self.columns = motion_columns(feature_set)
        self.function = TorchFunction(rigid_function(parameters))

    def forward(self, features: torch.Tensor) -> torch.Tensor:
        pos, vel, acc = (features[..., cols] for cols in self.columns)
        return self.function(pos, vel, acc)[0]
