"""Helpers shared by the tests."""

from pathlib import Path

import numpy as np

REPOSITORY = Path(__file__).resolve().parents[1]
# the Modelica Reference-FMUs, kept in the repository (README.md and LICENSE.txt beside them)
REFERENCE_FMUS = REPOSITORY / "cosim" / "examples" / "reference-fmus"


def workspace_points(rng: np.random.Generator, n: int, radius: float = 0.05) -> np.ndarray:
    """n points spread over the workspace disc, its boundary included (2 x n)."""
    r = radius * np.sqrt(rng.uniform(0, 1, n))
    r[: max(1, n // 8)] = radius  # always test the edge
    a = rng.uniform(-np.pi, np.pi, n)
    return np.vstack([r * np.cos(a), r * np.sin(a)])


def simulate(model, x0, params, times, current=(0.0, 0.0, 0.0), rtol=1e-12, atol=1e-14):
    """Tight-tolerance reference solution (CVODES, BDF/Newton) of the plant ODE at `times`."""
    import casadi as ca

    x = ca.SX.sym("x", model.n_states)
    ode = {"x": x, "ode": model.forward_dynamics(x, ca.DM(current), ca.DM(params))}
    solver = ca.integrator("reference", "cvodes", ode, float(times[0]), list(times[1:]),
                           {"abstol": atol, "reltol": rtol, "max_num_steps": 10**7})
    result = np.array(solver(x0=x0)["xf"])
    return np.column_stack([np.asarray(x0, dtype=float), result])
