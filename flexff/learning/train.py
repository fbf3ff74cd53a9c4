"""Training: a dataset folder in, a run folder out (weights, run.json, metrics.json, loss.png).

Adam on the MSE of min-max-scaled labels (the thesis's normalized units; for the pgnn the
residual F - F_rigid divided by the same label span, which gives the same MSE, F_rigid through
the labels' filter: `prior_labels`), truncated
backpropagation through time for the recurrent networks, random windows for the convolutional
ones (`learning.batches`), the epoch with the lowest validation loss kept. Seeded: the same
configuration, data, device and thread count give the same weights.

Every few epochs a checkpoint (weights, optimizer, random generators, history and the best
weights so far) is written into the run folder, and the best weights whenever they improve
(`learning.run_folder`); a run interrupted (kill -9 included) resumes from its last checkpoint
to the same weights as one never interrupted.
"""

from __future__ import annotations

import copy
import functools
import json
import math
import os
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np
import torch
from tqdm import tqdm

from flexff.controllers.features import FORCE_INPUTS, feature_names
from flexff.fmu.errors import InputError, RunError
from flexff.learning.batches import (
    TRAIN,
    VALIDATION,
    SequenceSet,
    WindowSampler,
    interior,
    window_roles,
)
from flexff.learning.dataset import Dataset, DatasetError, Trajectory, load_dataset
from flexff.learning.devices import pick_device
from flexff.learning.features import (
    LABELS,
    FeatureConfig,
    decimation,
    filter_labels,
    prepare_trajectory,
)
from flexff.learning.identify import identify_samples
from flexff.learning.models import (
    RECURRENT,
    SequenceNetwork,
    build_network,
    fit_linear_skip,
    parameter_count,
    pin_at_rest,
    silence_outputs,
    uses_prior,
)
from flexff.learning.presets import CHECKPOINT_EVERY, TrainConfig, make_config
from flexff.learning.rest_anchor import RestAnchor
from flexff.learning.rigid import rigid_forces
from flexff.learning.run_folder import (
    CHECKPOINT_FILE,
    RunFolderError,
    save_best,
    save_checkpoint,
    save_run,
    start_run,
)
from flexff.learning.scaling import MinMaxScaler
from flexff.learning.threads import torch_threads
from flexff.learning.training_step import (
    CudaGraphs,
    TrainingStep,
    adam,
    load_state,
    portable_state,
    set_learning_rate,
)

EpochReport = Callable[[dict[str, Any]], None]
# trajectories run whole side by side in one pass of role_mse: a recurrent network's pass is
# as long as the trajectory, so on a GPU, where a wider pass costs about the same, the
# validation of every epoch runs the training trajectories in one pass instead of eight
EVALUATION_GROUP = {"cpu": 8, "cuda": 64}
MSE_UNITS = ("MSE of min-max scaled labels, Fx, Fy or i1..i3 (run.json label_names; the "
             "thesis's normalized units)")


def train(model: str, preset: str, data: str | Path, out: str | Path, progress: bool = True,
          resume: bool | None = None, force: bool = True, checkpoint_every: int | None = None,
          on_epoch: EpochReport | None = None, **overrides: Any) -> dict[str, Any]:
    """Train `model` ('lstm', 'cnn-lstm', 'tcn', 'pgnn') with `preset` ('thesis', 'fast') on the
    dataset folder `data`; write the run folder `out`; return the metrics.

    `overrides` replace preset settings by name (see `learning.presets.make_config`), e.g.
    `epochs=5`, `feature_set="compact"`, `model_rate_hz=200`, `hidden=50`. `resume` and
    `force` say what to do with what `out` holds (`learning.run_folder.start_run`): by default
    a checkpoint of the same settings and data is resumed and anything else replaced, a
    finished run's files only once the new ones are complete (`flexff train` refuses instead
    unless told). `checkpoint_every`: epochs between checkpoints (default: the preset's).
    `on_epoch` is called after every epoch with {"epoch", "epochs", "train", "val",
    "best_epoch"} (learning.workers draws bars from it).
    """
    config = make_config(model, preset, **overrides)
    pick_device(config.device)  # a device that is not there fails before the data loads
    return fit(config, load_dataset(data), Path(out), progress, resume, force, checkpoint_every,
               on_epoch)


