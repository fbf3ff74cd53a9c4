"""The learning workflow's steps as one function each, on whatever they are given: collect on a
loop (a [machine] loop's excitation, or the manipulator's trajectory set), identify and train on
a dataset folder (a machine's or the manipulator's), evaluate a loop, an environment or imported
logs. `flexff data collect`, `identify`, `train`, `evaluate` and flexff.api call these; the
machine or manipulator path is chosen here, once. PyTorch loads only in the step that trains.

Docs: "Learning" (docs/explanation/learning.md), "Use flexff from Python"
(docs/how-to/python-api.md).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

from flexff.fmu.errors import InputError
from flexff.learning.excitation import CLASSES

if TYPE_CHECKING:  # numpy, scipy and torch load in the step that needs them
    from flexff.cosim.schema import RunConfig
    from flexff.learning.collect import CollectionReport
    from flexff.learning.dataset import Dataset
    from flexff.learning.identify import Identification
    from flexff.learning.linear_prior import LinearModel
    from flexff.learning.machine_dataset import MachineDataset


@dataclass(frozen=True)
class Identified:
    """What `identify_prior` found and wrote: the manipulator's rigid-body Identification or a
    machine's LinearModel, and the identified.json it wrote."""

    model: Identification | LinearModel
    path: Path


@dataclass(frozen=True)
class Evaluation:
    """What `evaluate_any` ran: `kind` ("machine": a loop with a [machine], "logs": a machine's
    imported logs, "manipulator": an environment of the thesis), its folder and summary."""

    kind: str
    out: Path
    summary: dict[str, Any]


def collect_data(out: str | Path, set_name: str | None = None, loop: RunConfig | None = None,
                 workers: int | None = None, scheduler: str | None = None, draws: int = 1,
                 n_train: int = 24, n_test: int = 6, duration: float = 20.0,
                 classes: Sequence[str] = CLASSES, progress: bool = True
                 ) -> CollectionReport | MachineDataset:
    """Collect a dataset into the folder `out` (resuming what is there). A `loop` with a
    [machine] runs on its excitation (`n_train` + `n_test` trajectories of `duration` s of
    `classes`, learning.machine_collect) and gives its MachineDataset; otherwise the
    manipulator's trajectory set `set_name` ("sim", "hardware") runs on `loop` (default: the
    set's built-in plant under PID; `draws`, `scheduler`: learning.collect) and gives the
    collection's report, which says what failed rather than raising."""
    from flexff.learning.collect import run_collection
    from flexff.learning.loop import is_manipulator_loop

    if loop is not None and not is_manipulator_loop(loop):
        from flexff.learning.machine_collect import collect_machine

        return collect_machine(loop, out, n_train, n_test, duration, workers=workers,
                               classes=classes, progress=progress)
    if set_name is None:
        raise InputError("data collect needs --set NAME, or --config LOOP.toml with a [machine]")
    return run_collection(set_name, out, workers, scheduler, progress=progress, config=loop,
                          draws=draws)


def import_data(files: Sequence[str | Path], out: str | Path, machine: str | Path | None = None,
                rate_hz: float | None = None, test: Sequence[str] | None = None
                ) -> Dataset | MachineDataset:
    """Import log `files` into the new dataset folder `out`, resampled to `rate_hz` (default:
    the logs' own), the logs named in `test` (default: the last one) forming the test split: a
    machine's through the [machine.log] map of the description file `machine`
    (learning.machine_logs), without one the manipulator's columns (learning.logs)."""
    if machine is None:
        from flexff.learning.logs import import_logs

        return import_logs(files, out, rate_hz, test)
    from flexff.cosim.machine import load_machine
    from flexff.learning.machine_logs import import_machine_logs

    return import_machine_logs(files, out, load_machine(machine), rate_hz, test)


