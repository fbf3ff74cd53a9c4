"""`flexff predict RUN --data LOGS -o predictions.csv`: each trained model's predicted effort
per sample of a machine's logs beside the measured one, raw and as the labels filter it, to
score or plot with one's own tools.

RUN is `flexff evaluate`'s output folder (its identified.json and every runs/<kind>) or one
training run folder (`flexff train`); LOGS a machine dataset (`flexff data import
--machine`, or collected). The samples are the model rate's: the measured effort as logged
there (raw) and as the labels are (`filtered`: taken `lead_s` earlier, low-passed,
decimated), each model's prediction (identified: the prior's linear model on the measured
motion; a network on the features of it, the physics-guided one over its prior), and
whether the sample is scored (`scored`: the filter's ends are not). The preprocessing is the
runs' own (run.json), recorded with the error's definition (machine_features.ERROR) and
the relative errors in a JSON file beside the CSV; a PNG plots measured and predicted.

Docs: "Predict a machine's efforts" (docs/how-to/import-logs.md).
"""

from __future__ import annotations

import csv
import json
import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import torch

from flexff.cosim.csv_text import TIME
from flexff.cosim.machine import Machine
from flexff.cosim.plots import save_figure
from flexff.cosim.recording import atomic_write
from flexff.fmu.errors import InputError
from flexff.learning.dataset_files import Trajectory
from flexff.learning.deploy import SIModel
from flexff.learning.description_data import features_from_dict, prior_efforts
from flexff.learning.linear_model import EDGE_PERIODS, read_linear_model
from flexff.learning.linear_prior import LinearModel, linear_model_from_dict
from flexff.learning.machine_dataset import MachineDataset, load_machine_dataset
from flexff.learning.machine_features import (
    MachineFeatures,
    label_filter,
    motion,
    prepare,
    preprocessing,
)
from flexff.learning.run_folder import RUN_FILE, load_run
from flexff.learning.threads import torch_threads

IDENTIFIED = "identified"
SPLITS = ("all", "train", "test")
LABEL_SETTINGS = ("cutoff_hz", "filter_order", "lead_s", "model_rate_hz")
SHOWN = 4  # trajectories plotted side by side at most (the CSV holds them all)


@dataclass(frozen=True)
class TrainedModels:
    """What a RUN folder holds: the identified linear model (or None) and each network's run
    folder by its name."""

    identified: LinearModel | None
    runs: Mapping[str, Path]


@dataclass(frozen=True)
class Predicted:
    """One trajectory's efforts at the model rate, (samples, axes) each."""

    trajectory: str
    split: str
    time: np.ndarray
    measured: np.ndarray  # as logged at these samples
    filtered: np.ndarray  # the labels: lead_s earlier, through the labels' filter
    models: Mapping[str, np.ndarray]  # model name -> prediction
    scored: np.ndarray  # bool (samples,): inside the filter's ends


@dataclass(frozen=True)
class Predictions:
    """Every trajectory's predictions, the preprocessing that made the labels and each
    model's relative error per axis over the scored samples."""

    machine: Machine
    trajectories: list[Predicted]
    preprocessing: dict[str, Any]
    relative_error: dict[str, dict[str, float]]


def trained_models(path: str | Path) -> TrainedModels:
    """The models in `path`: a training run folder, or an evaluation's folder."""
    path = Path(path)
    if (path / RUN_FILE).is_file():
        return TrainedModels(None, {_kind(path): path})
    runs = {_kind(run.parent): run.parent for run in sorted(path.glob(f"runs/*/{RUN_FILE}"))}
    identified = read_linear_model(path / "identified.json") \
        if (path / "identified.json").is_file() else None
    if identified is None and not runs:
        raise InputError(f"{path}: holds no trained model: give a training run folder "
                         f"(flexff train -o) or an evaluation's folder (flexff evaluate -o)")
    return TrainedModels(identified, runs)


def predict_logs(run: str | Path, data: str | Path, split: str = "all") -> Predictions:
    """Every model of `run` on the trajectories of the machine dataset `data` (`split`: all,
    train or test)."""
    return predict(trained_models(run), load_machine_dataset(data), split)