def fit(config: TrainConfig, dataset: Dataset, out: Path, progress: bool = True,
        resume: bool | None = None, force: bool = True, checkpoint_every: int | None = None,
        on_epoch: EpochReport | None = None) -> dict[str, Any]:
    """Train with a ready configuration on a loaded dataset; see `train`."""
    start = time.perf_counter()
    pick_device(config.device)  # before any work: a device that is not there fails now
    every = CHECKPOINT_EVERY[config.preset] if checkpoint_every is None else checkpoint_every
    if every < 1:
        raise InputError(f"checkpoint_every must be at least 1 epoch, got {every}")
    settings = _settings(config, dataset)
    checkpoint = start_run(out, settings, resume, force)
    train_set, test_set = _splits(dataset)
    rate_hz = dataset.sample_rate_hz
    model_rate = rate_hz / decimation(rate_hz, config.features.model_rate_hz)
    rng = np.random.default_rng(config.seed)
    train_x, train_f = _prepare(train_set, rate_hz, config.features, rng)
    test_x, test_f = _prepare(test_set, rate_hz, config.features, None)
    feature_set = config.features.feature_set
    identified = _identified_parameters(config, dataset, model_rate)
    prior = identified if uses_prior(config.model) else None
    force_inputs = identified if config.features.force_input else None
    if force_inputs is not None:  # the identified force as the last inputs
        train_x, test_x = ([with_force_inputs(x, force_inputs, config.features, model_rate)
                            for x in xs] for xs in (train_x, test_x))
    feature_scaler, label_scaler = MinMaxScaler.fit(train_x), MinMaxScaler.fit(train_f)
    edge = config.features.edge_samples(model_rate)
    labels = config.features.labels

    def targets(xs: list[np.ndarray], fs: list[np.ndarray]) -> list[np.ndarray]:
        if prior is not None:  # the residual over the prior, in label spans
            return [(f - prior_labels(x, prior, config.features, model_rate)) / label_scaler.span
                    for x, f in zip(xs, fs)]
        return [label_scaler.transform(f) for f in fs]

    def measure(network: SequenceNetwork, train_data: SequenceSet, test_data: SequenceSet
                ) -> dict[str, Any]:
        return {
            "model": config.model, "preset": config.preset, "units": MSE_UNITS,
            "train_mse": role_mse(network, train_data, TRAIN),
            "val_mse": role_mse(network, train_data, VALIDATION),
            "test_mse": role_mse(network, test_data, TRAIN),
            "test_mse_per_trajectory": {
                t.name: role_mse(network, test_data, TRAIN, only=[i])
                for i, t in enumerate(test_set)},
            "rigid_body_test_mse": _rigid_mse(test_x, test_f, label_scaler, feature_set, edge,
                                              labels=labels),
            **({} if prior is None else {
                "prior_parameters": prior,
                "prior_test_mse": _prior_mse(test_x, test_f, label_scaler, edge, prior,
                                             config.features, model_rate)})}

    network, history, metrics = fit_network(
        config, [feature_scaler.transform(x) for x in train_x], targets(train_x, train_f),
        [feature_scaler.transform(x) for x in test_x], targets(test_x, test_f), edge, rng,
        Checkpoints(out, settings, every), checkpoint, measure, progress, on_epoch)
    metrics = {**metrics, "seconds": time.perf_counter() - start,  # data preparation in
               "model_rate_hz": model_rate}
    save_run(out, config, network, feature_scaler, label_scaler,
             feature_names(feature_set, force_inputs is not None), list(LABELS[labels]), model_rate,
             {"data": {"path": str(Path(dataset.path).resolve()), "set": dataset.set,
                       "sha256": dataset.digest, "sample_rate_hz": rate_hz,
                       "plant": dict(dataset.plant), "train": [t.name for t in train_set],
                       "test": [t.name for t in test_set]},
              "parameters": metrics["parameters"],
              **({} if prior is None else {"prior_parameters": prior}),
              **({} if force_inputs is None else {"force_input": force_inputs})},
             {"metrics.json": lambda path: path.write_text(json.dumps(metrics, indent=2) + "\n"),
              "loss.png": lambda path: plot_losses(history, path,
                                                   f"{config.model} ({config.preset})")})
    return {**metrics, "run": str(out)}


def _settings(config: TrainConfig, dataset: Dataset) -> dict[str, Any]:
    """What a checkpoint must share to be resumed: the configuration (where it runs aside)
    and the data."""
    return {"config": config.learned_settings(), "data": dataset.digest}


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