def identify_prior(data: str | Path, out: str | Path, env: str = "hardware",
                   say: Callable[[str], None] = print) -> Identified:
    """Identify the physics prior of the dataset folder `data` on its training split by least
    squares and write identified.json into the folder `out` (made if missing): a machine's
    dataset its description's linear model (`say` gets the feature settings used), the
    manipulator's its rigid-body base parameters, preprocessed as the environment `env`
    ("sim", "hardware") of flexff evaluate does."""
    from flexff.cosim.run import output_folder
    from flexff.learning.identify import REPORT
    from flexff.learning.machine_dataset import is_machine_dataset

    output_folder(out)  # a folder, as for every command: made, or refused, first
    if is_machine_dataset(data):
        from flexff.learning.linear_model import write_linear_model
        from flexff.learning.machine_dataset import load_machine_dataset
        from flexff.learning.machine_identify import dataset_features, identify_dataset

        dataset = load_machine_dataset(data)
        features, settings = dataset_features(dataset)
        say(settings)
        model = identify_dataset(dataset, features)
        return Identified(model, write_linear_model(model, Path(out) / REPORT))
    from flexff.learning.evaluate import preprocessing
    from flexff.learning.identify import identify, write_identification

    identification = identify(data, *preprocessing(env))
    return Identified(identification, write_identification(identification, out))


def train_model(model: str, data: str | Path, out: str | Path, preset: str = "fast",
                seeds: Sequence[int] = (0,), epochs: int | None = None, labels: str = "forces",
                force_input: bool = False, resume: bool = False, force: bool = False,
                checkpoint_every: int | None = None, scheduler: str | None = None,
                device: str = "auto", cuda_graphs: bool = False, progress: bool = True
                ) -> dict[str, Any]:
    """Train `model` (learning.evaluate.MODELS) with `preset` ("fast", "thesis") on the dataset
    folder `data` into the run folder `out`; return its metrics. One seed trains here (`resume`,
    `force`, `checkpoint_every`: learning.run_folder); several seeds, or a Dask `scheduler`,
    train side by side into `out`/seedS, giving the metrics by seed (learning.workers). A
    machine's dataset trains one seed on its efforts, on features with the friction widths of
    its prior identified on it (the prior itself for the pgnn). `epochs` overrides the
    preset's; `labels` ("forces", "currents") and `force_input` are the manipulator's."""
    from flexff.learning.machine_dataset import is_machine_dataset

    overrides: dict[str, Any] = {} if epochs is None else {"epochs": epochs}
    if is_machine_dataset(data):
        if len(seeds) > 1 or scheduler is not None or labels != "forces" or force_input:
            raise InputError("a machine's dataset trains one seed here, on its efforts, without "
                             "--force-input (its physics is the pgnn's prior)")
        return _train_machine(model, data, out, preset, seeds[0], resume, force,
                              checkpoint_every, device, progress, overrides)
    overrides = {"labels": labels, **overrides, **({"force_input": True} if force_input else {}),
                 **({"cuda_graphs": True} if cuda_graphs else {})}
    if len(seeds) == 1 and scheduler is None:
        from flexff.learning.train import train

        return train(model, preset, data, out, progress, resume=resume, force=force,
                     checkpoint_every=checkpoint_every, **overrides, seed=seeds[0],
                     device=device)
    from flexff.learning.workers import TrainJob, train_parallel

    if resume or force or checkpoint_every is not None:
        raise InputError("--resume, --force and --checkpoint-every go with one seed trained "
                         "here; several seeds resume what their folders hold")
    if len(set(seeds)) != len(seeds):
        raise InputError(f"--seed: each seed once, got {list(seeds)}")
    jobs = [TrainJob(model, preset, Path(data), Path(out) / f"seed{s}", {**overrides, "seed": s},
                     label=f"seed{s}") for s in seeds]
    return train_parallel(jobs, progress=progress, scheduler=scheduler, device=device)