def predict(models: TrainedModels, dataset: MachineDataset, split: str = "all") -> Predictions:
    """Each of `models` on the trajectories of `dataset` in `split` (all, train or test)."""
    if split not in SPLITS:
        raise InputError(f"split: expected one of {', '.join(SPLITS)}, got {split!r}")
    chosen = [t for t in dataset.trajectories if split == "all" or t.split == split]
    if not chosen:
        raise InputError(f"{dataset.path}: no trajectory in the split {split!r}")
    rate_hz = dataset.sample_rate_hz
    machine = dataset.description
    features, derived = _label_settings(models, dataset)
    predicted: dict[str, list[np.ndarray]] = {}
    if models.identified is not None:
        _check_axes(models.identified.machine, machine, "identified.json")
        predicted[IDENTIFIED] = prior_efforts(models.identified, chosen, rate_hz, machine,
                                              features)
    with torch.no_grad(), torch_threads():
        for name, folder in models.runs.items():
            predicted[name] = _network(folder, chosen, dataset)
    decimation = features.decimation(rate_hz)
    assert features.cutoff_hz is not None and features.model_rate_hz is not None
    edge = math.ceil(EDGE_PERIODS / features.cutoff_hz * features.model_rate_hz)
    trajectories = []
    for k, trajectory in enumerate(chosen):
        signals = trajectory.signals
        filtered = label_filter(motion(signals, rate_hz, machine, features)[1], rate_hz, features)
        n = len(filtered)
        scored = np.zeros(n, dtype=bool)
        scored[edge:n - edge] = True
        trajectories.append(Predicted(
            trajectory.name, trajectory.split, np.asarray(signals[TIME])[::decimation][:n],
            np.column_stack([np.asarray(signals[a.effort_signal])[::decimation][:n]
                             for a in machine.axes]),
            filtered, {name: values[k] for name, values in predicted.items()}, scored))
    errors = {name: relative_errors([t.filtered[t.scored] for t in trajectories],
                                    [t.models[name][t.scored] for t in trajectories], machine)
              for name in predicted}
    record = {**preprocessing(features, features, rate_hz), "derived": derived}
    return Predictions(machine, trajectories, record, errors)


def relative_errors(labels: Sequence[np.ndarray], predicted: Sequence[np.ndarray],
                    machine: Machine) -> dict[str, float]:
    """||F - P|| / ||F|| per axis over all the samples given (machine_features.ERROR)."""
    f, p = np.concatenate(labels), np.concatenate(predicted)
    return {a.name: float(np.linalg.norm(f[:, k] - p[:, k]) / np.linalg.norm(f[:, k]))
            for k, a in enumerate(machine.axes)}


def write_predictions(predictions: Predictions, out: str | Path,
                      about: Mapping[str, Any] | None = None) -> list[Path]:
    """The CSV `out`, the JSON of errors and preprocessing (`about` added) and the PNG beside
    it (same stem); the paths written."""
    out = Path(out)
    if out.is_dir():
        raise InputError(f"{out}: is a folder: give the name of the CSV file to write")
    out.parent.mkdir(parents=True, exist_ok=True)
    machine = predictions.machine
    names = list(predictions.relative_error)
    header = ["trajectory", "split", TIME, "scored"]
    for axis in machine.axes:
        header += [axis.effort_signal, f"{axis.effort_signal}_filtered",
                   *(f"{name}.{axis.effort_signal}" for name in names)]

    def rows(tmp: Path) -> None:
        with tmp.open("w", newline="") as file:
            writer = csv.writer(file)
            writer.writerow(header)
            for t in predictions.trajectories:
                for i in range(len(t.time)):
                    row = [t.trajectory, t.split, f"{t.time[i]:.9g}", int(t.scored[i])]
                    for k in range(len(machine.axes)):
                        row += [f"{t.measured[i, k]:.9g}", f"{t.filtered[i, k]:.9g}",
                                *(f"{t.models[n][i, k]:.9g}" for n in names)]
                    writer.writerow(row)
    atomic_write(out, rows)
    record = {**(about or {}), "machine": machine.name, "axes": [a.name for a in machine.axes],
              "trajectories": {t.trajectory: t.split for t in predictions.trajectories},
              "relative_error": predictions.relative_error,
              "preprocessing": predictions.preprocessing}
    text = json.dumps(record, indent=2) + "\n"
    metrics = out.with_suffix(".json")
    atomic_write(metrics, lambda tmp: tmp.write_text(text, "utf-8"))
    return [out, metrics, plot_predictions(predictions, out.with_suffix(".png"))]