def fit_network(config: TrainConfig, train_x: list[np.ndarray], train_y: list[np.ndarray],
                test_x: list[np.ndarray], test_y: list[np.ndarray], edge: int,
                rng: np.random.Generator, saver: Checkpoints, checkpoint: dict[str, Any] | None,
                measure: Callable[[SequenceNetwork, SequenceSet, SequenceSet], dict[str, Any]],
                progress: bool = True, on_epoch: EpochReport | None = None,
                unlabelled: list[np.ndarray] | None = None, select_residuals: bool = False,
                anchor: RestAnchor | None = None
                ) -> tuple[SequenceNetwork, dict[str, Any], dict[str, Any]]:
    """Train `config`'s network on scaled features and targets (lists of (n, k) arrays, one
    per trajectory; `edge` samples at each end, and those `unlabelled` marks in a training
    trajectory, out of every loss), the training trajectories' windows split into training
    and validation; return the network (best epoch, on the CPU), its history, and `measure`'s
    metrics with the timing and device: any machine's training (this module's `fit`,
    learning.machine_train) runs through here. With `select_residuals`, a residual output
    that does not help keeps its prior alone (`unhelpful_residuals`); with `anchor`, its
    pinned outputs are held to it at rest (learning.rest_anchor)."""
    roles = window_roles([len(x) for x in train_x], config.window, config.val_fraction, rng, edge,
                         unlabelled)
    device = pick_device(config.device)
    with reproducible(config.seed, config.threads):
        network = build_network(config.model, train_x[0].shape[1],
                                n_outputs=train_y[0].shape[1], **config.architecture)
        network.to(device)
        train_data = SequenceSet.build(train_x, train_y, roles, device)
        test_data = SequenceSet.build(test_x, test_y, [interior(len(x), edge) for x in test_x],
                                      device)
        fitted = train_data.role == TRAIN
        fit_linear_skip(network, train_data.x[fitted], train_data.y[fitted],
                        _skip_columns(config), anchor)
        history = _fit_loop(network, config, train_data, rng, progress, saver, checkpoint,
                            on_epoch)
        pin_at_rest(network, anchor)
        selected = select_residuals and uses_prior(config.model)
        silenced = unhelpful_residuals(network, train_data) if selected else []
        silence_outputs(network, silenced)
        metrics = {
            **measure(network, train_data, test_data),
            **({"prior_alone": silenced} if selected else {}),
            "parameters": parameter_count(network),
            "seconds_per_epoch": float(np.mean(history["seconds"])),
            "epochs": config.epochs, "best_epoch": history["best_epoch"],
            "device": str(device), "cuda_graphs": history["cuda_graphs"],
            "threads": torch.get_num_threads() if device.type == "cpu" else None,
            "history": {k: history[k] for k in ("train", "val", "seconds")},
        }
    network.cpu()
    return network, history, metrics


@torch.no_grad()
def unhelpful_residuals(network: SequenceNetwork, data: SequenceSet) -> list[int]:
    """The outputs whose residual does not lower the validation MSE below its prior's (a zero
    residual's): the prior alone is kept there. The loss sums every output's scaled error, so
    an output whose prior already holds its axis learns the others' noise: on a 3-axis plant
    whose linear axis the prior models exactly, its residual raised that axis's error by a
    third on the training set itself, and its e2 ratio fell from 5660 to 1400."""
    network.eval()
    batch = EVALUATION_GROUP["cuda" if data.x.is_cuda else "cpu"]
    residual = prior = torch.zeros(data.y.shape[-1], dtype=torch.float64)
    for k in range(0, len(data), batch):
        pred, _ = network(data.x[k:k + batch])
        y = data.y[k:k + batch]
        mask = (data.role[k:k + batch] == VALIDATION).unsqueeze(-1).to(pred.dtype)
        residual = residual + ((pred - y) ** 2 * mask).sum(dim=(0, 1)).double().cpu()
        prior = prior + (y ** 2 * mask).sum(dim=(0, 1)).double().cpu()
    return [k for k in range(len(residual)) if not residual[k] < prior[k]]


def _skip_columns(config: TrainConfig) -> slice:
    """The features a linear skip is fitted on: with force inputs those alone, so that the
    physics enters linearly through them and no least-squares weight on the collinear motion
    features, fitted to the labels' noise, extrapolates beyond the training range (hardware
    stand-in, the test split's geometric-mean e2 ratio x / y: TCN 233 / 201 and LSTM
    207 / 246 with the skip on the force inputs, 53 / 73 and 53 / 71 on every feature)."""
    return slice(-len(FORCE_INPUTS), None) if config.features.force_input else slice(None)


