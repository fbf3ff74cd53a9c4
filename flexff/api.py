"""flexff from Python, for scripts and notebooks: the same validated run model and engine as the
command line (`flexff run`), as functions.

    from flexff import api

    config = api.load("run.toml")                # TOML or SSP, checked like `flexff run`
    recording = api.simulate(config)             # in memory: recording["vdp.x0"], .time
    metrics = api.run(config, "out")             # into a folder, as `flexff run ... -o out`
    configs = api.sweep("run.toml", {"fmu.vdp.parameters.mu": [0.5, 1.5]})
    results = api.run_many(configs, "sweep")     # in parallel, one subfolder each
    result = api.read("out")                     # flexff.results.load: recording, metrics, run.json
    api.register_builtin("gain", (api.Option("k", "number", 1.0),), gain_system)  # [fmu.g]

A configuration is a frozen cosim.schema.RunConfig; change one through `api.sweep` (or
dataclasses.replace and `api.check`). `api.predict` is `flexff predict` as a function.
"""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING, Any

from flexff.cosim.batch import BatchResult, sweep
from flexff.cosim.batch import run_batch as run_many
from flexff.cosim.builtins import Option, register_builtin
from flexff.cosim.config import checked as check
from flexff.cosim.recording import Recording
from flexff.cosim.run import load_run_config as load
from flexff.cosim.run import run_config as run
from flexff.cosim.run import simulate_config as simulate
from flexff.cosim.schema import RunConfig
from flexff.results import RunResult
from flexff.results import load as read

if TYPE_CHECKING:  # learning loads PyTorch: only when a prediction is asked for
    from flexff.learning.predict import Predictions


def predict(run: str | Path, data: str | Path, split: str = "all") -> Predictions:
    """Each model of `run` (flexff evaluate's folder or a training run) on the machine
    dataset `data` (`split`: all, train, test): per trajectory the measured efforts raw and
    filtered as the labels are, each model's prediction, the preprocessing used and the
    relative errors (learning.predict)."""
    from flexff.learning.predict import predict_logs

    return predict_logs(run, data, split)


def write_predictions(predictions: Predictions, out: str | Path,
                      about: dict[str, Any] | None = None) -> list[Path]:
    """`predictions` as `flexff predict` writes them: the CSV `out`, its .json and .png."""
    from flexff.learning.predict import write_predictions as write

    return write(predictions, out, about)


__all__ = ["BatchResult", "Option", "Recording", "RunConfig", "RunResult", "check", "load",
           "predict", "read", "register_builtin", "run", "run_many", "simulate", "sweep",
           "write_predictions"]
