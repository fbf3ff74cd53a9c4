"""Training for any machine: a machine's trajectories in, a run folder out, through the same
network, optimiser, checkpoints and run folder as the manipulator's (learning.train).

Features and labels come from learning.machine_features (its settings derived from the
training data where not given); the labels are each axis's effort, scaled to the training
span. run.json keeps the machine description and the resolved feature settings beside the
training configuration, so that export and the feedforward FMU compute the same features.
"""

from __future__ import annotations

import dataclasses
import json
import math
import time
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from flexff.cosim.machine import Machine, machine_table
from flexff.fmu.errors import InputError
from flexff.learning.batches import TRAIN, VALIDATION, SequenceSet
from flexff.learning.dataset_files import Trajectory
from flexff.learning.devices import pick_device
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
from flexff.learning.models import SequenceNetwork, uses_prior
from flexff.learning.presets import CHECKPOINT_EVERY, PLACEMENT, TrainConfig
from flexff.learning.rest_anchor import rest_anchor
from flexff.learning.run_folder import RUN_FILE, save_run, start_run
from flexff.learning.scaling import MinMaxScaler
from flexff.learning.train import (
    Checkpoints,
    EpochReport,
    fit_network,
    plot_losses,
    role_mse,
)

MSE_UNITS = "MSE of min-max scaled efforts, axis by axis (run.json label_names)"
# the FeatureConfig settings a machine's run reads; its features are MachineFeatures'
MACHINE_FEATURE_KEYS = ("edge_periods",)


def machine_config(config: TrainConfig, learned: bool = False) -> dict[str, Any]:
    """The training configuration as a machine's run.json holds it: its feature settings
    only those that apply (the manipulator's encoders, corner and noise do not), the
    PLACEMENT settings left out where `learned`."""
    data = config.learned_settings() if learned else json.loads(json.dumps(config.to_dict()))
    data["features"] = {k: data["features"][k] for k in MACHINE_FEATURE_KEYS}
    return data


def features_to_dict(features: MachineFeatures) -> dict[str, Any]:
    """The settings as JSON data (run.json)."""
    plain: dict[str, Any] = json.loads(json.dumps(dataclasses.asdict(features)))
    return plain


def features_from_dict(data: Mapping[str, Any]) -> MachineFeatures:
    return MachineFeatures(**{**data, "direction_widths": tuple(data["direction_widths"])})


