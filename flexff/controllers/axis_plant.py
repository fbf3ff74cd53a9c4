"""The manipulator's axis for loop shaping: at the workspace centre the nominal plant splits
into two equal mass-spring-damper axes P(s) = 1 / (m s^2 + d s + k) from end-effector force to
position (M, K and D are multiples of the identity by the three-fold symmetry)."""

from __future__ import annotations

import numpy as np

from flexff.blocks.loop_shaping import AxisPlant
from flexff.plant.analysis import linearization
from flexff.plant.model import PlantModel


def axis_plant(model: PlantModel | None = None, tolerance: float = 1e-9) -> AxisPlant:
    """Per-axis mass, damping and stiffness of the (nominal) plant at rest at the centre.

    Raises ValueError if M, K or D are not multiples of the identity there (relative tolerance).
    """
    model = model or PlantModel("nominal")
    p = model.parameter_values()
    mass = np.array(model.terms([0.0, 0.0], [0.0, 0.0], p)[0])
    state_matrix = linearization(model, p)[2:4, :4]
    stiffness, damping = -mass @ state_matrix[:, :2], -mass @ state_matrix[:, 2:4]
    for name, matrix in (("mass", mass), ("stiffness", stiffness), ("damping", damping)):
        if not np.allclose(matrix, matrix[0, 0] * np.eye(2), rtol=0,
                           atol=tolerance * abs(matrix[0, 0])):
            raise ValueError(f"the {name} matrix at the centre is not a multiple of the "
                             f"identity, so the axes do not decouple: {matrix.tolist()}")
    return AxisPlant(float(mass[0, 0]), float(damping[0, 0]), float(stiffness[0, 0]))
