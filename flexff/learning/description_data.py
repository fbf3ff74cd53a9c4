"""A [machine] description's training data: its trajectories as the features and labels of
learning.machine_features (their settings derived from the training data where not given),
the labels each axis's effort; the physics-guided model learns the residual over the
machine's identified linear model (learning.machine_identify.identify_dataset).

run.json keeps the machine description and the resolved feature settings beside the training
configuration, so that export and the feedforward FMU compute the same features.
"""

from __future__ import annotations

import dataclasses
import json
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from flexff.cosim.machine import Machine, machine_table
from flexff.fmu.errors import InputError
from flexff.learning.dataset_files import Trajectory
from flexff.learning.feature_spec import feature_names
from flexff.learning.linear_prior import LinearModel
from flexff.learning.machine_features import (
    MachineFeatures,
    label_filter,
    motion,
    named_motion,
    prepare,
    preprocessing,
)
from flexff.learning.models import uses_prior
from flexff.learning.presets import PLACEMENT, TrainConfig
from flexff.learning.rest_anchor import rest_anchor
from flexff.learning.run_folder import RUN_FILE
from flexff.learning.training_data import TrainingData

MSE_UNITS = "MSE of min-max scaled efforts, axis by axis (run.json label_names)"


def machine_config(config: TrainConfig, learned: bool = False) -> dict[str, Any]:
    """The training configuration as a machine's run.json holds it (TrainConfig.record): of
    feature settings edge_periods alone, the others are run.json's machine_features."""
    return config.record({"edge_periods": config.edge_periods}, learned)


def features_to_dict(features: MachineFeatures) -> dict[str, Any]:
    """The settings as JSON data (run.json)."""
    plain: dict[str, Any] = json.loads(json.dumps(dataclasses.asdict(features)))
    return plain


def features_from_dict(data: Mapping[str, Any]) -> MachineFeatures:
    return MachineFeatures(**{**data, "direction_widths": tuple(data["direction_widths"])})


@dataclass(frozen=True)
class DescriptionData:
    """The TrainingSource of a machine's trajectories for `config`: `given` the feature
    settings asked for, `features` those resolved on the training split; `prior` the
    identified linear model the physics-guided model (and only it) learns over."""

    config: TrainConfig
    machine: Machine
    rate_hz: float
    train_set: list[Trajectory]
    test_set: list[Trajectory]
    digest: str  # names the data
    given: MachineFeatures
    features: MachineFeatures
    prior: LinearModel | None

    @classmethod
    def of(cls, config: TrainConfig, machine: Machine, rate_hz: float,
           trajectories: Sequence[Trajectory], digest: str,
           features: MachineFeatures | None = None, prior: LinearModel | None = None
           ) -> DescriptionData:
        """The source with the feature settings `features` (default: all derived from the
        data), checked."""
        if uses_prior(config.model) != (prior is not None):
            raise InputError(f"{config.model}: the physics-guided model (pgnn) and only it "
                             f"learns over an identified prior: give the prior for pgnn, none "
                             f"for others")
        train_set = [t for t in trajectories if t.split == "train"]
        test_set = [t for t in trajectories if t.split == "test"]
        for split, chosen in (("train", train_set), ("test", test_set)):
            if not chosen:
                raise InputError(f"the '{split}' split is empty: mark some trajectories "
                                 f"'{split}' (flexff data import --test, or the excitation's "
                                 f"split)")
        given = features or MachineFeatures.of(machine)
        resolved = given.resolved(rate_hz, [t.signals for t in train_set], machine)
        return cls(config, machine, rate_hz, train_set, test_set, digest, given, resolved,
                   prior)

    @property
    def settings(self) -> dict[str, Any]:
        """The configuration (where it runs aside), features, machine, data and prior."""
        settings = {"config": machine_config(self.config, learned=True),
                    "features": features_to_dict(self.features),
                    "machine": machine_table(self.machine), "data": self.digest,
                    "prior": None if self.prior is None else self.prior.to_dict()}
        plain: dict[str, Any] = json.loads(json.dumps(settings))
        return plain

    def finished(self, out: Path) -> dict[str, Any] | None:
        """The metrics of a run of these settings finished in `out` (run.json and
        metrics.json there), else None: an interrupted evaluation keeps what it trained."""
        try:
            info = json.loads((out / RUN_FILE).read_text())
            metrics = json.loads((out / "metrics.json").read_text())
        except (OSError, ValueError):
            return None
        config = {k: v for k, v in info["config"].items() if k not in PLACEMENT}
        found = {"config": config, "features": info.get("machine_features"),
                 "machine": info.get("machine"), "data": info.get("data", {}).get("sha256"),
                 "prior": info.get("machine_prior")}
        return {**metrics, "run": str(out)} if found == self.settings else None

    def prepare(self, rng: np.random.Generator) -> TrainingData:
        """Features and efforts of both splits at the model rate; the prior's efforts and,
        where the labels are its residual, the resting samples."""
        config, machine, rate_hz = self.config, self.machine, self.rate_hz
        features = self.features
        assert features.model_rate_hz is not None and features.cutoff_hz is not None
        train_x, train_f = _prepared(self.train_set, rate_hz, machine, features, rng)
        test_x, test_f = _prepared(self.test_set, rate_hz, machine, features, None)
        prior = self.prior
        priors = None if prior is None else (
            prior_efforts(prior, self.train_set, rate_hz, machine, features),
            prior_efforts(prior, self.test_set, rate_hz, machine, features))
        model_rate = features.model_rate_hz
        return TrainingData(
            train_x, train_f, test_x, test_f, [t.name for t in self.test_set], priors,
            None if prior is None else [resting(t, rate_hz, machine, features)
                                        for t in self.train_set],
            select_residuals=True, anchor=rest_anchor(machine, features.inputs),
            edge=config.edge_samples(features.cutoff_hz, model_rate),
            skip=slice(None), model_rate_hz=model_rate,
            feature_names=feature_names(machine, features.inputs),
            label_names=[a.effort_signal for a in machine.axes], units=MSE_UNITS,
            baselines={}, metrics={},
            preprocessing={"cutoff_hz": features.cutoff_hz,
                           "preprocessing": preprocessing(self.given, features, rate_hz)},
            run_info={"machine": machine_table(machine),
                      "machine_features": features_to_dict(features),
                      **({} if prior is None else {"machine_prior": prior.to_dict()}),
                      "data": {"sha256": self.digest, "sample_rate_hz": rate_hz,
                               "train": [t.name for t in self.train_set],
                               "test": [t.name for t in self.test_set]}},
            config_record=machine_config(config),
            title=f"{config.model} ({config.preset}), {machine.name}")


