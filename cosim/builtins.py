"""Built-in FMUs registered by name: what a machine package gives a run configuration's
`[fmu.NAME] builtin = "..."` beside the manipulator's own (cosim.schema.BUILTIN_OPTIONS).

A built-in is a name, its option keys and a factory (options, step) -> fmu.system.System that
fmu.build turns into an FMU when a run resolves, given as "module:function" and imported only
then (a run of FMUs by path pays for no CasADi). Packages register theirs through the entry
point group `flexff.builtins` (a light function that calls `register_builtin`; flexff's own
loop blocks and example machines do so in pyproject.toml), loaded on first look-up of a
built-in; a script may call `register_builtin` itself, with a function or its path.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass
from importlib import import_module
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
    factory: Factory | str  # or "module:function"
    description: str = ""

    def system(self, options: Mapping[str, Any], step: float) -> System:
        factory = self.factory
        if isinstance(factory, str):
            module, _, function = factory.partition(":")
            factory = getattr(import_module(module), function)
        return factory(options, step)


_REGISTRY: dict[str, Builtin] = {}
_LOADED: list[bool] = []


def register_builtin(name: str, options: tuple[str, ...], factory: Factory | str,
                     description: str = "") -> None:
    """Make `name` a built-in FMU of run configurations."""
    _REGISTRY[name] = Builtin(name, options, factory, description)


def registered() -> dict[str, Builtin]:
    """Every registered built-in, the entry points' loaded on the first call."""
    if not _LOADED:
        _LOADED.append(True)
        for point in entry_points(group=GROUP):
            point.load()()
    return dict(_REGISTRY)