def _identified_parameters(config: TrainConfig, dataset: Dataset, model_rate: float
                           ) -> dict[str, float] | None:
    """The physics-guided model's prior, or a black-box network's force inputs: the
    deployable parameters of the rigid-body model identified from the training trajectories
    (learning.identify: inertias, flexures, motor friction and torque constants), without the
    added training noise, so that runs of other seeds share it; None for a model with neither.
    It needs the motion alone: the compact features hold it, bit for bit as every other set
    does, and cost a fraction of the work."""
    if not (uses_prior(config.model) or config.features.force_input):
        return None
    motion = replace(config.features, labels="forces", feature_set="compact")
    return dict(_identified_prior(str(Path(dataset.path).resolve()), dataset.digest, motion,
                                  model_rate))


@functools.lru_cache(maxsize=2)
def _identified_prior(path: str, digest: str, features: FeatureConfig, model_rate: float
                      ) -> tuple[tuple[str, float], ...]:
    """_identified_parameters of the dataset folder `path` (whose content `digest` names), once per
    process: an ensemble's members, trained one after another in a worker, share it (22 s of
    a physics-guided run's 55 s of data preparation on the hardware set)."""
    dataset = load_dataset(path)
    if dataset.digest != digest:
        raise DatasetError(f"{path} changed while training on it")
    identification = identify_samples(*_prepare(dataset.split("train"),
                                                dataset.sample_rate_hz, features, None),
                                      features, model_rate)
    return tuple(identification.parameters().items())


def _rigid_mse(xs: list[np.ndarray], fs: list[np.ndarray], scaler: MinMaxScaler,
               feature_set: str, edge: int, labels: str = "forces") -> float:
    """The test MSE of the nominal rigid-body model (as motor currents for current `labels`)
    in the same units and on the same samples (the `edge` samples at each end left out):
    the baseline to beat."""
    errors = [((f - rigid_forces(x, feature_set, None, labels)) / scaler.span)[
        interior(len(x), edge) == TRAIN] for x, f in zip(xs, fs)]
    return float(np.mean(np.concatenate(errors) ** 2))


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


def _prior_mse(xs: list[np.ndarray], fs: list[np.ndarray], scaler: MinMaxScaler, edge: int,
               parameters: dict[str, float], config: FeatureConfig, rate_hz: float) -> float:
    """The test MSE of the prior alone in the units and on the samples of the residual's
    (prior_labels), the `edge` samples at each end left out: the baseline to beat."""
    errors = [((f - prior_labels(x, parameters, config, rate_hz)) / scaler.span)[
        interior(len(x), edge) == TRAIN] for x, f in zip(xs, fs)]
    return float(np.mean(np.concatenate(errors) ** 2))


class Checkpoints:
    """Writes the checkpoints of one training run (see `learning.run_folder`)."""

    def __init__(self, out: Path, settings: dict[str, Any], every: int) -> None:
        self.out, self.settings, self.every = out, settings, every

    def best(self, state: dict[str, torch.Tensor], epoch: int, val: float) -> None:
        save_best(self.out, state, epoch, val)

    def epoch_done(self, epochs: int, network: SequenceNetwork, optimizer: torch.optim.Optimizer,
                   rng: np.random.Generator, history: dict[str, Any], best: float,
                   best_state: dict[str, torch.Tensor] | None) -> None:
        """Write a checkpoint every `every` epochs and after the last (so that a failed final
        write resumes with nothing to repeat)."""
        done = len(history["train"])
        if done % self.every and done != epochs:
            return
        save_checkpoint(self.out, {
            "settings": json.dumps(self.settings), "epoch": done, "epochs": epochs,
            "network": network.state_dict(), "optimizer": portable_state(optimizer),
            "best": best, "best_state": best_state or {},
            "rng": json.dumps(rng.bit_generator.state), "torch_rng": torch.get_rng_state(),
            "cuda_rng": torch.cuda.get_rng_state_all() if torch.cuda.is_available() else [],
            "history": json.dumps(history)})


