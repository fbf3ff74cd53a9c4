"""`flexff evaluate --config LOOP.toml`: the whole workflow on any machine's loop, and the
comparison an engineer would make, per axis.

The loop's dataset is collected (learning.machine_collect), its prior's linear model identified
(learning.linear_model), each model trained with the identified friction widths side by side
in worker processes (learning.train), exported and built into its feedforward FMU; then,
on the loop's own reference, the loop runs under PID alone, with the identified feedforward and
each learned one, and ILC finds the limit (learning.ilc; its settings from the arguments, else
[machine.ilc]; a diverged iteration keeps its best trial, a failed one leaves its column out,
the evaluation goes on). summary.json holds every run's e2, einf, rms and e2 ratio PID alone /
scenario per axis, the noise floor and own shares where `[machine] exact` is given, and how
ILC ended; table.md the ratios and that line; errors.png each run's tracking error per axis.

Docs: "Your own machine" (docs/tutorials/own-machine.md).
"""

from __future__ import annotations

import json
import warnings
from collections.abc import Callable, Sequence
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

from tqdm import tqdm

from flexff.controllers.learned_feedforward import learned_feedforward_system
from flexff.controllers.machine_feedforward import inverse_model_system
from flexff.cosim.executor import execute
from flexff.cosim.metrics import machine_axes, tracking_metrics
from flexff.cosim.recording import atomic_write
from flexff.cosim.run import simulate_config
from flexff.cosim.schema import RunConfig
from flexff.fmu.build import build_fmu
from flexff.fmu.errors import InputError, RunError
from flexff.learning.description_data import DescriptionData
from flexff.learning.devices import pick_device, training_gpus
from flexff.learning.excitation import CLASSES
from flexff.learning.export import export
from flexff.learning.ilc import DIVERGED, NOISE_FLOOR, divergence_line, ilc
from flexff.learning.linear_model import write_linear_model
from flexff.learning.linear_prior import LinearModel, linear_model_from_dict
from flexff.learning.machine_collect import collect_machine
from flexff.learning.machine_dataset import MachineDataset, load_machine_dataset
from flexff.learning.machine_features import MachineFeatures, friction_widths
from flexff.learning.machine_identify import dataset_features, identify_dataset
from flexff.learning.machine_loop import loop_machine, with_feedforward, with_feedforward_fmu
from flexff.learning.models import uses_prior
from flexff.learning.presets import make_config
from flexff.learning.report import own_fields, plot_tracking_errors, ratio_table
from flexff.learning.train import fit
from flexff.learning.workers import worker_count

MODELS = ("lstm", "cnn-lstm", "tcn", "pgnn")
# a model's training time on the drive example (fast preset, one core): the longest start
# first, so that the workers end together (2 cores: 140 s for all four, 160 s in MODELS' order;
# the pgnn's since measured on the rough drive, 1.2 times the TCN's)
TRAINING_SECONDS = {"pgnn": 130.0, "tcn": 108.0, "cnn-lstm": 85.0, "lstm": 55.0}
SUMMARY = "summary.json"