def _train_machine(model: str, data: str | Path, out: str | Path, preset: str, seed: int,
                   resume: bool, force: bool, checkpoint_every: int | None, device: str,
                   progress: bool, overrides: dict[str, Any]) -> dict[str, Any]:
    """train_model on a machine's dataset (see there)."""
    from flexff.learning.description_data import DescriptionData
    from flexff.learning.machine_dataset import load_machine_dataset
    from flexff.learning.machine_evaluate import learned_features
    from flexff.learning.machine_identify import identify_dataset
    from flexff.learning.presets import make_config
    from flexff.learning.train import fit

    dataset = load_machine_dataset(data)
    config = make_config(model, preset, seed=seed, device=device, **overrides)
    identified = identify_dataset(dataset)
    source = DescriptionData.of(config, dataset.description, dataset.sample_rate_hz,
                                dataset.trajectories, dataset.digest,
                                learned_features(identified),
                                identified if model == "pgnn" else None)
    return fit(config, source, Path(out), progress, resume=resume, force=force,
               checkpoint_every=checkpoint_every)


def evaluate_any(out: str | Path, env: str = "sim", loop: RunConfig | None = None,
                 data: str | Path | None = None, models: Sequence[str] | None = None,
                 preset: str = "fast", epochs: int | None = None, device: str = "auto",
                 scheduler: str | None = None, currents: Sequence[str] = (),
                 ilc_labels: Sequence[str] | None = None, force_input: Sequence[str] = (),
                 n_train: int = 24, n_test: int = 6, duration: float = 20.0,
                 classes: Sequence[str] = CLASSES, ilc_iterations: int | None = None,
                 ilc_cutoff_hz: float | None = None, ilc_gain: float | None = None,
                 progress: bool = True, say: Callable[[str], None] = print) -> Evaluation:
    """Collect, train, export and compare `models` (default: every kind, learning.evaluate.MODELS)
    against PID alone into the folder `out`: on `loop` when it has a [machine]
    (learning.machine_evaluate: `n_train`, `n_test`, `duration`, `classes` its excitation), on
    a machine's imported logs `data` with no loop (each model's effort prediction,
    learning.log_evaluate), else on the manipulator's environment `env` ("sim", "hardware";
    `loop`, `data`, `scheduler`, `currents`, `ilc_labels`, `force_input`: learning.evaluate).
    `ilc_*` set the ILC of a loop, `epochs` overrides the preset's."""
    from flexff.cosim.run import output_folder
    from flexff.learning.loop import is_manipulator_loop
    from flexff.learning.machine_dataset import is_machine_dataset

    machine = loop is not None and not is_manipulator_loop(loop)
    logs = loop is None and data is not None and is_machine_dataset(data)
    if logs and any(v is not None for v in (ilc_iterations, ilc_cutoff_hz, ilc_gain)):
        raise InputError("--ilc-iterations, --ilc-cutoff and --ilc-gain set the ILC of a loop: "
                         "leave them out for imported logs (no loop runs)")
    if (machine or logs) and (currents or ilc_labels is not None or force_input):
        raise InputError("--currents, --ilc-labels and --force-input are for the manipulator's "
                         f"environments: leave them out for "
                         f"{'a machine' if machine else 'imported logs'}")
    output_folder(out)
    from flexff.learning.evaluate import MODELS

    kinds = MODELS if models is None else models
    overrides: dict[str, Any] = {} if epochs is None else {"epochs": epochs}
    if machine:
        from flexff.learning.machine_evaluate import evaluate_machine

        assert loop is not None
        return Evaluation("machine", Path(out), evaluate_machine(
            loop, out, kinds, preset, n_train, n_test, duration, classes=classes,
            ilc_iterations=ilc_iterations, ilc_cutoff_hz=ilc_cutoff_hz, ilc_gain=ilc_gain,
            progress=progress, say=say, device=device, **overrides))
    if logs:
        from flexff.learning.log_evaluate import evaluate_logs

        assert data is not None
        return Evaluation("logs", Path(out), evaluate_logs(
            data, out, kinds, preset, progress=progress, say=say, device=device, **overrides))
    from flexff.learning.evaluate import evaluate

    return Evaluation("manipulator", Path(out), evaluate(
        env, out, preset, kinds, data, epochs, say=say, loop=loop, progress=progress,
        scheduler=scheduler, currents=currents, device=device, ilc_labels=ilc_labels,
        force_input=force_input, ilc_iterations=ilc_iterations, ilc_cutoff_hz=ilc_cutoff_hz,
        ilc_gain=ilc_gain))
