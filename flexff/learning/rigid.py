"""The prior of the physics-guided model: eq. (2.4) with identified parameters.

F_prior = M a + C v + Q + D - A^T tau_friction from the wrist position, velocity and
acceleration held in the features, the nominal model's inverse dynamics with some of its
parameters replaced (`parameters`: flat plant parameter names, the rigid-body model identified
from the training data by learning.identify; none: the nominal model, which has no friction).
Nothing in it is trained by gradient descent: the network beside it learns only the remainder
F - F_prior, the epsilon of eq. (2.5). Evaluated in numpy (CasADi, float64) when preparing
training data and as a torch module (the same CasADi expression replayed op by op) inside
the exported model. A current-level pgnn's prior is that force as the motor currents the
controller would allocate for it.
"""

from __future__ import annotations

import functools
from collections.abc import Mapping

import casadi as ca
import numpy as np
import torch
from torch import nn

from flexff.controllers.allocation import motor_currents
from flexff.controllers.features import motion_columns, nominal_model
from flexff.learning.casadi_torch import TorchFunction, frozen
from flexff.learning.samples import evaluate_samples

Parameters = Mapping[str, float]  # flat nominal-model parameters replaced in the prior


def rigid_function(parameters: Parameters | None = None, labels: str = "forces"
                   ) -> ca.Function:
    """CasADi Function (pos, vel, acc) -> F [N] of the nominal model, its parameters (with
    `parameters` in place) built in; for `labels` = "currents" that force as motor currents
    [A], allocated at pos as the controller allocates (controllers.allocation): the prior of
    a current-level model."""
    return _frozen(tuple(sorted((parameters or {}).items())), labels)


@functools.cache
def _frozen(parameters: tuple[tuple[str, float], ...], labels: str) -> ca.Function:
    model = nominal_model()
    force = frozen(model.inverse_dynamics, [3], [model.parameter_values(**dict(parameters))])
    if labels == "forces":
        return force
    position, velocity, acceleration = (ca.SX.sym(n, 2) for n in ("pos", "vel", "acc"))
    return ca.Function("rigid_currents", [position, velocity, acceleration],
                       [motor_currents(force(position, velocity, acceleration), position)])


def rigid_forces(features: np.ndarray, feature_set: str, parameters: Parameters | None = None,
                 labels: str = "forces") -> np.ndarray:
    """F_prior (n, 2) [N] (`labels` = "currents": as motor currents, (n, 3) [A]) for features
    (n, n_features) in SI units."""
    pos, vel, acc = motion_columns(feature_set)
    return evaluate_samples(rigid_function(parameters, labels), features[:, pos],
                            features[:, vel], features[:, acc])


class RigidBodyForce(nn.Module):
    """Torch module: SI features (..., n_features) -> F_prior (..., 2) [N] (or as currents,
    (..., 3) [A])."""

    def __init__(self, feature_set: str, parameters: Parameters | None = None,
                 labels: str = "forces") -> None:
        super().__init__()
        self.columns = motion_columns(feature_set)
        self.function = TorchFunction(rigid_function(parameters, labels))

    def forward(self, features: torch.Tensor) -> torch.Tensor:
        pos, vel, acc = (features[..., cols] for cols in self.columns)
        return self.function(pos, vel, acc)[0]