def evaluate_machine(loop: RunConfig, out: str | Path, models: Sequence[str] = MODELS,
                     preset: str = "fast", n_train: int = 24, n_test: int = 6,
                     duration: float = 20.0, ilc_iterations: int | None = None,
                     workers: int | None = None, progress: bool = True,
                     ilc_cutoff_hz: float | None = None, ilc_gain: float | None = None,
                     classes: Sequence[str] = CLASSES, say: Callable[[str], None] = print,
                     **overrides: Any) -> dict[str, Any]:
    """Collect, identify, train, export, build and compare on `loop`; write `out`. ILC's
    `ilc_iterations`, `ilc_cutoff_hz` and `ilc_gain` default to the loop's [machine.ilc];
    `classes` are the excitation's (learning.excitation); `say` gets the preprocessing used,
    each derived setting marked."""
    if n_test < 1:  # the comparison runs on the test trajectories
        raise InputError(f"n_test (--trajectories TRAIN TEST): {n_test!r}: the evaluation "
                         f"compares the models on the test trajectories: give at least one")
    check_settings(models, preset, overrides)
    machine = loop_machine(loop)
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    data = collect_machine(loop, out / "data", n_train, n_test, duration, classes=classes,
                           workers=workers, progress=progress)
    features, settings = dataset_features(data)
    say(settings)
    identified = identify_dataset(data, features)
    write_linear_model(identified, out / "identified.json")
    fmus = {"identified": build_fmu(inverse_model_system(
        machine, identified.casadi_function(), loop.step,
        f"identified linear model of {machine.name}", identified.lead_s),
        out / "fmus" / "identified.fmu")}
    training = train_models(data, identified, out, models, preset, workers, progress,
                            learned_features(identified), **overrides)
    for kind in models:
        fmus[kind] = build_fmu(learned_feedforward_system(
            out / "models" / f"{kind}.onnx", loop.step), out / "fmus" / f"{kind}.fmu")
    axes = machine_axes(machine)
    runs = {"pid": with_feedforward(loop),
            **{name: with_feedforward_fmu(loop, path) for name, path in fmus.items()}}
    recordings = {name: simulate_config(run, progress=False) for name, run in runs.items()}
    metrics = {name: tracking_metrics(rec, axes) for name, rec in recordings.items()}
    plot_tracking_errors(
        {name: rec.time for name, rec in recordings.items()},
        {a.name: {name: a.error(rec.signals, a.columns(rec.signals))
                  for name, rec in recordings.items()} for a in axes},
        {a.name: a.unit for a in machine.axes}, out / "errors.png")
    limit, ilc_record, ilc_line = _limit(loop, out, identified, ilc_iterations,
                                         ilc_cutoff_hz, ilc_gain, progress)
    if limit is not None:
        best = next(t for t in limit["trials"] if t["trial"] == limit["best"])
        metrics["ilc"] = {a.name: {k: best[a.name][k] for k in ("e2", "einf", "rms")}
                          for a in machine.axes}
    floor = limit.get(NOISE_FLOOR) if limit is not None else None
    summary = {"machine": machine.name, "axes": [a.name for a in machine.axes],
               **({NOISE_FLOOR: floor} if floor else {}), "ilc": ilc_record,
               "scenarios": {name: {a: {**m, "e2_ratio": metrics["pid"][a]["e2"] / m["e2"],
                                        **(own_fields(m["e2"], floor[a]) if floor else {})}
                                    for a, m in per_axis.items()}
                             for name, per_axis in metrics.items()},
               "training": {k: {"seconds": v["seconds"], "test_mse": v["test_mse"]}
                            for k, v in training.items()},
               "identified": identified.to_dict()["axes"]}
    text = json.dumps(summary, indent=2) + "\n"
    atomic_write(out / SUMMARY, lambda tmp: tmp.write_text(text, "utf-8"))
    table = summary_table(summary, ilc_line)
    atomic_write(out / "table.md", lambda tmp: tmp.write_text(table, "utf-8"))
    return summary


def summary_table(summary: dict[str, Any], ilc_line: str) -> str:
    """table.md: the e2 ratios (report.ratio_table), the ILC column headed as diverged where
    it did, and the line that says how ILC ended."""
    labels = {"ilc": "ilc (diverged: best so far)"} if DIVERGED in summary["ilc"] else None
    return ratio_table(summary, labels) + "\n" + ilc_line + "\n"