def fit_machine(config: TrainConfig, machine: Machine, rate_hz: float,
                trajectories: Sequence[Trajectory], digest: str, out: Path,
                features: MachineFeatures | None = None, progress: bool = True,
                resume: bool | None = None, force: bool = True,
                checkpoint_every: int | None = None, on_epoch: EpochReport | None = None,
                prior: LinearModel | None = None, reuse: bool = False) -> dict[str, Any]:
    """Train `config`'s model on a machine's trajectories (`digest` names the data) with the
    feature settings `features` (default: all derived from the data); write the run folder
    `out`; return the metrics. The physics-guided model learns the residual over `prior`, the
    machine's identified linear model (learning.machine_identify.identify_dataset), its efforts
    through the labels' filter as the labels are. With `reuse`, a run finished in `out` with
    the same settings and data is kept (an interrupted evaluation resumes)."""
    start = time.perf_counter()
    pick_device(config.device)  # before any work: a device that is not there fails now
    if uses_prior(config.model) != (prior is not None):
        raise InputError(f"{config.model}: the physics-guided model (pgnn) and only it learns "
                         f"over an identified prior: give the prior for pgnn, none for others")
    every = CHECKPOINT_EVERY[config.preset] if checkpoint_every is None else checkpoint_every
    train_set = [t for t in trajectories if t.split == "train"]
    test_set = [t for t in trajectories if t.split == "test"]
    for split, chosen in (("train", train_set), ("test", test_set)):
        if not chosen:
            raise InputError(f"the '{split}' split is empty: mark some trajectories "
                             f"'{split}' (flexff data import --test, or the excitation's split)")
    given = features or MachineFeatures.of(machine)
    resolved = given.resolved(rate_hz, [t.signals for t in train_set], machine)
    settings = {"config": machine_config(config, learned=True),
                "features": features_to_dict(resolved), "machine": machine_table(machine),
                "data": digest, "prior": None if prior is None else prior.to_dict()}
    if reuse and _finished_alike(out, settings):
        return {**json.loads((out / "metrics.json").read_text()), "run": str(out)}
    checkpoint = start_run(out, json.loads(json.dumps(settings)), resume, force)
    rng = np.random.default_rng(config.seed)
    train_x, train_f = _prepared(train_set, rate_hz, machine, resolved, rng)
    test_x, test_f = _prepared(test_set, rate_hz, machine, resolved, None)
    feature_scaler, label_scaler = MinMaxScaler.fit(train_x), MinMaxScaler.fit(train_f)
    train_prior = prior_efforts(prior, train_set, rate_hz, machine, resolved)
    test_prior = prior_efforts(prior, test_set, rate_hz, machine, resolved)

    def targets(fs: list[np.ndarray], priors: list[np.ndarray] | None) -> list[np.ndarray]:
        if priors is None:
            return [label_scaler.transform(f) for f in fs]
        return [(f - p) / label_scaler.span for f, p in zip(fs, priors)]
    assert resolved.model_rate_hz is not None and resolved.cutoff_hz is not None
    model_rate = resolved.model_rate_hz
    edge = math.ceil(config.features.edge_periods / resolved.cutoff_hz * model_rate)

    def measure(network: SequenceNetwork, train_data: SequenceSet, test_data: SequenceSet
                ) -> dict[str, Any]:
        return {"model": config.model, "preset": config.preset, "units": MSE_UNITS,
                "train_mse": role_mse(network, train_data, TRAIN),
                "val_mse": role_mse(network, train_data, VALIDATION),
                "test_mse": role_mse(network, test_data, TRAIN),
                "test_mse_per_trajectory": {t.name: role_mse(network, test_data, TRAIN, only=[i])
                                            for i, t in enumerate(test_set)},
                **({} if test_prior is None else {"prior_test_mse": float(np.mean(
                    np.concatenate([((f - p) / label_scaler.span)[edge:len(f) - edge]
                                    for f, p in zip(test_f, test_prior)]) ** 2))})}

    network, history, metrics = fit_network(
        config, [feature_scaler.transform(x) for x in train_x],
        targets(train_f, train_prior), [feature_scaler.transform(x) for x in test_x],
        targets(test_f, test_prior), edge, rng, Checkpoints(out, settings, every), checkpoint,
        measure, progress, on_epoch,
        None if prior is None else [resting(t, rate_hz, machine, resolved) for t in train_set],
        select_residuals=True,
        anchor=rest_anchor(machine, resolved.inputs, feature_scaler.transform,
                           lambda efforts: targets([efforts], None if prior is None
                                                   else [np.zeros_like(efforts)])[0]))
    metrics = {**metrics, "seconds": time.perf_counter() - start, "model_rate_hz": model_rate,
               "cutoff_hz": resolved.cutoff_hz,
               "preprocessing": preprocessing(given, resolved, rate_hz)}
    save_run(out, config, network, feature_scaler, label_scaler,
             feature_names(machine, resolved.inputs), [a.effort_signal for a in machine.axes],
             model_rate,
             {"machine": machine_table(machine), "machine_features": features_to_dict(resolved),
              **({} if prior is None else {"machine_prior": prior.to_dict()}),
              "data": {"sha256": digest, "sample_rate_hz": rate_hz,
                       "train": [t.name for t in train_set],
                       "test": [t.name for t in test_set]},
              "parameters": metrics["parameters"]},
             {"metrics.json": lambda path: path.write_text(json.dumps(metrics, indent=2) + "\n"),
              "loss.png": lambda path: plot_losses(history, path,
                                                   f"{config.model} ({config.preset}), "
                                                   f"{machine.name}")},
             machine_config(config))
    return {**metrics, "run": str(out)}


def _finished_alike(out: Path, settings: Mapping[str, Any]) -> bool:
    """Whether `out` holds a finished run (run.json, metrics.json) of these settings."""
    try:
        info = json.loads((out / RUN_FILE).read_text())
        json.loads((out / "metrics.json").read_text())
    except (OSError, ValueError):
        return False
    config = {k: v for k, v in info["config"].items() if k not in PLACEMENT}
    found = {"config": config, "features": info.get("machine_features"),
             "machine": info.get("machine"), "data": info.get("data", {}).get("sha256"),
             "prior": info.get("machine_prior")}
    return bool(found == json.loads(json.dumps(settings)))


def prior_efforts(prior: LinearModel | None, trajectories: list[Trajectory],
                   rate_hz: float, machine: Machine, features: MachineFeatures
                   ) -> list[np.ndarray] | None:
    """The prior's efforts along each trajectory's measured motion, through the labels'
    filter and decimation (what its labels are compared with); None without a prior."""
    if prior is None:
        return None
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
