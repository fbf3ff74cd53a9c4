"""The machine of the exported models that carry no machine description (a model card without
`machine`): what such a card means that it does not say itself, registered by that machine's
package through the entry points `flexff.builtins` (the thesis's manipulator, whose models
predate machine descriptions: controllers.manipulator).

learning.model_card takes from it the output sets a card may name, their default and the check
of the card's parameters; learning.export and learning.deploy the outputs and units of a label
level, the reference signals and the features a model computes from them.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import Any

from flexff.cosim.plugins import loaded
from flexff.fmu.errors import InputError
from flexff.fmu.system import Variable


@dataclass(frozen=True)
class ImplicitMachine:
    """`outputs`: label level ("forces") -> the signals a model of that level outputs, the first
    the outputs of a card that names none; `usage`: the card's usage text on those outputs, the
    inputs and the prior; `check_parameters`: refuses (TypeError or ValueError) a card's
    prior_parameters or force_input that are not the machine's; `reference`: the signals a
    model with input kind "reference" takes; `feature_units` (feature set, with force inputs)
    -> their units; `reference_features` (feature set, force_input) -> the CasADi Function of
    the reference that computes them."""

    outputs: Mapping[str, tuple[Variable, ...]]
    usage: str
    check_parameters: Callable[[Mapping[str, float]], object]
    reference: tuple[Variable, ...]
    feature_units: Callable[[str, bool], list[str]]
    reference_features: Callable[[str, Mapping[str, float] | None], Any]

    def output_level(self, signals: list[str]) -> str | None:
        """The label level whose outputs are `signals`, or None."""
        return next((level for level, outputs in self.outputs.items()
                     if [v.name for v in outputs] == signals), None)


_REGISTERED: list[ImplicitMachine] = []


def register_implicit_machine(machine: ImplicitMachine) -> None:
    """Make `machine` that of the models without a machine description; registering it again
    changes nothing, another one is a ValueError."""
    if _REGISTERED and _REGISTERED[0] != machine:
        raise ValueError("the machine of models without a machine description is already "
                         "registered")
    _REGISTERED[:] = [machine]


def implicit_machine() -> ImplicitMachine:
    """The registered machine of models without a machine description (the entry points
    loaded first); InputError if no package registers one."""
    loaded()
    if not _REGISTERED:
        raise InputError("no installed package registers the machine of models without a "
                         "machine description (entry points flexff.builtins); reinstall "
                         "flexff, or export the model from a machine's run")
    return _REGISTERED[0]
