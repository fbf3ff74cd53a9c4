"""Value references and FMI attributes of every variable of a System's FMU.

The layout is decided here once, so that the generated config.h (C side) and
modelDescription.xml (importer side) cannot disagree. Real value references come in contiguous
blocks, in this order: parameters, `max_substep` (continuous systems only), inputs, outputs,
states; the Integer `seed` follows the last Real, and FMI 3.0's `time` the seed. Importers
should still look variables up by name in modelDescription.xml.
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass
from typing import Literal

from flexff.fmu.errors import InputError
from flexff.fmu.system import Parameter, System, Variable

Role = Literal["parameter", "max_substep", "input", "output", "state", "seed"]
ROLES: tuple[Role, ...] = ("parameter", "max_substep", "input", "output", "state", "seed")
# (role, causality, variability, variable): one Real of the layout; None for max_substep
_Row = tuple[Role, str, str, Variable | None]


@dataclass(frozen=True)
class ScalarVariable:
    """One FMU variable with the attributes modelDescription.xml needs."""

    name: str
    value_reference: int
    role: Role
    type: Literal["Real", "Integer"]
    causality: str
    variability: str
    unit: str = ""
    description: str = ""
    start: float | int | None = None
    positive: bool = False


@dataclass(frozen=True)
class Layout:
    """All variables of one FMU, ordered by value reference."""

    variables: tuple[ScalarVariable, ...]

    def block(self, role: Role) -> tuple[ScalarVariable, ...]:
        """The variables of one role, in value-reference order."""
        return tuple(v for v in self.variables if v.role == role)

    def first_vr(self, role: Role) -> int:
        """Value reference where the block of `role` starts (even if the block is empty)."""
        vr = 0
        for r in ROLES:
            if r == role:
                return vr
            vr += len(self.block(r))
        raise ValueError(f"unknown role {role!r}")

    @property
    def n_real(self) -> int:
        return sum(v.type == "Real" for v in self.variables)


def time_value_reference(layout: Layout) -> int:
    """The value reference of FMI 3.0's independent variable `time`, after the `seed`."""
    return layout.block("seed")[0].value_reference + 1


def clock_value_references(layout: Layout) -> tuple[int, int]:
    """The value references of an FMI 3.0 network task's clocks, the step's and the network's
    (fmu.model_description3), after `time`."""
    time = time_value_reference(layout)
    return time + 1, time + 2


def model_identifier(system: System) -> str:
    """A C identifier (and file name) derived from the system's name."""
    ident = re.sub(r"\W", "_", system.name, flags=re.ASCII)
    return ident if ident and not ident[0].isdigit() else f"_{ident}"


def make_layout(system: System) -> Layout:
    """Assign value references and FMI attributes; reject duplicate names and bad starts."""
    if system.kind not in ("continuous", "discrete"):
        raise ValueError(f"system kind must be 'continuous' or 'discrete', not {system.kind!r}")
    discrete = system.kind == "discrete"
    if discrete and not (system.sample_time is not None and system.sample_time > 0):
        raise ValueError("a discrete system needs a positive sample_time")
    if not discrete and not (system.max_substep > 0 and math.isfinite(system.max_substep)):
        raise ValueError("max_substep must be positive and finite")
    if system.n_noise < 0:
        raise ValueError("n_noise must be >= 0")

    time_kind = "discrete" if discrete else "continuous"
    substep: list[_Row] = [] if discrete else [("max_substep", "parameter", "tunable", None)]
    rows: list[_Row] = [
        *(("parameter", "parameter", "tunable", p) for p in system.parameters),
        *substep,
        *(("input", "input", "continuous", u) for u in system.inputs),
        *(("output", "output", "continuous", y) for y in system.outputs),
        *(("state", "local", time_kind, x) for x in system.states),
    ]
    variables = []
    for vr, (role, causality, variability, var) in enumerate(rows):
        if var is None:  # the max_substep row
            variables.append(ScalarVariable(
                "max_substep", vr, role, "Real", causality, variability, unit="s",
                description="largest RK4 sub-step inside one communication step",
                start=float(system.max_substep), positive=True))
            continue
        if role == "parameter" and isinstance(var, Parameter) and var.fixed:
            variability = "fixed"
        has_start = role in ("parameter", "input")
        if has_start and not math.isfinite(var.start):
            raise ValueError(f"start value of {var.name!r} must be finite")
        variables.append(ScalarVariable(
            var.name, vr, role, "Real", causality, variability, unit=var.unit,
            description=var.description, start=float(var.start) if has_start else None,
            positive=getattr(var, "positive", False)))
    variables.append(ScalarVariable(
        "seed", len(rows), "seed", "Integer", "parameter", "fixed",
        description="seed of the noise generator, applied at fmi2ExitInitializationMode",
        start=0))

    names = [v.name for v in variables]
    duplicates = sorted({n for n in names if names.count(n) > 1})
    if duplicates:
        raise InputError("variable names must be unique across parameters, inputs, outputs and "
                         f"states (max_substep and seed are reserved); duplicated: {duplicates}")
    if any(not n for n in names):
        raise ValueError("variable names must not be empty")
    return Layout(tuple(variables))