def plot_predictions(predictions: Predictions, path: Path) -> Path:
    """Measured effort (raw, filtered) and each model's prediction per axis over time, one
    column per trajectory (the first SHOWN)."""
    from matplotlib.figure import Figure

    machine = predictions.machine
    shown = predictions.trajectories[:SHOWN]
    figure = Figure(figsize=(4.5 * len(shown) + 2, 1.2 + 2.4 * len(machine.axes)))
    grid = figure.subplots(len(machine.axes), len(shown), sharex="col", squeeze=False)
    for column, t in enumerate(shown):
        for row, axis in enumerate(machine.axes):
            ax = grid[row, column]
            ax.plot(t.time, t.measured[:, row], color="0.75", lw=0.6, label="measured (raw)")
            ax.plot(t.time, t.filtered[:, row], color="k", lw=1.0, label="measured (filtered)")
            for k, (name, values) in enumerate(t.models.items()):
                ax.plot(t.time, values[:, row], color=f"C{k}", lw=0.8, label=name)
            ax.grid(True, alpha=0.3)
            if column == 0:
                ax.set_ylabel(f"{axis.effort_signal} [{axis.effort_unit}]")
        grid[0, column].set_title(f"{t.trajectory} ({t.split})")
        grid[-1, column].set_xlabel("time [s]")
    grid[0, -1].legend(loc="upper left", bbox_to_anchor=(1.01, 1.0), fontsize="small")
    more = len(predictions.trajectories) - len(shown)
    if more > 0:
        figure.suptitle(f"{more} more trajectories in the CSV", fontsize="small")
    return save_figure(figure, path)


def _kind(folder: Path) -> str:
    """A run's model kind as its run.json names it (the folder's name otherwise)."""
    try:
        return str(json.loads((folder / RUN_FILE).read_text())["config"]["model"])
    except (OSError, ValueError, KeyError, TypeError):
        return folder.name


def _label_settings(models: TrainedModels, data: MachineDataset
                    ) -> tuple[MachineFeatures, list[str]]:
    """The resolved feature settings that made the runs' labels (all runs alike) and which of
    them training derived from its data (its metrics.json); for an identified model alone the
    description's, resolved on the data's training split."""
    found, derived = {}, []
    for name, folder in models.runs.items():
        info = json.loads((folder / RUN_FILE).read_text())
        if "machine_features" not in info:
            raise InputError(f"{folder}: a manipulator's run: flexff predict takes a "
                             f"machine's runs (flexff train on a machine dataset)")
        found[name] = features_from_dict(info["machine_features"])
        try:
            metrics = json.loads((folder / "metrics.json").read_text())
            derived = list(metrics["preprocessing"]["derived"])
        except (OSError, ValueError, KeyError, TypeError):
            pass  # a run from before the record: its settings hold, not their origin
    if found:
        first = next(iter(found.values()))
        for name, features in found.items():
            for setting in LABEL_SETTINGS:
                if getattr(features, setting) != getattr(first, setting):
                    raise InputError(f"the runs {next(iter(found))} and {name} filter their "
                                     f"labels differently ({setting}): predict one at a time")
        return first, derived
    given = MachineFeatures.of(data.description)
    train = [t.signals for t in data.trajectories if t.split == "train"] \
        or [t.signals for t in data.trajectories]
    resolved = given.resolved(data.sample_rate_hz, train, data.description)
    return resolved, preprocessing(given, resolved, data.sample_rate_hz)["derived"]


def _check_axes(trained: Machine, machine: Machine, where: str) -> None:
    want = [(a.name, a.effort_signal) for a in trained.axes]
    if want != [(a.name, a.effort_signal) for a in machine.axes]:
        raise InputError(f"{where}: learned the axes {', '.join(n for n, _ in want)}; the "
                         f"data's machine has {', '.join(a.name for a in machine.axes)}")


def _network(folder: Path, trajectories: list[Trajectory], data: MachineDataset
             ) -> list[np.ndarray]:
    """A network's efforts on each trajectory's features, over its own prior if it has one."""
    run = load_run(folder)
    trained = run.machine
    assert trained is not None
    _check_axes(trained, data.description, str(folder))
    features = features_from_dict(run.info["machine_features"])
    model = SIModel(run, "features", prior=False)
    out = []
    for trajectory in trajectories:
        x, _ = prepare(trajectory.signals, data.sample_rate_hz, data.description, features)
        y = model(torch.from_numpy(np.ascontiguousarray(x, dtype=np.float64)),
                  *model.initial_state())[0]
        out.append(y.numpy())
    if model.residual:
        prior = linear_model_from_dict(run.info["machine_prior"], str(folder / RUN_FILE))
        out = [p + q for p, q in zip(out, prior_efforts(prior, trajectories,
                                                        data.sample_rate_hz, data.description,
                                                        features))]
    return out

