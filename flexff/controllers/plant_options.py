"""The plant FMU's options a configuration may set (the built-in `plant` and the short form's
[plant] table alike): its parameters by variant and their physical checks."""

from __future__ import annotations

from collections.abc import Mapping
from typing import TYPE_CHECKING, Any

from flexff.plant.variants import VARIANTS

if TYPE_CHECKING:
    from flexff.cosim.checks import TableChecker

PLANT_EXTRA = ("max_substep",)  # plant FMU parameters beyond the System's own
START_PARAMETERS = ("x_start", "y_start")


def plant_parameter_names(variant: str) -> tuple[str, ...]:
    """The plant FMU's parameters of `variant` a configuration may set."""
    from flexff.plant.system import plant_parameters  # CasADi: manipulator runs only

    return (*(p.name for p in plant_parameters(variant)), *PLANT_EXTRA)


def checked_plant_parameters(checker: TableChecker, t: Mapping[str, Any], variant: str,
                             where: str, start: tuple[float, ...]) -> dict[str, float]:
    """Plant parameter values, checked physically; x_start, y_start default to `start`."""
    from flexff.plant.kinematics import check_workspace
    from flexff.plant.system import plant_parameters

    known = {p.name: p for p in plant_parameters(variant)}
    values = dict(zip(START_PARAMETERS, start))
    for key in t:
        positive = key in PLANT_EXTRA or known[key].positive
        values[key] = checker.number(t, where, key, None, positive=positive)
    physical = {k: v for k, v in values.items() if k not in (*START_PARAMETERS, *PLANT_EXTRA)}
    try:
        VARIANTS[variant].parameters.with_values(**physical)
        check_workspace(VARIANTS[variant].parameters, values["x_start"], values["y_start"],
                        "the start position (x_start, y_start)")
    except ValueError as error:
        keys = ", ".join(f"{where}.{k}" for k in t) or where
        raise checker.error(keys, str(error)) from None
    return values
