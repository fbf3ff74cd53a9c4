"""What training needs from a machine's data, whichever machine: the settings that identify a
run and, prepared from them, the inputs and labels at the model rate with what the run folder
records about them. `learning.train.fit` takes a `TrainingSource` and does all else once; the
sources are a [machine] description's (learning.description_data) and the manipulator's
dataset's (learning.manipulator_data).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Protocol

import numpy as np

from flexff.learning.rest_anchor import RestAnchor


@dataclass(frozen=True)
class TrainingData:
    """One run's prepared data: per trajectory (n, k) arrays at the model rate, unscaled."""

    train_x: list[np.ndarray]  # the network's inputs
    train_labels: list[np.ndarray]  # the efforts it learns, filtered as the motion is
    test_x: list[np.ndarray]
    test_labels: list[np.ndarray]
    test_names: list[str]  # metrics.json's test_mse_per_trajectory keys
    # the prior's efforts through the labels' filter where the model learns the residual over
    # it (the physics-guided model), else None: (training, test), as the labels are
    prior: tuple[list[np.ndarray], list[np.ndarray]] | None
    # per training trajectory, the samples whose residual is no label (learning.batches)
    resting: list[np.ndarray] | None
    select_residuals: bool  # an output whose residual does not help keeps its prior alone
    anchor: RestAnchor | None  # where the model is held at rest (learning.rest_anchor), unscaled
    edge: int  # samples at each end of a trajectory out of every loss
    skip: slice  # the inputs a linear skip is fitted on (learning.models.fit_linear_skip)
    model_rate_hz: float
    feature_names: list[str]
    label_names: list[str]
    units: str  # what the MSEs of metrics.json measure
    # metric name -> a baseline's test efforts (as test_labels), scored as the network is
    baselines: dict[str, list[np.ndarray]]
    metrics: dict[str, Any]  # more of metrics.json, after the baselines
    preprocessing: dict[str, Any]  # metrics.json's last entries: how the data was prepared
    run_info: dict[str, Any]  # run.json's entries about the data and the machine
    config_record: dict[str, Any]  # run.json's config (learning.presets.TrainConfig.record)
    title: str  # loss.png's


class TrainingSource(Protocol):
    """A machine's data for one training configuration."""

    @property
    def settings(self) -> dict[str, Any]:
        """What a checkpoint must share to be resumed (JSON data): checked before any work."""

    def prepare(self, rng: np.random.Generator) -> TrainingData:
        """The data, the training trajectories' noise drawn from `rng`."""