def _restore(checkpoint: dict[str, Any], network: SequenceNetwork,
             optimizer: torch.optim.Adam, captured: bool, rng: np.random.Generator, out: Path
             ) -> tuple[dict[str, Any], float, dict[str, torch.Tensor] | None]:
    """Put the training state of `checkpoint` (from run folder `out`) back, the optimizer's
    as a `captured` step's Adam wants it; return its history, best loss and best weights."""
    try:
        network.load_state_dict(checkpoint["network"])
        load_state(optimizer, checkpoint["optimizer"], captured)
        rng.bit_generator.state = json.loads(checkpoint["rng"])
        torch.set_rng_state(checkpoint["torch_rng"])
        if checkpoint["cuda_rng"] and torch.cuda.is_available():
            torch.cuda.set_rng_state_all(checkpoint["cuda_rng"])
        history = json.loads(checkpoint["history"])
    except Exception:
        raise RunFolderError(f"{out / CHECKPOINT_FILE} does not fit the network of its settings "
                             f"(damaged): start again with --force") from None
    return history, float(checkpoint["best"]), dict(checkpoint["best_state"]) or None


def _fit_loop(network: SequenceNetwork, config: TrainConfig, data: SequenceSet,
              rng: np.random.Generator, progress: bool, saver: Checkpoints,
              checkpoint: dict[str, Any] | None, on_epoch: EpochReport | None) -> dict[str, Any]:
    captured = _replays_graphs(config, data)
    optimizer = adam(network, config.learning_rate, captured)
    step = TrainingStep(network, optimizer, config.grad_clip, CudaGraphs() if captured else None)
    recurrent = config.model in RECURRENT
    sampler = None if recurrent else WindowSampler(data, config.window, network.history)
    history: dict[str, Any] = {"train": [], "val": [], "seconds": []}
    best, best_state = math.inf, None
    if checkpoint is not None:
        history, best, best_state = _restore(checkpoint, network, optimizer, captured, rng,
                                             saver.out)
    first = len(history["train"])
    bar = tqdm(range(first, config.epochs), initial=first, total=config.epochs,
               desc=f"{config.model}", disable=not progress, unit="epoch")
    for epoch in bar:
        start = time.perf_counter()
        network.train()
        if sampler is None:  # a recurrent network
            loss = _recurrent_epoch(network, config, data, step, rng, epoch)
        else:
            loss = _window_epoch(config, sampler, step, rng, epoch)
        val = role_mse(network, data, VALIDATION)
        history["seconds"].append(time.perf_counter() - start)
        history["train"].append(loss)
        history["val"].append(val)
        if val < best:
            best, best_state = val, copy.deepcopy(network.state_dict())
            history["best_epoch"] = epoch + 1
            saver.best(best_state, epoch + 1, val)
        saver.epoch_done(config.epochs, network, optimizer, rng, history, best, best_state)
        bar.set_postfix(train=f"{loss:.3g}", val=f"{val:.3g}", best=history.get("best_epoch"))
        if on_epoch is not None:
            on_epoch({"epoch": epoch + 1, "epochs": config.epochs, "train": loss, "val": val,
                      "best_epoch": history.get("best_epoch")})
    if best_state is None:
        raise RunError(f"training diverged (validation loss {history['val'][-1]}): lower "
                       f"learning_rate (now {config.learning_rate:g}) or grad_clip")
    network.load_state_dict(best_state)
    history["cuda_graphs"] = step.graphs is not None
    return history


def _replays_graphs(config: TrainConfig, data: SequenceSet) -> bool:
    """Whether the training steps replay CUDA graphs: asked for, and the data on CUDA."""
    return config.cuda_graphs and data.x.is_cuda


def _recurrent_epoch(network: SequenceNetwork, config: TrainConfig, data: SequenceSet,
                     step: TrainingStep, rng: np.random.Generator, epoch: int) -> float:
    """One TBPTT pass: each group of trajectories chunk by chunk, the state carried on.

    Which chunks hold training samples, and how many, is read from a host copy of the roles,
    and the loss is summed on the device: on a GPU no chunk waits for the one before. A chunk
    without training samples only carries the state on."""
    roles = data.role.cpu().numpy() == TRAIN
    groups = data.groups(config.batch_size, rng)
    chunks = range(0, data.x.shape[1], config.window)
    total, count, k = torch.zeros((), device=data.x.device), 0, 0
    for on_host, group in groups:
        x, y, role = data.x[group], data.y[group], data.role[group]
        state = network.initial_state(len(group), x.device)
        for start in chunks:
            _set_learning_rate(step.optimizer, config, epoch + k / (len(groups) * len(chunks)))
            k += 1
            part = slice(start, start + config.window)
            samples = int(roles[on_host, part].sum())
            if samples:
                loss, state = step(x[:, part], state, y[:, part], role[:, part] == TRAIN)
                total, count = total + loss * samples, count + samples
            else:
                with torch.no_grad():
                    state = network(x[:, part], state)[1]
    return float(total) / count


