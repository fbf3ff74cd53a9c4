"""Does a reference stay where a learned feedforward was trained?

A network fed inputs outside its training range extrapolates, and a residual network can then
add forces many times the rigid-body force (measured: up to 1 N against 0.1 N when the hardware
models, trained on circles up to 0.29 Hz, ran the 1.8 Hz sim evaluation reference). The export
stores the range of every feature in the training data (metadata `feature_range`); this module
computes the features of a reference with the nominal kinematics, as the FMU does, at the
samples the FMU feeds the network (one per model period), and names those that leave that range
by more than MARGIN of its span.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from flexff.controllers.features import (
    FEATURE_SETS,
    feature_names,
    feature_units,
    reference_features,
)
from flexff.controllers.learned_feedforward import model_period
from flexff.fmu.defaults import DEFAULT_STEP
from flexff.fmu.errors import InputError
from flexff.learning.model_card import ModelCard, read_card
from flexff.plant.signals import REFERENCE, names

MARGIN = 0.1  # of a feature's training span: how far beyond it counts as extrapolating


@dataclass(frozen=True)
class RangeExcess:
    """One feature the reference drives outside the training range [low, high]."""

    signal: str
    unit: str
    low: float
    high: float
    reached_low: float
    reached_high: float
    spans: float  # how far beyond the range, in training spans
    fraction: float  # of the reference's samples outside [low, high]

    def describe(self) -> str:
        return (f"{self.signal} reaches [{self.reached_low:.4g}, {self.reached_high:.4g}] "
                f"{self.unit}, trained on [{self.low:.4g}, {self.high:.4g}] "
                f"({self.spans:.2g} spans beyond, {100 * self.fraction:.0f} % of samples)")


def training_range_excess(model: str | Path, reference: Mapping[str, np.ndarray],
                          step: float = DEFAULT_STEP) -> list[RangeExcess] | None:
    """The features of `model` that `reference` (sampled every `step` s from t = 0) drives more
    than MARGIN spans outside the training range, farthest first; None for a model exported
    without its range."""
    card = read_card(model)
    if card.feature_range is None:
        return None
    every = model_period(card, step, model)  # the FMU runs the network on every n-th sample
    signals, low, high = _trained_range(card, model)
    seen = {n: np.asarray(reference[n], dtype=float).ravel()[::every] for n in names(REFERENCE)}
    span = np.where(high > low, high - low, 1.0)
    features = reference_features(seen, card.feature_set, card.force_input)
    below, above = features.min(axis=0), features.max(axis=0)
    spans = np.maximum(low - below, above - high) / span
    outside = ((features < low) | (features > high)).mean(axis=0)
    units = feature_units(card.feature_set, card.force_input is not None)
    found = [RangeExcess(signals[k], units[k], float(low[k]), float(high[k]),
                         float(below[k]), float(above[k]), float(spans[k]), float(outside[k]))
             for k in np.flatnonzero(spans > MARGIN)]
    return sorted(found, key=lambda e: -e.spans)


def _trained_range(card: ModelCard, model: str | Path) -> tuple[list[str], np.ndarray, np.ndarray]:
    """The signals, lows and highs of the card's feature_range, one per feature of its set;
    InputError where the metadata does not hold that (it is not checked when the card is read:
    the range is this module's alone)."""
    if card.feature_set not in FEATURE_SETS:
        raise InputError(f"{model}: metadata feature_set {card.feature_set!r} is not one of "
                         f"{', '.join(FEATURE_SETS)}; export the model again with `flexff "
                         f"export`")
    n = len(feature_names(card.feature_set, card.force_input is not None))
    trained = card.feature_range
    signals: list[str] = []
    low = high = np.zeros(0)
    if isinstance(trained, dict):
        try:
            signals = [str(s) for s in trained["signals"]]
            low, high = (np.asarray(trained[k], dtype=float) for k in ("low", "high"))
        except (KeyError, TypeError, ValueError):
            pass  # refused below
    if not len(signals) == n or low.shape != (n,) or high.shape != (n,):
        raise InputError(f"{model}: metadata feature_range is not the range of the {n} features "
                         f"of the set {card.feature_set!r} ({{\"signals\", \"low\", \"high\"}}, "
                         f"{n} each); export the model again with `flexff export`")
    return signals, low, high
