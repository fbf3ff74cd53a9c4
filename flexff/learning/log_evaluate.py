"""`flexff evaluate --data LOGS`: a machine's models compared on logs alone, with no loop to
run them in: each model's force prediction on the test logs, per axis as robot identification
reports it, the relative 2-norm ||F - F^|| / ||F|| of the efforts through the labels' filter
(machine_features.ERROR; the filter's settings, given in `[machine.learning]` or derived from
the data, in summary.json's `preprocessing`).

The linear model of the prior is identified on the training logs, each network trained on
them (learning.machine_evaluate.train_models) and run on the test logs' measured motion; the
physics-guided model adds its residual to the identified model (learning.predict).
summary.json holds the errors, table.md them in percent, predictions.csv (.json, .png) every
model's efforts per sample of the test logs.
"""

from __future__ import annotations

import json
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

from flexff.cosim.recording import atomic_write
from flexff.learning.linear_model import write_linear_model
from flexff.learning.machine_dataset import load_machine_dataset
from flexff.learning.machine_evaluate import (
    MODELS,
    SUMMARY,
    check_settings,
    learned_features,
    train_models,
)
from flexff.learning.machine_identify import dataset_features, identify_dataset
from flexff.learning.predict import TrainedModels, predict, write_predictions

PREDICTIONS = "predictions.csv"  # every model's efforts on the test logs (learning.predict)


def evaluate_logs(data_path: str | Path, out: str | Path, models: Sequence[str] = MODELS,
                  preset: str = "fast", workers: int | None = None, progress: bool = True,
                  say: Callable[[str], None] = print, **overrides: Any) -> dict[str, Any]:
    """Identify, train and compare on the machine dataset `data_path` (imported logs); write
    `out` (with every model's predictions on the test logs, predictions.csv); return the
    summary. `say` gets the preprocessing used, each derived setting marked."""
    check_settings(models, preset, overrides)
    data = load_machine_dataset(data_path)
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    features, settings = dataset_features(data)
    say(settings)
    identified = identify_dataset(data, features)
    write_linear_model(identified, out / "identified.json")
    train_models(data, identified, out, models, preset, workers, progress,
                 learned_features(identified), **overrides)
    predictions = predict(TrainedModels(identified, {k: out / "runs" / k for k in models}),
                          data, "test")
    write_predictions(predictions, out / PREDICTIONS)
    axes = [a.name for a in data.description.axes]
    summary = {"machine": data.description.name, "axes": axes,
               "measure": "relative 2-norm of the effort error on the test logs",
               "test": [t.trajectory for t in predictions.trajectories],
               "relative_error": predictions.relative_error,
               "preprocessing": predictions.preprocessing,
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
