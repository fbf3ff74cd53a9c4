"""Preprocessing made for ideal encoders, given a loop whose encoders count or are noisy.

The `sim` environment of `flexff evaluate` preprocesses for the nominal plant's ideal encoders
(learning.evaluate: the angles left as they are, a 5 Hz low-pass); the thesis's preprocessing
(`hardware`: angles counted in whole encoder counts, 1.8 Hz) is made for counted, noisy ones.
Given the `sim` settings, a loop whose plant counts its encoders or adds noise to them trains
on features full of the counts' steps and the noise, and measured silently worse: PID alone /
physics-guided e2 14x where the hardware settings give 60x. The plant says which it has: the
built-in plant's `encoder_quantization` and `noise_std` (its variant's values, or the loop's),
or the parameters of those names of a plant FMU by path.

Such a run is warned of, not refused: it is a legitimate question (how the sim preprocessing
fares on such a loop), and there is no other way to put the sim reference and set on it; the
warning names the effects and what to use instead.
"""

from __future__ import annotations

import warnings
from collections.abc import Mapping
from typing import Any

from flexff.cosim.schema import RunConfig
from flexff.fmu.importer import read_fmu
from flexff.learning.features import FeatureConfig
from flexff.plant.variants import VARIANTS

EFFECTS = ("encoder_quantization", "noise_std")  # plant parameters: 0 switches each off


class EncoderWarning(UserWarning):
    """Preprocessing for ideal encoders given a loop whose encoders are not."""


def effects_of(values: Mapping[str, Any]) -> dict[str, float]:
    """The encoder effects that are on among plant parameter `values` (name -> value)."""
    return {name: float(values[name]) for name in EFFECTS
            if isinstance(values.get(name), (int, float)) and float(values[name]) > 0}


def loop_encoders(loop: RunConfig) -> dict[str, float]:
    """The encoder effects of the loop's plant: the built-in one's (its variant's values
    with the loop's), or those a plant FMU by path has as parameters (start values with the
    loop's); {} for ideal encoders, or for a plant that does not say."""
    plant = loop.builtin("plant")
    if plant is not None:
        return effects_of({**_variant_values(plant.options["variant"]), **plant.parameters})
    found: dict[str, float] = {}
    for f in loop.fmus:
        if f.path is None:
            continue
        variables = read_fmu(f.path).variables
        if any(name in variables for name in EFFECTS):
            found |= effects_of({**{n: v.start for n, v in variables.items()}, **f.parameters})
    return found


def variant_encoders(variant: str) -> dict[str, float]:
    """The encoder effects of the built-in plant `variant` with its own values."""
    return effects_of(_variant_values(variant))


def _variant_values(variant: str) -> dict[str, float]:
    """The built-in plant `variant`'s own values of the EFFECTS parameters."""
    parameters = VARIANTS[variant].parameters
    return {name: getattr(parameters, name) for name in EFFECTS}


def describe(effects: Mapping[str, float]) -> str:
    """The effects in words, e.g. `encoder_quantization = 1, noise_std = 0.001`."""
    return ", ".join(f"{name} = {value:g}" for name, value in effects.items())


def warn_ideal_preprocessing(features: FeatureConfig, effects: Mapping[str, float],
                             what: str) -> str | None:
    """Warn (EncoderWarning) when `features` are made for ideal encoders (angles left
    uncounted) and `effects` say that `what` (a loop, a dataset) has counted or noisy ones;
    return the warning's text, or None."""
    if features.quantize_encoders or not effects:
        return None
    text = (f"{what} has encoders that count or are noisy ({describe(effects)}), but the "
            f"preprocessing is made for ideal ones (angles not counted, a "
            f"{features.cutoff_hz:g} Hz low-pass): the counts' steps and the noise reach the "
            f"features (measured on the hardware stand-in: e2 14x instead of 60x); use the "
            f"hardware settings (flexff evaluate --env hardware)")
    warnings.warn(text, EncoderWarning, stacklevel=2)
    return text


def warn_set_on_loop(set_name: str, variant: str, loop: RunConfig) -> str | None:
    """Warn (EncoderWarning) when the trajectory set `set_name`, made for the built-in plant
    `variant` with ideal encoders (and preprocessed for them by flexff evaluate --env
    `set_name`), is collected on a loop whose encoders count or are noisy; return the text."""
    effects = loop_encoders(loop)
    if variant_encoders(variant) or not effects:
        return None
    text = (f"the {set_name} set is made for the {variant} plant's ideal encoders, and "
            f"flexff evaluate --env {set_name} preprocesses it for them, but {loop.origin} "
            f"has encoders that count or are noisy ({describe(effects)}): the counts' steps "
            f"and the noise would reach the features (measured on the hardware stand-in: e2 "
            f"14x instead of 60x); collect the hardware set (--set hardware) for such a loop")
    warnings.warn(text, EncoderWarning, stacklevel=2)
    return text
