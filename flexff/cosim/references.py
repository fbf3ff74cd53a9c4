"""A run's [reference]: its kinds, sampled once on the communication grid.

The kinds of cosim.axis_references (AXIS_KINDS) make a reference for the axes of a run's
[machine], any number of them. Machine packages register kinds of their own
(register_reference_kind, through their entry point of cosim.plugins.GROUP): each checks its
table's keys, samples itself and documents its keys (cosim.config_keys). build_reference
samples any of them, once per process for the last few tables.
"""

from __future__ import annotations

import json
from collections import OrderedDict
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any, Protocol

import numpy as np

from flexff.cosim.axis_references import AXIS_KINDS, build_axis_reference
from flexff.cosim.machine import Machine
from flexff.cosim.plugins import loaded
from flexff.fmu.errors import InputError

if TYPE_CHECKING:
    from flexff.cosim.checks import TableChecker
    from flexff.cosim.config_keys import Key

SAVGOL_ORDER = 3  # the polynomial a table's derivatives are fitted with (Savitzky-Golay)
SMOOTHING_WINDOW = 0.025  # s: the window they are fitted over, unless a configuration sets it


class Sampled(Protocol):
    """A sampled reference: times [s] and its signals by name, `positions` among them (held
    at rest after its end)."""

    @property
    def t(self) -> np.ndarray: ...

    @property
    def positions(self) -> tuple[str, ...]: ...

    @property
    def duration(self) -> float: ...

    def signals(self) -> dict[str, np.ndarray]: ...


class ReferenceKeyError(InputError):
    """A reference that cannot be built because of the value of its table's key `key`
    (`segments[2]`: the third of a list)."""

    def __init__(self, key: str, message: str) -> None:
        super().__init__(message)
        self.key = key


@dataclass(frozen=True)
class ReferenceKind:
    """A machine package's [reference] kind: `check` turns its table, keys included, into
    checked options (None: no keys beside `kind`); `build` samples it (options, step) ->
    Sampled; `keys` document its table's keys (cosim.config_keys: those of the tables
    `reference` and, for lists of tables, `reference.LIST[k]`)."""

    name: str
    build: Callable[[Mapping[str, Any], float], Sampled]
    check: Callable[[TableChecker, Mapping[str, Any]], dict[str, Any]] | None = None
    keys: tuple[Key, ...] = ()


_REFERENCE_KINDS: dict[str, ReferenceKind] = {}


def register_reference_kind(kind: ReferenceKind) -> None:
    """Make `kind.name` a [reference] kind (a machine package, through its entry point of
    cosim.plugins.GROUP)."""
    _REFERENCE_KINDS[kind.name] = kind


def reference_kinds() -> dict[str, ReferenceKind]:
    """The machine packages' [reference] kinds, their entry points loaded."""
    loaded()
    return dict(_REFERENCE_KINDS)


def reference_kind_names() -> tuple[str, ...]:
    """Every [reference] kind: the machine packages' (cosim.plugins), then AXIS_KINDS."""
    return (*reference_kinds(), *AXIS_KINDS)


def build_reference(kind: str, options: Mapping[str, Any], step: float,
                    machine: Machine | None = None) -> Sampled:
    """The reference of a checked [reference] table (cosim.config), sampled every `step`
    seconds from t = 0 (a kind of AXIS_KINDS for the axes of `machine`): once per process for
    the last few tables (the configuration's check and the run both ask for it; a reference
    is not changed by its users). A file among the options that changed since is read
    again."""
    stamps = {key: (value.stat().st_mtime_ns, value.stat().st_size)
              for key, value in options.items() if isinstance(value, Path) and value.is_file()}
    axes = None  # an axis reference's axes, limits included
    if kind in AXIS_KINDS and machine is not None:
        axes = [(a.name, a.limits) for a in machine.axes]
    key = json.dumps({"kind": kind, "options": options, "step": step, "files": stamps,
                      "axes": axes}, sort_keys=True, default=str)
    if key not in _SAMPLED:
        reference = (build_axis_reference(kind, options, step, machine)
                     if kind in AXIS_KINDS else _registered(kind).build(options, step))
        for values in (reference.t, *reference.signals().values()):
            values.flags.writeable = False  # shared: nobody changes it in place
        _SAMPLED[key] = reference
        while len(_SAMPLED) > SAMPLED_KEPT:
            _SAMPLED.popitem(last=False)
    _SAMPLED.move_to_end(key)
    return _SAMPLED[key]


SAMPLED_KEPT = 4  # references kept sampled (a 100 s one at 1 kHz: 5.6 MB)
_SAMPLED: OrderedDict[str, Sampled] = OrderedDict()


def _registered(kind: str) -> ReferenceKind:
    found = reference_kinds().get(kind)
    if found is None:
        raise InputError(f"{kind!r} is no [reference] kind (known: "
                         f"{', '.join(reference_kind_names())})")
    return found
