"""`flexff evaluate --data LOGS`: a machine's models compared on logs alone, with no loop to
run them in: each model's force prediction on the test logs, per axis as robot identification
reports it, the relative 2-norm ||F - F^|| / ||F|| of the efforts through the labels' filter.

The linear model of the prior is identified on the training logs, each network trained on
them (learning.machine_evaluate.train_models) and run on the test logs' measured motion; the
physics-guided model adds its residual to the identified model. summary.json holds the errors,
table.md them in percent.
"""

from __future__ import annotations

import json
import math
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np
import torch

from flexff.controllers.linear_prior import LinearModel
from flexff.cosim.recording import atomic_write
from flexff.learning.dataset_files import Trajectory
from flexff.learning.deploy import SIModel
from flexff.learning.linear_model import EDGE_PERIODS, write_linear_model
from flexff.learning.machine_dataset import MachineDataset, load_machine_dataset
from flexff.learning.machine_evaluate import (
    MODELS,
    SUMMARY,
    check_settings,
    learned_features,
    train_models,
)
from flexff.learning.machine_features import MachineFeatures, prepare
from flexff.learning.machine_identify import identify_dataset
from flexff.learning.machine_train import features_from_dict, prior_efforts
from flexff.learning.run_folder import Run, load_run
from flexff.learning.threads import torch_threads


def evaluate_logs(data_path: str | Path, out: str | Path, models: Sequence[str] = MODELS,
                  preset: str = "fast", workers: int | None = None, progress: bool = True,
                  **overrides: Any) -> dict[str, Any]:
    """Identify, train and compare on the machine dataset `data_path` (imported logs); write
    `out`; return the summary."""
    check_settings(models, preset, overrides)
    data = load_machine_dataset(data_path)
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    features = MachineFeatures().resolved(data.sample_rate_hz,
                                          [t.signals for t in data.split("train")],
                                          data.description)
    identified = identify_dataset(data, features)
    write_linear_model(identified, out / "identified.json")
    train_models(data, identified, out, models, preset, workers, progress,
                 learned_features(identified), **overrides)
    test = data.split("test")
    errors = {"identified": _identified_errors(data, identified, test, features)}
    for kind in models:
        errors[kind] = _network_errors(data, load_run(out / "runs" / kind), identified, test)
    axes = [a.name for a in data.description.axes]
    summary = {"machine": data.description.name, "axes": axes,
               "measure": "relative 2-norm of the effort error on the test logs",
               "test": [t.name for t in test], "relative_error": errors,
               "identified": identified.to_dict()["axes"]}
    text = json.dumps(summary, indent=2) + "\n"
    atomic_write(out / SUMMARY, lambda tmp: tmp.write_text(text, "utf-8"))
    atomic_write(out / "table.md", lambda tmp: tmp.write_text(error_table(summary), "utf-8"))
    return summary


def error_table(summary: dict[str, Any]) -> str:
    """The relative errors in percent per axis as a Markdown table."""
    names = list(summary["relative_error"])
    lines = ["| axis | " + " | ".join(names) + " |", "|---|" + "---:|" * len(names)]
    for axis in summary["axes"]:
        lines.append(f"| {axis} | " + " | ".join(
            f"{100 * summary['relative_error'][n][axis]:.2f} %" for n in names) + " |")
    return "\n".join(lines) + "\n"


def _identified_errors(data: MachineDataset, model: LinearModel, test: list[Trajectory],
                       features: MachineFeatures) -> dict[str, float]:
    predicted = prior_efforts(model, test, data.sample_rate_hz, data.description, features)
    assert predicted is not None
    labels = [prepare(t.signals, data.sample_rate_hz, data.description, features)[1]
              for t in test]
    return _relative(data, labels, predicted, features)


@torch.no_grad()
def _network_errors(data: MachineDataset, run: Run, prior: LinearModel,
                    test: list[Trajectory]) -> dict[str, float]:
    features = features_from_dict(run.info["machine_features"])
    model = SIModel(run, "features", prior=False)
    labels, predicted = [], []
    with torch_threads():
        for trajectory in test:
            x, f = prepare(trajectory.signals, data.sample_rate_hz, data.description, features)
            out = model(torch.from_numpy(np.ascontiguousarray(x, dtype=np.float64)),
                        *model.initial_state())[0]
            labels.append(f)
            predicted.append(out.numpy())
    if model.residual:
        priors = prior_efforts(prior, test, data.sample_rate_hz, data.description, features)
        assert priors is not None
        predicted = [p + q for p, q in zip(predicted, priors)]
    return _relative(data, labels, predicted, features)


def _relative(data: MachineDataset, labels: list[np.ndarray], predicted: list[np.ndarray],
              features: MachineFeatures) -> dict[str, float]:
    """||F - F^|| / ||F|| per axis over every test log, the filter's ends left out."""
    assert features.cutoff_hz is not None and features.model_rate_hz is not None
    edge = math.ceil(EDGE_PERIODS / features.cutoff_hz * features.model_rate_hz)
    f = np.concatenate([x[edge:len(x) - edge] for x in labels])
    g = np.concatenate([x[edge:len(x) - edge] for x in predicted])
    return {a.name: float(np.linalg.norm(f[:, k] - g[:, k]) / np.linalg.norm(f[:, k]))
            for k, a in enumerate(data.description.axes)}
