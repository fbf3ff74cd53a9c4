"""What machine packages add to cosim beside built-in FMUs (cosim.builtins), and the loading of
the entry points (group `flexff.builtins`) through which they register it all.

  short forms       tables of their own (e.g. a [plant], [controller], [feedforward]) that
                    expand to FMUs and sources of the general form
  reference kinds   [reference] kinds of a machine, their keys checked and documented
                    (cosim.references.register_reference_kind)
  short names       recorded signals a run keeps under their short names too (cosim.run)
  inverse models    models for ILC's learning filter that a description names
                    (cosim.inverse_models.register_inverse_model)
  metrics warnings  a line on a run's metrics.json to show beside its result (a learned
                    feedforward that extrapolates), or None

Each entry point names a function without arguments that calls the `register_*` functions;
they are loaded once, the first time anything registered is looked up.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass
from importlib.metadata import entry_points
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from flexff.cosim.checks import TableChecker
    from flexff.cosim.schema import FmuConfig, SourceConfig

GROUP = "flexff.builtins"
# (checker, the configuration's tables, the reference's first point or None) -> FMUs, sources
Expander = Callable[["TableChecker", Mapping[str, Any], "tuple[float, ...] | None"],
                    "tuple[list[FmuConfig], list[SourceConfig]]"]
Describer = Callable[[], dict[str, Any]]  # -> the machine's [machine] table (cosim.machine)
MetricsWarning = Callable[[Mapping[str, Any]], "str | None"]  # metrics.json -> a line or None


@dataclass(frozen=True)
class ShortForm:
    """A machine's tables and their expansion; `default`: it also expands a configuration
    without [fmu.*] tables; `describe`: the machine description of the FMUs it expands to
    (a configuration's own [machine] table takes its place)."""

    name: str
    tables: tuple[str, ...]
    expand: Expander
    default: bool = False
    describe: Describer | None = None


_SHORT_FORMS: dict[str, ShortForm] = {}
_SHORT_NAMES: dict[str, None] = {}  # ordered, each once
_METRICS_WARNINGS: list[MetricsWarning] = []
_LOADED: list[bool] = []


def loaded() -> None:
    """Load the entry points of GROUP, once per process."""
    if _LOADED:
        return
    _LOADED.append(True)
    for point in entry_points(group=GROUP):
        point.load()()


def register_short_form(name: str, tables: tuple[str, ...], expand: Expander,
                        default: bool = False, describe: Describer | None = None) -> None:
    """Let the tables `tables` of a configuration expand (`expand`) to the general form, with
    the machine description `describe` gives."""
    _SHORT_FORMS[name] = ShortForm(name, tables, expand, default, describe)


def register_short_names(names: tuple[str, ...]) -> None:
    """Keep the recorded signals `names` under their short names too (cosim.run)."""
    _SHORT_NAMES.update(dict.fromkeys(names))


def register_metrics_warning(warning: MetricsWarning) -> None:
    """Show the line `warning` makes of a run's metrics beside its result (metrics_warnings)."""
    if warning not in _METRICS_WARNINGS:
        _METRICS_WARNINGS.append(warning)


def short_forms() -> tuple[ShortForm, ...]:
    loaded()
    return tuple(_SHORT_FORMS.values())


def short_names() -> tuple[str, ...]:
    loaded()
    return tuple(_SHORT_NAMES)


def metrics_warnings() -> tuple[MetricsWarning, ...]:
    loaded()
    return tuple(_METRICS_WARNINGS)
