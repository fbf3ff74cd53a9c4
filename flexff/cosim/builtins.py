"""Built-in FMUs registered by name: what a machine package gives a run configuration's
`[fmu.NAME] builtin = "..."` (the manipulator's plant, controller and feedforwards among them,
registered by controllers.manipulator).

A built-in is a name, its options (Option: kind, default, allowed values, a further check) and a
factory (options, step) -> fmu.system.System that fmu.build turns into an FMU when a run
resolves, a function or its "module:function" path, imported only then (a run of FMUs by path
pays for no CasADi); optionally a check of its `parameters`, options that are also start
values, the run's sampled sources as the factory's third argument, and entries it adds to
metrics.json. Packages register theirs through the entry point group `flexff.builtins`
(cosim.plugins: a light function that calls `register_builtin`, loaded on first look-up of a
built-in); a script may call `register_builtin` itself.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from importlib import import_module
from typing import TYPE_CHECKING, Any

from flexff.cosim.plugins import loaded
from flexff.fmu.errors import InputError

if TYPE_CHECKING:
    import numpy as np

    from flexff.cosim.checks import TableChecker
    from flexff.cosim.schema import FmuConfig
    from flexff.fmu.system import System

OPTION_KINDS = ("any", "number", "integer", "flag", "number-or-flag", "choice", "file")
Factory = Callable[..., "System"]  # (options, step), and the sources where reads_sources
# (checker, options, parameters, `fmu.NAME`, the reference's first point or None) -> the
# checked start values
ParameterCheck = Callable[["TableChecker", Mapping[str, Any], Mapping[str, Any], str,
                           "tuple[float, ...] | None"], dict[str, Any]]
# (the FMU's configuration, the sampled reference signals, step) -> entries of metrics.json
RunMetrics = Callable[["FmuConfig", Mapping[str, "np.ndarray"], float], Mapping[str, Any]]


class OptionError(InputError):
    """A bad option value, naming the `option` (a factory's or a check's; the run's error
    names `fmu.NAME.option`)."""

    def __init__(self, option: str, message: str) -> None:
        super().__init__(message)
        self.option = option


@dataclass(frozen=True)
class Option:
    """One option key of a built-in. `kind`: "any" (as given), "number", "integer", "flag"
    (true or false, kept only where true), "number-or-flag", "choice" (one of `choices`) or
    "file" (relative to the configuration, existing, ending in `suffix` if given). A value not
    given takes `default` (None: left out; `required`: an error); `check` may refuse a given
    value by raising ValueError."""

    key: str
    kind: str = "any"
    default: Any = None
    required: bool = False
    choices: tuple[Any, ...] = ()
    positive: bool = False
    suffix: str = ""
    check: Callable[[Any], object] | None = None

    def __post_init__(self) -> None:
        if self.kind not in OPTION_KINDS:
            raise ValueError(f"option {self.key!r}: kind {self.kind!r} is not one of "
                             f"{', '.join(OPTION_KINDS)}")


@dataclass(frozen=True)
class Builtin:
    """A registered built-in FMU (see the module's docstring)."""

    name: str
    options: tuple[Option, ...]
    factory: Factory | str  # or "module:function"
    description: str = ""
    parameters: ParameterCheck | None = None  # None: its parameters go to the FMU as given
    start_options: tuple[str, ...] = ()  # options the FMU also gets as start values
    reads_sources: bool = False  # the factory's third argument: the run's sampled sources
    metrics: RunMetrics | None = None

    @property
    def keys(self) -> tuple[str, ...]:
        return tuple(o.key for o in self.options)

    def system(self, options: Mapping[str, Any], step: float, sources: Mapping[str, Any]
               ) -> System:
        """The System of `options` at `step` (`sources`: the run's sampled source signals)."""
        factory = self.factory
        if isinstance(factory, str):
            module, _, function = factory.partition(":")
            factory = getattr(import_module(module), function)
        return factory(options, step, sources) if self.reads_sources else factory(options, step)


_REGISTRY: dict[str, Builtin] = {}


def register_builtin(name: str, options: Sequence[str | Option], factory: Factory | str,
                     description: str = "", *, parameters: ParameterCheck | None = None,
                     start_options: tuple[str, ...] = (), reads_sources: bool = False,
                     metrics: RunMetrics | None = None) -> None:
    """Make `name` a built-in FMU of run configurations (an option given by its key alone is
    taken as given; `factory` a function or its "module:function" path). Registering the same
    built-in again changes nothing; another one under a taken name is a ValueError.

    >>> api.register_builtin("my-drive", (), "flexff.machines.drive:drive_from_options",
    ...                      "the drive example's plant, under a name of my own")"""
    builtin = Builtin(name, tuple(o if isinstance(o, Option) else Option(o) for o in options),
                      factory, description, parameters, start_options, reads_sources, metrics)
    if _REGISTRY.get(name, builtin) != builtin:
        raise ValueError(f"a built-in FMU {name!r} is already registered")
    _REGISTRY[name] = builtin


def registered() -> dict[str, Builtin]:
    """Every registered built-in, the entry points' loaded on the first call."""
    loaded()
    return dict(_REGISTRY)


def checked_options(checker: TableChecker, builtin: Builtin, table: Mapping[str, Any],
                    where: str) -> dict[str, Any]:
    """The options of `builtin` in `table` (the keys of [`where`]) checked, defaults filled
    in, in the order the built-in declares them."""
    options = {}
    for option in builtin.options:
        value = _value(checker, option, table, where)
        if value is not None:
            options[option.key] = value
    return options


def _value(checker: TableChecker, o: Option, t: Mapping[str, Any], where: str) -> Any:
    key, c = f"{where}.{o.key}", checker
    if o.key not in t and not o.required:
        return o.default
    if o.kind == "number" or (o.kind == "number-or-flag" and not isinstance(t.get(o.key),
                                                                             bool)):
        value: Any = c.number(t, where, o.key, None, positive=o.positive)
    elif o.kind == "integer":
        value = c.integer(t, where, o.key, None)
        if value is None:
            raise c.error(key, "required")
    elif o.kind == "choice":
        value = c.choice(t, where, o.key, o.choices, None)
    elif o.kind == "file":
        value = c.path(t, where, o.key)
        if o.suffix and value.suffix.lower() != o.suffix:
            raise c.error(key, f"{value} is not an {o.suffix} file")
    elif o.kind in ("flag", "number-or-flag"):
        value = t.get(o.key)
        if not isinstance(value, bool):
            raise c.error(key, f"expected true or false, got {value!r}")
        if o.kind == "flag" and not value:
            return None
    else:
        value = t.get(o.key)
        if value is None:
            raise c.error(key, "required")
    if o.kind == "integer" and o.choices and value not in o.choices:
        raise c.error(key, f"must be one of {o.choices}, got {value}")
    if o.check is not None:
        try:
            o.check(value)
        except ValueError as error:
            raise c.error(key, str(error)) from None
    return value