def _window_epoch(config: TrainConfig, sampler: WindowSampler, step: TrainingStep,
                  rng: np.random.Generator, epoch: int) -> float:
    """One pass over random training windows, each with its history as the initial buffer;
    the loss summed on the device (no batch waits for the one before)."""
    n_batches = math.ceil(len(sampler) / config.batch_size)
    total = count = torch.zeros((), device=sampler.data.x.device)
    for k, (hist, x, y, mask) in enumerate(sampler.batches(config.batch_size, rng)):
        _set_learning_rate(step.optimizer, config, epoch + k / n_batches)
        loss, _ = step(x, (hist.transpose(1, 2),), y, mask)
        samples = mask.sum()
        total, count = total + loss * samples, count + samples
    return float(total / count)


def _set_learning_rate(optimizer: torch.optim.Optimizer, config: TrainConfig,
                       epochs_done: float) -> None:
    set_learning_rate(optimizer, learning_rate(config, epochs_done / config.epochs))


def learning_rate(config: TrainConfig, fraction: float) -> float:
    """The learning rate at `fraction` (0 to 1) of training.

    onecycle: cosine warm-up over the first 30 % from peak/25 to the peak, then cosine
    annealing to peak/1e4 (PyTorch's OneCycleLR defaults); cosine: from the peak to zero.
    """
    peak = config.learning_rate
    if config.schedule == "constant":
        return peak
    if config.schedule == "cosine":
        return peak * 0.5 * (1 + math.cos(math.pi * fraction))
    warm = 0.3
    if fraction < warm:
        low = peak / 25
        return low + (peak - low) * 0.5 * (1 - math.cos(math.pi * fraction / warm))
    low = peak / 25 / 1e4
    return low + (peak - low) * 0.5 * (1 + math.cos(math.pi * (fraction - warm) / (1 - warm)))


@torch.no_grad()
def role_mse(network: SequenceNetwork, data: SequenceSet, role: int,
             only: list[int] | None = None) -> float:
    """MSE over the samples of `role`, each trajectory run whole from the zero state, a
    group of them per pass (EVALUATION_GROUP)."""
    network.eval()
    batch = EVALUATION_GROUP["cuda" if data.x.is_cuda else "cpu"]
    indices = list(range(len(data))) if only is None else only
    total, count = 0.0, 0
    for k in range(0, len(indices), batch):
        group = indices[k:k + batch]
        pred, _ = network(data.x[group])
        mask = data.role[group] == role
        weight = mask.unsqueeze(-1).to(pred.dtype)
        total += float(((pred - data.y[group]) ** 2 * weight).sum())
        count += int(mask.sum()) * pred.shape[-1]
    return total / count if count else math.nan


@contextmanager
def reproducible(seed: int, threads: int = 0) -> Iterator[None]:
    """Seed torch, prefer deterministic kernels, set the CPU threads (learning.threads);
    restore after.

    The switch is torch's own, without `torch.use_deterministic_algorithms`' import of the
    compiler's settings (1.8 s of a training's start, for a compiler flexff does not use).
    cuBLAS is deterministic only with a fixed workspace, set before its first call."""
    os.environ.setdefault("CUBLAS_WORKSPACE_CONFIG", ":4096:8")
    deterministic = torch.are_deterministic_algorithms_enabled()
    warn_only = torch.is_deterministic_algorithms_warn_only_enabled()
    torch.manual_seed(seed)
    torch._C._set_deterministic_algorithms(True, warn_only=True)
    try:
        with torch_threads(threads):
            yield
    finally:
        torch._C._set_deterministic_algorithms(deterministic, warn_only=warn_only)


def plot_losses(history: dict[str, Any], path: Path, title: str) -> None:
    """Training and validation loss per epoch on a log scale, the kept epoch marked."""
    from matplotlib.figure import Figure  # imported here: 0.4 s of every training's start

    figure = Figure(figsize=(6, 4), tight_layout=True)
    axes = figure.subplots()
    epochs = np.arange(1, len(history["train"]) + 1)
    axes.semilogy(epochs, history["train"], label="training (running mean, dropout on)")
    axes.semilogy(epochs, history["val"], label="validation")
    axes.axvline(history["best_epoch"], color="grey", linestyle=":",
                 label=f"kept: epoch {history['best_epoch']}")
    axes.set_xlabel("epoch")
    axes.set_ylabel("MSE (scaled labels)")
    axes.set_title(title)
    axes.legend()
    figure.savefig(path, dpi=120)
