"""Inverse models that machine packages register by name, for the learning filter of iterative
learning control (learning.ilc) on a loop whose description names one (`[machine.ilc] model`).

A model is a function (loop: RunConfig, recording of trial 0) -> CasADi Function
(position, velocity, acceleration per axis) -> effort per axis. It is registered as
"module:function" and imported only when an iteration runs, so that describing a machine loads
no model code. Registration goes through the entry points of cosim.plugins.
"""

from __future__ import annotations

import importlib
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

from flexff.cosim.plugins import loaded
from flexff.fmu.errors import InputError


@dataclass(frozen=True)
class InverseModelEntry:
    """A registered model: its "module:function" and one line on what it models."""

    target: str
    summary: str


_MODELS: dict[str, InverseModelEntry] = {}


def register_inverse_model(name: str, target: str, summary: str) -> None:
    """Make `[machine.ilc] model = "NAME"` use the function `target` ("module:function")."""
    _MODELS[name] = InverseModelEntry(target, summary)


def inverse_model_names() -> tuple[str, ...]:
    loaded()
    return tuple(_MODELS)


def inverse_model(name: str) -> Callable[..., Any]:
    """The registered model `name`, imported; InputError naming the known ones."""
    loaded()
    entry = _MODELS.get(name)
    if entry is None:
        raise InputError(f"no inverse model {name!r} is registered (known: "
                         f"{', '.join(_MODELS) or 'none'})")
    module, _, function = entry.target.partition(":")
    model: Callable[..., Any] = getattr(importlib.import_module(module), function)
    return model
