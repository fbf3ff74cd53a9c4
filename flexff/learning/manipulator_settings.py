"""The manipulator's training settings: the generic training configuration (learning.presets)
and the preprocessing of its dataset (learning.features.FeatureConfig), made from a preset and
overrides by name, and run.json's `config` record of both, laid out as runs have always held it.
"""

from __future__ import annotations

import dataclasses
from dataclasses import replace
from typing import Any

from flexff.fmu.errors import InputError
from flexff.learning.features import PRESET_FEATURES, FeatureConfig, feature_record
from flexff.learning.models import uses_prior
from flexff.learning.presets import TrainConfig, make_config

FEATURE_SETTINGS = tuple(f.name for f in dataclasses.fields(FeatureConfig))


def manipulator_settings(model: str, preset: str, **overrides: Any
                         ) -> tuple[TrainConfig, FeatureConfig]:
    """The preset's training configuration and preprocessing for `model`, with overrides by
    name: a FeatureConfig field (`feature_set="compact"`, `model_rate_hz=200`,
    `labels="currents"`), else as learning.presets.make_config (`epochs=5`, `hidden=50`)."""
    feature_overrides = {k: v for k, v in overrides.items() if k in FEATURE_SETTINGS}
    config = make_config(model, preset, FEATURE_SETTINGS,
                         **{k: v for k, v in overrides.items() if k not in FEATURE_SETTINGS})
    if uses_prior(model) and feature_overrides.get("force_input"):
        raise InputError(f"force_input is for the black-box networks: the {model} model has the "
                         f"identified rigid-body force as its prior already")
    return config, replace(PRESET_FEATURES[preset], **feature_overrides)


def config_record(config: TrainConfig, features: FeatureConfig, learned: bool = False
                  ) -> dict[str, Any]:
    """run.json's `config` of a run of `config` on data preprocessed by `features`
    (TrainConfig.record, learning.features.feature_record)."""
    return config.record(feature_record(features, config.edge_periods), learned)