def _limit(loop: RunConfig, out: Path, identified: LinearModel, iterations: int | None,
           cutoff_hz: float | None, gain: float | None, progress: bool
           ) -> tuple[dict[str, Any] | None, dict[str, Any], str]:
    """ILC on the loop's reference with the identified model (learning.ilc): its ilc.json
    (None where it failed), the summary's record of it and a line for the table. A
    divergence or a failure is warned of in one line and leaves the evaluation going."""
    try:
        limit = ilc(loop, out / "ilc", iterations, cutoff_hz, progress=progress,
                    say=lambda _: None, gain=gain,
                    model=lambda _machine, _recording: identified.casadi_function())
    except RunError as error:
        line = f"ILC failed, its column is left out: {error}"
        warnings.warn(line, stacklevel=2)
        return None, {"failed": str(error)}, line
    record = {"best": limit["best"], "trials": len(limit["trials"]),
              "cutoff_hz": limit["cutoff_hz"], "gain": limit["gain"]}
    if DIVERGED in limit:
        line = divergence_line(limit)
        warnings.warn(line, stacklevel=2)
        return limit, {**record, DIVERGED: limit[DIVERGED]}, line
    return limit, record, (f"ILC: trial {limit['best']} the best of {len(limit['trials'])} "
                           f"(cutoff {limit['cutoff_hz']:.4g} Hz, gain {limit['gain']:g})")


def learned_features(identified: LinearModel) -> MachineFeatures:
    """The feature settings of the description (the rest derived from the data), with the
    direction widths of the machine's identified Coulomb friction
    (machine_features.friction_widths)."""
    return replace(MachineFeatures.of(identified.machine),
                   direction_widths=friction_widths(identified))


def check_settings(models: Sequence[str], preset: str, overrides: dict[str, Any]) -> None:
    """Each model's training settings made once before any work: an override that a
    configuration refuses (its name, its value) fails now, not after the collection."""
    for kind in models:
        make_config(kind, preset, **overrides)


def train_models(data: MachineDataset, identified: LinearModel, out: Path,
                 models: Sequence[str], preset: str, workers: int | None, progress: bool,
                 features: MachineFeatures, **overrides: Any) -> dict[str, dict[str, Any]]:
    """Train and export each of `models` on `data` with the feature settings `features`
    side by side in worker processes (one per core, or shared GPUs), the physics-guided one over
    `identified`, into `out`/runs/<kind> and `out`/models/<kind>.onnx; each one's metrics."""
    jobs = [_Training(kind, preset, overrides, data.path, out,
                      identified.to_dict() if uses_prior(kind) else None, features)
            for kind in sorted(models, key=lambda kind: -TRAINING_SECONDS.get(kind, 0.0))]
    gpus = len(training_gpus(pick_device(overrides.get("device", "auto"))))
    training, failed = {}, []
    with tqdm(total=len(jobs), unit="model", desc="train", disable=not progress) as bar, \
            execute(_train, jobs, worker_count(len(jobs), workers, gpus), fresh=True) as execution:
        for finished in execution:
            kind = jobs[finished.index].kind
            if finished.error is not None:
                failed.append(f"{kind}: {finished.error}")
            else:
                assert finished.result is not None
                training[kind] = finished.result
            bar.update()
    if failed:
        raise RunError(f"training failed: {'; '.join(failed)}")
    return training


@dataclass(frozen=True)
class _Training:
    """One model to train and export in a worker process: what it needs, all picklable."""

    kind: str
    preset: str
    overrides: dict[str, Any]
    data: Path
    out: Path
    prior: dict[str, Any] | None  # the identified model (learning.linear_prior), for pgnn
    features: MachineFeatures


def _train(job: _Training) -> dict[str, Any]:
    """Train `job`'s model on the dataset, export it; its metrics."""
    data = load_machine_dataset(job.data)
    prior = None if job.prior is None else linear_model_from_dict(job.prior, "the prior")
    config = make_config(job.kind, job.preset, **job.overrides)
    source = DescriptionData.of(config, data.description, data.sample_rate_hz, data.trajectories,
                                data.digest, job.features, prior)
    run = job.out / "runs" / job.kind
    metrics = source.finished(run)  # an interrupted evaluation keeps what it trained
    if metrics is None:
        metrics = fit(config, source, run, progress=False)
    export(run, job.out / "models" / f"{job.kind}.onnx")
    return metrics
