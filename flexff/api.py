"""flexff from Python: the command line's verbs as functions, over the same package functions.

    from flexff import api

    config = api.load("run.toml")                # TOML or SSP, checked like `flexff run`
    recording = api.simulate(config)             # in memory: recording["vdp.x0"], .time
    metrics = api.run(config, "out")             # into a folder, as `flexff run ... -o out`
    configs = api.sweep("run.toml", {"fmu.vdp.parameters.mu": [0.5, 1.5]})
    results = api.run_many(configs, "sweep")     # in parallel, one subfolder each
    data = api.collect("data", "drive.toml")     # flexff data collect --config drive.toml
    api.identify("data", "prior"); api.train("tcn", "data", "run"); api.export("run", "m.onnx")
    api.ilc("drive.toml", "ilc"); api.evaluate("eval", loop="drive.toml")

Each function's docstring ends with an example, run in turn by tests/flexff/test_api_examples.py
(drive.toml: machines/examples). PyTorch loads only in the functions that train or run a model.
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

if TYPE_CHECKING:  # learning loads numpy, scipy and PyTorch: only in the function that runs
    from flexff.learning.collect import CollectionReport
    from flexff.learning.machine_dataset import MachineDataset
    from flexff.learning.predict import Predictions
    from flexff.learning.workflow import Evaluation, Identified

Loop = RunConfig | str | Path  # a loaded run configuration, or its TOML or SSP file


def _loaded(loop: Loop | None) -> RunConfig | None:
    """`loop` as a RunConfig, read (and checked) where it is a file's name."""
    return loop if loop is None or isinstance(loop, RunConfig) else load(loop)


def collect(out: str | Path, loop: Loop | None = None, set_name: str | None = None,
            **options: Any) -> CollectionReport | MachineDataset:
    """A training dataset collected into the folder `out` under the loop's feedback, as
    `flexff data collect`: a `loop` with a [machine] on its excitation (its MachineDataset),
    else the manipulator's trajectory set `set_name` ("sim", "hardware") on `loop` or its
    built-in plant (the CollectionReport). `options`: learning.workflow.collect_data's
    (n_train, n_test, duration, classes, workers, scheduler, draws, progress).

    >>> data = api.collect("data", "drive.toml", n_train=2, n_test=1, duration=2.0,
    ...                    progress=False)
    >>> len(data.trajectories), len(data.split("test"))
    (3, 1)
    """
    from flexff.learning.workflow import collect_data

    return collect_data(out, set_name, _loaded(loop), **options)


def identify(data: str | Path, out: str | Path, **options: Any) -> Identified:
    """The physics prior of the dataset folder `data` identified by least squares on its
    training split, identified.json written into the folder `out`, as `flexff identify`.
    `options`: learning.workflow.identify_prior's (env, say).

    >>> identified = api.identify("data", "prior", say=lambda line: None)
    >>> identified.path.name
    'identified.json'
    """
    from flexff.learning.workflow import identify_prior

    return identify_prior(data, out, **options)


def train(model: str, data: str | Path, out: str | Path, **options: Any) -> dict[str, Any]:
    """The network `model` ("lstm", "cnn-lstm", "tcn", "pgnn") trained on the dataset folder
    `data` into the run folder `out`, as `flexff train`; its metrics. `options`:
    learning.workflow.train_model's (preset, epochs, seeds, device, resume, force, ...).

    >>> metrics = api.train("tcn", "data", "run", epochs=1, device="cpu", progress=False)
    >>> metrics["epochs"]
    1
    """
    from flexff.learning.workflow import train_model

    return train_model(model, data, out, **options)


def export(run: str | Path, out: str | Path, **options: Any) -> Path:
    """The training run folder `run` (or a list of runs of one kind: their mean) as the ONNX
    file `out`, as `flexff export`; its path. `options`: learning.export.export's (inputs).

    >>> api.export("run", "tcn.onnx").name
    'tcn.onnx'
    """
    from flexff.learning.export import export as export_run

    return export_run(run, out, **options)


def ilc(loop: Loop, out: str | Path, **options: Any) -> dict[str, Any]:
    """Iterative learning control on the loop's one reference into the folder `out`, as
    `flexff ilc`: the content of its ilc.json (each trial's errors, the best trial). `options`:
    learning.ilc.ilc's (iterations, cutoff_hz, gain, floor, progress, say).

    >>> import dataclasses
    >>> short = api.check(dataclasses.replace(api.load("drive.toml"), stop=1.0))
    >>> state = api.ilc(short, "ilc", iterations=1, floor=False, progress=False,
    ...                 say=lambda line: None)
    >>> len(state["trials"])  # PID alone, then one learning trial
    2
    """
    from flexff.learning.ilc import ilc as learn

    config = _loaded(loop)
    assert config is not None
    return learn(config, out, **options)


def evaluate(out: str | Path, loop: Loop | None = None, **options: Any) -> Evaluation:
    """Collect, train, export and compare each model's feedforward against PID alone into the
    folder `out`, as `flexff evaluate`: on a `loop` with a [machine], on a machine's dataset
    `data` with no loop (each model's effort prediction), else on the manipulator's `env`.
    `options`: learning.workflow.evaluate_any's (data, env, models, preset, epochs, ...).

    >>> evaluation = api.evaluate("eval", data="data", models=["tcn"], epochs=1, device="cpu",
    ...                           progress=False, say=lambda line: None)
    >>> evaluation.kind, (evaluation.out / "table.md").exists()
    ('logs', True)
    """
    from flexff.learning.workflow import evaluate_any

    return evaluate_any(out, loop=_loaded(loop), **options)


def predict(run: str | Path, data: str | Path, split: str = "all") -> Predictions:
    """Each model of `run` (flexff evaluate's folder or a training run) on the machine
    dataset `data` (`split`: all, train, test): per trajectory the measured efforts raw and
    filtered as the labels are, each model's prediction, the preprocessing used and the
    relative errors (learning.predict).

    >>> predictions = api.predict("eval", "data", split="test")
    >>> "tcn" in predictions.relative_error
    True
    """
    from flexff.learning.predict import predict_logs

    return predict_logs(run, data, split)


def write_predictions(predictions: Predictions, out: str | Path,
                      about: dict[str, Any] | None = None) -> list[Path]:
    """`predictions` as `flexff predict` writes them: the CSV `out`, its .json and .png.

    >>> written = api.write_predictions(predictions, "predictions.csv")
    >>> written[2].name
    'predictions.png'
    """
    from flexff.learning.predict import write_predictions as write

    return write(predictions, out, about)


__all__ = ["BatchResult", "Option", "Recording", "RunConfig", "RunResult", "check", "collect",
           "evaluate", "export", "identify", "ilc", "load", "predict", "read",
           "register_builtin", "run", "run_many", "simulate", "sweep", "train",
           "write_predictions"]
