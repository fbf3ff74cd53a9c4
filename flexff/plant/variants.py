"""The named plants (variants): which parameter values and whether the parasitic mode is
modelled. Apart from plant.model, so that a configuration or the command line can name and
check a variant without loading CasADi."""

from __future__ import annotations

from dataclasses import dataclass

from flexff.fmu.errors import InputError
from flexff.plant.parameters import HARDWARE, NOMINAL, PlantParameters


@dataclass(frozen=True)
class Variant:
    """A named plant: its true parameter values and whether the parasitic mode is modelled."""

    name: str
    parameters: PlantParameters
    parasitic_mode: bool


VARIANTS = {
    "nominal": Variant("nominal", NOMINAL, parasitic_mode=False),
    "hardware": Variant("hardware", HARDWARE, parasitic_mode=True),
}


def get_variant(name: str) -> Variant:
    """The variant called `name`, or an InputError listing the known ones."""
    try:
        return VARIANTS[name]
    except KeyError:
        raise InputError(
            f"unknown plant variant {name!r}: choose one of {', '.join(VARIANTS)}") from None
