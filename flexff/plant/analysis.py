"""Linear analysis at the workspace centre and the summary `flexff plant info` prints."""

from __future__ import annotations

from typing import Any

import casadi as ca
import numpy as np

from flexff.plant.model import PlantModel
from flexff.plant.variants import Variant, get_variant

FRICTION_FREE = {f"tau_coulomb{i}": 0.0 for i in (1, 2, 3)}


def linearization(model: PlantModel, params: np.ndarray) -> np.ndarray:
    """State matrix d(xdot)/dx at rest at the centre with zero currents."""
    x, i = ca.SX.sym("x", model.n_states), ca.SX.sym("i", 3)
    jac = ca.Function("state_matrix", [x, i, model.p],
                      [ca.jacobian(model.forward_dynamics(x, i, model.p), x)])
    x0 = model.initial_state([0.0, 0.0], params)
    return np.array(jac(x0, [0.0, 0.0, 0.0], params))


def modes(model: PlantModel, params: np.ndarray) -> list[tuple[float, float, np.ndarray]]:
    """Vibration modes at the centre: (natural frequency [Hz], damping ratio, eigenvector).

    Coulomb friction is left out: its smooth tanh would act as a large viscous term at rest.
    Sorted by frequency; one entry per complex-conjugate pair.
    """
    names = model.variant.parameters.names()
    params = np.array(params, dtype=float)
    for name, value in FRICTION_FREE.items():
        params[names.index(name)] = value
    values, vectors = np.linalg.eig(linearization(model, params))
    result = [(abs(lam) / (2 * np.pi), -lam.real / abs(lam), vectors[:, k])
              for k, lam in enumerate(values) if lam.imag > 0]
    return sorted(result, key=lambda m: m[0])


def plant_info(variant: Variant | str = "nominal") -> dict[str, Any]:
    """Parameters with units, natural frequencies at the centre and workspace of a variant."""
    variant = get_variant(variant) if isinstance(variant, str) else variant
    model = PlantModel(variant)
    found = modes(model, model.parameter_values())
    return {
        "variant": variant.name,
        "parasitic_mode": variant.parasitic_mode,
        "states": model.state_names,
        "workspace_radius_m": float(variant.parameters.workspace_radius),
        "natural_frequencies_hz": [round(float(f), 6) for f, _, _ in found],
        "damping_ratios": [round(float(z), 6) for _, z, _ in found],
        "parameters": [
            {"name": n, "value": float(v), "unit": u, "description": d}
            for n, v, u, d, _ in variant.parameters.describe()],
    }
