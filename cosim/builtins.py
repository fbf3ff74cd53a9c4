"""Built-in FMUs registered by name: what a machine package gives a run configuration's
`[fmu.NAME] builtin = "..."` beside the manipulator's own (cosim.schema.BUILTIN_OPTIONS).

A built-in is a name, its option keys and a factory (options, step) -> fmu.system.System that
fmu.build turns into an FMU when a run resolves. Packages register theirs through the entry
point group `flexff.builtins` (a function that calls `register_builtin`; flexff's own loop
blocks and example machines do so in pyproject.toml), loaded on first look-up; a script may
call `register_builtin` itself.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass
from importlib.metadata import entry_points
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from flexff.fmu.system import System

GROUP = "flexff.builtins"
Factory = Callable[[Mapping[str, Any], float], "System"]


@dataclass(frozen=True)
class Builtin:
    """A registered built-in FMU: its option keys and the factory of its System."""

    name: str
    options: tuple[str, ...]
    system: Factory
    description: str = ""


_REGISTRY: dict[str, Builtin] = {}
_LOADED: list[bool] = []


def register_builtin(name: str, options: tuple[str, ...], system: Factory,
                     description: str = "") -> None:
    """Make `name` a built-in FMU of run configurations."""
    _REGISTRY[name] = Builtin(name, options, system, description)


def registered() -> dict[str, Builtin]:
    """Every registered built-in, the entry points' loaded on the first call."""
    if not _LOADED:
        _LOADED.append(True)
        for point in entry_points(group=GROUP):
            point.load()()
    return dict(_REGISTRY)
