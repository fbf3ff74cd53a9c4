"""The manipulator's training data: a dataset folder's trajectories (learning.dataset) as
features of the encoders' motion and force or current labels (learning.features), the
rigid-body model identified on the training split (learning.identify) as the physics-guided
model's prior or a black-box network's force inputs, the nominal one as the baseline to beat.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np

from flexff.controllers.features import FORCE_INPUTS, feature_names
from flexff.learning.dataset import Dataset, DatasetError, Trajectory, load_dataset
from flexff.learning.features import LABELS, FeatureConfig, filter_labels, prepare_trajectory
from flexff.learning.identify import identify_samples
from flexff.learning.manipulator_settings import config_record
from flexff.learning.models import uses_prior
from flexff.learning.presets import TrainConfig
from flexff.learning.rigid import rigid_forces
from flexff.learning.signal_processing import decimation
from flexff.learning.training_data import TrainingData

MSE_UNITS = ("MSE of min-max scaled labels, Fx, Fy or i1..i3 (run.json label_names; the "
             "thesis's normalized units)")


@dataclass(frozen=True)
class ManipulatorData:
    """The TrainingSource of the manipulator's dataset for `config`, preprocessed by
    `features`."""

    config: TrainConfig
    features: FeatureConfig
    dataset: Dataset

    @property
    def settings(self) -> dict[str, Any]:
        """The configuration and preprocessing (where it runs aside) and the data."""
        return {"config": config_record(self.config, self.features, learned=True),
                "data": self.dataset.digest}

    def prepare(self, rng: np.random.Generator) -> TrainingData:
        """Features and labels of both splits at the model rate, the prior's force (pgnn),
        the force inputs (force_input) and the nominal rigid-body model's force (the
        baseline)."""
        config, features, dataset = self.config, self.features, self.dataset
        train_set, test_set = _splits(dataset)
        rate_hz = dataset.sample_rate_hz
        model_rate = rate_hz / decimation(rate_hz, features.model_rate_hz)
        train_x, train_f = _prepare(train_set, rate_hz, features, rng)
        test_x, test_f = _prepare(test_set, rate_hz, features, None)
        identified = _identified_parameters(config, features, dataset, model_rate)
        prior = identified if uses_prior(config.model) else None
        force_inputs = identified if features.force_input else None
        if force_inputs is not None:  # the identified force as the last inputs
            train_x, test_x = ([with_force_inputs(x, force_inputs, features, model_rate)
                                for x in xs] for xs in (train_x, test_x))
        priors = None if prior is None else (
            [prior_labels(x, prior, features, model_rate) for x in train_x],
            [prior_labels(x, prior, features, model_rate) for x in test_x])
        return TrainingData(
            train_x, train_f, test_x, test_f, [t.name for t in test_set], priors,
            resting=None, select_residuals=False, anchor=None,
            edge=config.edge_samples(features.cutoff_hz, model_rate),
            skip=_skip_columns(features), model_rate_hz=model_rate,
            feature_names=feature_names(features.feature_set, force_inputs is not None),
            label_names=list(LABELS[features.labels]), units=MSE_UNITS,
            baselines={"rigid_body_test_mse": [
                rigid_forces(x, features.feature_set, None, features.labels) for x in test_x]},
            metrics={} if prior is None else {"prior_parameters": prior},
            preprocessing={},
            run_info={"data": {"path": str(Path(dataset.path).resolve()), "set": dataset.set,
                               "sha256": dataset.digest, "sample_rate_hz": rate_hz,
                               "plant": dict(dataset.plant),
                               "train": [t.name for t in train_set],
                               "test": [t.name for t in test_set]},
                      **({} if prior is None else {"prior_parameters": prior}),
                      **({} if force_inputs is None else {"force_input": force_inputs})},
            config_record=config_record(config, features),
            title=f"{config.model} ({config.preset})")


def _splits(dataset: Dataset) -> tuple[list[Trajectory], list[Trajectory]]:
    train_set, test_set = dataset.split("train"), dataset.split("test")
    for name, split in (("train", train_set), ("test", test_set)):
        if not split:
            raise DatasetError(f"{dataset.path}: the '{name}' split is empty; mark some "
                               f"trajectories '{name}' in manifest.json or collect more data")
    return train_set, test_set


def _prepare(trajectories: list[Trajectory], rate_hz: float, features: FeatureConfig,
             rng: np.random.Generator | None) -> tuple[list[np.ndarray], list[np.ndarray]]:
    pairs = [prepare_trajectory(t, rate_hz, features, rng) for t in trajectories]
    return [x for x, _ in pairs], [f for _, f in pairs]


def _skip_columns(features: FeatureConfig) -> slice:
    """The features a linear skip is fitted on: with force inputs those alone, so that the
    physics enters linearly through them and no least-squares weight on the collinear motion
    features, fitted to the labels' noise, extrapolates beyond the training range (hardware
    stand-in, the test split's geometric-mean e2 ratio x / y: TCN 233 / 201 and LSTM
    207 / 246 with the skip on the force inputs, 53 / 73 and 53 / 71 on every feature)."""
    return slice(-len(FORCE_INPUTS), None) if features.force_input else slice(None)


def _identified_parameters(config: TrainConfig, features: FeatureConfig, dataset: Dataset,
                           model_rate: float) -> dict[str, float] | None:
    """The physics-guided model's prior, or a black-box network's force inputs: the
    deployable parameters of the rigid-body model identified from the training trajectories
    (learning.identify: inertias, flexures, motor friction and torque constants), without the
    added training noise, so that runs of other seeds share it; None for a model with neither.
    It needs the motion alone: the compact features hold it, bit for bit as every other set
    does, and cost a fraction of the work."""
    if not (uses_prior(config.model) or features.force_input):
        return None
    motion = replace(features, labels="forces", feature_set="compact")
    return dict(_identified_prior(str(Path(dataset.path).resolve()), dataset.digest, motion,
                                  model_rate, config.edge_samples(features.cutoff_hz, model_rate)))


@functools.lru_cache(maxsize=2)
def _identified_prior(path: str, digest: str, features: FeatureConfig, model_rate: float,
                      edge: int) -> tuple[tuple[str, float], ...]:
    """_identified_parameters of the dataset folder `path` (whose content `digest` names), the
    `edge` samples at each end left out, once per process: an ensemble's members, trained one
    after another in a worker, share it (22 s of a physics-guided run's 55 s of data
    preparation on the hardware set)."""
    dataset = load_dataset(path)
    if dataset.digest != digest:
        raise DatasetError(f"{path} changed while training on it")
    identification = identify_samples(*_prepare(dataset.split("train"),
                                                dataset.sample_rate_hz, features, None),
                                      features, model_rate, edge)
    return tuple(identification.parameters().items())


def with_force_inputs(features: np.ndarray, parameters: dict[str, float], config: FeatureConfig,
                      rate_hz: float) -> np.ndarray:
    """A network's training inputs with force_input: the features (n, k) of one trajectory at
    `rate_hz` and, after them, the force of the rigid-body model of `parameters` along their
    motion (n, k + 2), through the labels' filter where `config.filtered_prior` says so.

    Filtered, the force input steps at a motor reversal as the labels do, smoothed, and the
    network learns to pass it on (its linear skip, fitted first, takes it about 1:1); the
    deployed feedforward computes it from the reference, unfiltered, and so passes the sharp
    step on, as the physics-guided model's prior does (prior_labels)."""
    force = prior_labels(features, parameters, replace(config, labels="forces"), rate_hz)
    return np.hstack([features, force])


def prior_labels(features: np.ndarray, parameters: dict[str, float], config: FeatureConfig,
                 rate_hz: float) -> np.ndarray:
    """What the physics-guided network's labels subtract: the prior's force (or currents)
    along the features of one trajectory at `rate_hz`, through the labels' own filter where
    `config.filtered_prior` says so (the default).

    The labels are the applied force low-passed; the prior is evaluated on the low-passed
    motion. Those differ where the force is not smooth: at each motor reversal the Coulomb
    friction steps, and the labels hold the step smoothed over a second while the prior
    steps within milliseconds. Their difference taught the network a wiggle at every reversal
    that the deployed prior, stepping at 1 kHz, does not need (hardware stand-in, evaluation
    reference: 4 mN peaks at the three motors' reversals, the closed loop ringing after each
    at 1.2 Hz, e2 x 118 against 158 for the prior alone). Filtered alike, the steps cancel
    and the residual holds what the prior lacks: e2 237 / 135 against 118 / 107 (3 seeds,
    flexff evaluate --env hardware)."""
    prior = rigid_forces(features, config.feature_set, parameters, config.labels)
    return filter_labels(prior, rate_hz, config) if config.filtered_prior else prior
