"""Training: any machine's data in, a run folder out (weights, run.json, metrics.json, loss.png).

`fit` takes a TrainingSource (learning.training_data: a [machine] description's data,
learning.description_data, or the manipulator's dataset folder, learning.manipulator_data,
which `train` loads) and does the rest alike for every machine: Adam on the MSE of
min-max-scaled labels (the thesis's normalized units; for the pgnn the residual over its prior,
F - F_prior, divided by the same label span, which gives the same MSE), truncated
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
import json
import math
import os
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

import numpy as np
import torch
from tqdm import tqdm

from flexff.fmu.errors import InputError, RunError
from flexff.learning.batches import (
    TRAIN,
    VALIDATION,
    SequenceSet,
    WindowSampler,
    interior,
    window_roles,
)
from flexff.learning.dataset import load_dataset
from flexff.learning.devices import pick_device
from flexff.learning.manipulator_data import ManipulatorData
from flexff.learning.manipulator_settings import manipulator_settings
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
from flexff.learning.presets import CHECKPOINT_EVERY, TrainConfig
from flexff.learning.rest_anchor import RestAnchor
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
from flexff.learning.training_data import TrainingSource
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


def train(model: str, preset: str, data: str | Path, out: str | Path, progress: bool = True,
          resume: bool | None = None, force: bool = True, checkpoint_every: int | None = None,
          on_epoch: EpochReport | None = None, **overrides: Any) -> dict[str, Any]:
    """Train `model` ('lstm', 'cnn-lstm', 'tcn', 'pgnn') with `preset` ('thesis', 'fast') on the
    dataset folder `data`; write the run folder `out`; return the metrics.

    `overrides` replace preset settings by name (see
    `learning.manipulator_settings.manipulator_settings`), e.g.
    `epochs=5`, `feature_set="compact"`, `model_rate_hz=200`, `hidden=50`. `resume` and
    `force` say what to do with what `out` holds (`learning.run_folder.start_run`): by default
    a checkpoint of the same settings and data is resumed and anything else replaced, a
    finished run's files only once the new ones are complete (`flexff train` refuses instead
    unless told). `checkpoint_every`: epochs between checkpoints (default: the preset's).
    `on_epoch` is called after every epoch with {"epoch", "epochs", "train", "val",
    "best_epoch"} (learning.workers draws bars from it).
    """
    config, features = manipulator_settings(model, preset, **overrides)
    pick_device(config.device)  # a device that is not there fails before the data loads
    return fit(config, ManipulatorData(config, features, load_dataset(data)), Path(out),
               progress, resume, force, checkpoint_every, on_epoch)


def fit(config: TrainConfig, source: TrainingSource, out: Path, progress: bool = True,
        resume: bool | None = None, force: bool = True, checkpoint_every: int | None = None,
        on_epoch: EpochReport | None = None) -> dict[str, Any]:
    """Train with a ready configuration on any machine's data `source` (its settings checked
    against the run folder `out` before it prepares the data); see `train` for the rest."""
    start = time.perf_counter()
    pick_device(config.device)  # before any work: a device that is not there fails now
    every = CHECKPOINT_EVERY[config.preset] if checkpoint_every is None else checkpoint_every
    if every < 1:
        raise InputError(f"checkpoint_every must be at least 1 epoch, got {every}")
    settings = source.settings
    checkpoint = start_run(out, settings, resume, force)
    rng = np.random.default_rng(config.seed)
    data = source.prepare(rng)
    feature_scaler = MinMaxScaler.fit(data.train_x)
    label_scaler = MinMaxScaler.fit(data.train_labels)
    train_prior, test_prior = (None, None) if data.prior is None else data.prior

    def targets(fs: list[np.ndarray], priors: list[np.ndarray] | None) -> list[np.ndarray]:
        if priors is None:
            return [label_scaler.transform(f) for f in fs]
        return [(f - p) / label_scaler.span for f, p in zip(fs, priors)]  # in label spans

    def test_mse(efforts: list[np.ndarray]) -> float:
        """A baseline's test MSE in the network's units, on its samples (the edges out; a
        mask, not a slice: the same order of summation whatever the arrays' layout)."""
        errors = [((f - e) / label_scaler.span)[interior(len(f), data.edge) == TRAIN]
                  for f, e in zip(data.test_labels, efforts)]
        return float(np.mean(np.concatenate(errors) ** 2))

    def measure(network: SequenceNetwork, train_data: SequenceSet, test_data: SequenceSet
                ) -> dict[str, Any]:
        return {
            "model": config.model, "preset": config.preset, "units": data.units,
            "train_mse": role_mse(network, train_data, TRAIN),
            "val_mse": role_mse(network, train_data, VALIDATION),
            "test_mse": role_mse(network, test_data, TRAIN),
            "test_mse_per_trajectory": {
                name: role_mse(network, test_data, TRAIN, only=[i])
                for i, name in enumerate(data.test_names)},
            **{name: test_mse(efforts) for name, efforts in data.baselines.items()},
            **data.metrics,
            **({} if test_prior is None else {"prior_test_mse": test_mse(test_prior)})}

    anchor = None if data.anchor is None else data.anchor.scaled(
        feature_scaler.transform,
        lambda efforts: targets([efforts], None if train_prior is None
                                else [np.zeros_like(efforts)])[0])
    network, history, metrics = fit_network(
        config, [feature_scaler.transform(x) for x in data.train_x],
        targets(data.train_labels, train_prior), [feature_scaler.transform(x) for x in data.test_x],
        targets(data.test_labels, test_prior), data.edge, rng, Checkpoints(out, settings, every),
        checkpoint, measure, progress, on_epoch, data.resting, data.select_residuals, data.skip,
        anchor)
    metrics = {**metrics, "seconds": time.perf_counter() - start,  # data preparation in
               "model_rate_hz": data.model_rate_hz, **data.preprocessing}
    save_run(out, data.config_record, network, feature_scaler, label_scaler, data.feature_names,
             data.label_names, data.model_rate_hz,
             {**data.run_info, "parameters": metrics["parameters"]},
             {"metrics.json": lambda path: path.write_text(json.dumps(metrics, indent=2) + "\n"),
              "loss.png": lambda path: plot_losses(history, path, data.title)})
    return {**metrics, "run": str(out)}


def fit_network(config: TrainConfig, train_x: list[np.ndarray], train_y: list[np.ndarray],
                test_x: list[np.ndarray], test_y: list[np.ndarray], edge: int,
                rng: np.random.Generator, saver: Checkpoints, checkpoint: dict[str, Any] | None,
                measure: Callable[[SequenceNetwork, SequenceSet, SequenceSet], dict[str, Any]],
                progress: bool = True, on_epoch: EpochReport | None = None,
                unlabelled: list[np.ndarray] | None = None, select_residuals: bool = False,
                skip: slice = slice(None), anchor: RestAnchor | None = None
                ) -> tuple[SequenceNetwork, dict[str, Any], dict[str, Any]]:
    """Train `config`'s network on scaled features and targets (lists of (n, k) arrays, one
    per trajectory; `edge` samples at each end, and those `unlabelled` marks in a training
    trajectory, out of every loss), the training trajectories' windows split into training
    and validation; return the network (best epoch, on the CPU), its history, and `measure`'s
    metrics with the timing and device. With `select_residuals`, a residual output that does
    not help keeps its prior alone (`unhelpful_residuals`); `skip`: the features the linear
    skip is fitted on; with `anchor`, its pinned outputs are held to it at rest
    (learning.rest_anchor)."""
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
        fit_linear_skip(network, train_data.x[fitted], train_data.y[fitted], skip, anchor)
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