def prior_efforts(prior: LinearModel, trajectories: list[Trajectory], rate_hz: float,
                  machine: Machine, features: MachineFeatures) -> list[np.ndarray]:
    """The prior's efforts along each trajectory's measured motion, through the labels'
    filter and decimation (what its labels are compared with)."""
    out = []
    for trajectory in trajectories:
        moved, _ = motion(trajectory.signals, rate_hz, machine, features)
        efforts = prior.predict(named_motion(moved, machine))
        out.append(label_filter(np.column_stack([efforts[a.name] for a in machine.axes]),
                                rate_hz, features))
    return out


def resting(trajectory: Trajectory, rate_hz: float, machine: Machine,
            features: MachineFeatures) -> np.ndarray:
    """Where every axis's reference rests (zero velocity), at the model rate: there the
    physics-guided model's residual is no label, the network's own continuation of the
    motion's residual to rest is kept. A loop's effort at rest is its controller settling the
    last move (a creep below the encoder's count against steep friction), not dynamics a
    feedforward should give: learned, it pushed the stage example from rest by 15 mN (e2
    1.79x its noise floor in y, 1.23x without). Trained to zero instead, the residual dropped
    what holds the machine at rest too (the rough drive's spring: the prior's e2 ratio 2.03,
    the pgnn's 1.76). Where one axis moves, the others' efforts may hold its coupling: they
    stay labels. All False for a trajectory without references (logs)."""
    names = [a.derivatives[0] for a in machine.axes]
    n = len(trajectory.signals[machine.axes[0].effort_signal])
    still = np.zeros(n, dtype=bool)
    if all(name in trajectory.signals for name in names):
        still = np.all([np.asarray(trajectory.signals[name]) == 0.0 for name in names], axis=0)
    return np.asarray(still[::features.decimation(rate_hz)])


def _prepared(trajectories: list[Trajectory], rate_hz: float, machine: Machine,
              features: MachineFeatures, rng: np.random.Generator | None
              ) -> tuple[list[np.ndarray], list[np.ndarray]]:
    pairs = [prepare(t.signals, rate_hz, machine, features, rng) for t in trajectories]
    return [x for x, _ in pairs], [f for _, f in pairs]
