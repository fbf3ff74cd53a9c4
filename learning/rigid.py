"""The rigid-body prior of the physics-guided model: eq. (2.4) on the nominal plant.

F_rigid = M a + C v + Q + D from the wrist position, velocity and acceleration held in the
features. It is fixed (nothing in it is trained): the network beside it learns only the
remainder F - F_rigid, the epsilon of eq. (2.5). Evaluated in numpy (CasADi, float64) when
preparing training data and as a torch module (the same CasADi expression replayed op by op)
inside the exported model.
"""

from __future__ import annotations

import functools

import casadi as ca
import numpy as np
import torch
from torch import nn

from controllers.features import motion_columns, nominal_model
from learning.casadi_torch import TorchFunction, frozen


@functools.lru_cache(maxsize=None)
def rigid_function() -> ca.Function:
    """CasADi Function (pos, vel, acc) -> F [N] of the nominal model, parameters built in."""
    model = nominal_model()
    return frozen(model.inverse_dynamics, [3], [model.parameter_values()])


def rigid_forces(features: np.ndarray, feature_set: str) -> np.ndarray:
    """F_rigid (n, 2) [N] for features (n, n_features) in SI units."""
    pos, vel, acc = motion_columns(feature_set)
    function = rigid_function()
    n = features.shape[0]
    out = function.map(n, "thread", 2)(features[:, pos].T, features[:, vel].T, features[:, acc].T)
    return np.asarray(out, dtype=float).T.reshape(n, 2)


class RigidBodyForce(nn.Module):
    """Torch module: SI features (..., n_features) -> F_rigid (..., 2) [N]."""

    def __init__(self, feature_set: str) -> None:
        super().__init__()
        self.columns = motion_columns(feature_set)
        self.function = TorchFunction(rigid_function())

    def forward(self, features: torch.Tensor) -> torch.Tensor:
        pos, vel, acc = (features[..., cols] for cols in self.columns)
        return self.function(pos, vel, acc)[0]
