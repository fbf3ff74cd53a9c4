"""Every feedforward on references its models never trained on: the test split of the set they
trained on, in closed loop. A learned feedforward is meant for any motion, not for the one
evaluation reference, so `flexff evaluate` also runs each scenario but the ILC limit (which
belongs to one reference) on each test trajectory's reference, and reports per scenario and
axis the e2 ratio PID alone / scenario on every reference, their geometric mean and the worst.

Measured on the hardware set's ten test references (six circles of 0.07 to 0.28 Hz, four
splines), e2 ratio x / y, geometric mean: identified rigid-body 194 / 199, physics-guided
225 / 221, TCN 17 / 22, CNN-LSTM 15 / 13, LSTM 10 / 13. Four of the ten leave the models'
training range (the run's feedforward_range says so); there the LSTM did worse than PID alone
(0.44 / 0.54), and the physics-guided model, before its residual faded out beyond the range
(learning.deploy.trust), fell to 7 / 9 against its prior's 40 / 44.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import replace
from pathlib import Path
from statistics import geometric_mean
from typing import Any

from tqdm import tqdm

from flexff.cosim.config import parse_config
from flexff.cosim.executor import execute
from flexff.cosim.metrics import metrics_axes
from flexff.cosim.run import run_config
from flexff.cosim.schema import RecordConfig, RunConfig
from flexff.fmu.errors import InputError, RunError
from flexff.learning.dataset import Dataset

FOLDER = "held-out"  # in flexff evaluate's output folder: one run per reference and scenario
BASE = "pid"  # the scenario every ratio divides


def _e2_of_run(job: tuple[RunConfig, Path]) -> dict[str, float]:
    """e2 per axis of one run (in a worker process)."""
    config, folder = job
    metrics = run_config(config, folder, progress=False)
    return {axis: metrics[axis]["e2"] for axis in metrics_axes(metrics)}


def references_held_out(dataset: Dataset) -> tuple[dict[str, Mapping[str, Any]], list[str]]:
    """The [reference] tables of the dataset's test trajectories, by trajectory name, and the
    names of those without one that a run takes (imported logs carry none; a synthetic
    set's splines a description of their own)."""
    runnable, other = {}, []
    for t in dataset.split("test"):
        try:
            parse_config({"reference": dict(t.reference)}, name=t.name)
        except InputError:
            other.append(t.name)
        else:
            runnable[t.name] = t.reference
    return runnable, other


def run_held_out(configs: Mapping[str, Mapping[str, RunConfig]], out: Path,
                 progress: bool = True, workers: int | None = None) -> dict[str, Any]:
    """Run `configs` (reference name -> scenario -> its run on that reference, BASE among
    them) into out/REFERENCE/SCENARIO with the least record, in up to `workers` processes
    (default: one per CPU; cosim.executor); return, per scenario but BASE, the e2 ratio BASE /
    scenario on each reference ("e2_ratio": scenario -> axis -> list in the order of
    "references"), their geometric mean and their least ("worst")."""
    keys = [(reference, name) for reference, scenarios in configs.items() for name in scenarios]
    jobs = [(replace(configs[reference][name], record=RecordConfig(signals=(), plot=False)),
             out / reference / name) for reference, name in keys]
    e2: dict[str, dict[str, dict[str, float]]] = {reference: {} for reference in configs}
    with tqdm(total=len(jobs), unit="run", desc="held-out references",
              disable=not progress) as bar, execute(_e2_of_run, jobs, workers) as running:
        for finished in running:
            reference, name = keys[finished.index]
            if finished.result is None:
                raise finished.error or RunError(f"held-out run {reference}/{name} cancelled")
            e2[reference][name] = finished.result
            bar.update()
    references = list(configs)
    names = [n for n in (configs[references[0]] if references else {}) if n != BASE]
    ratios = {name: {axis: [e2[r][BASE][axis] / e2[r][name][axis] for r in references]
                     for axis in e2[references[0]][BASE]} for name in names}
    return {"references": references, "e2_ratio": ratios,
            "geometric_mean": {name: {axis: geometric_mean(values) for axis, values
                                      in by_axis.items()} for name, by_axis in ratios.items()},
            "worst": {name: {axis: min(values) for axis, values in by_axis.items()}
                      for name, by_axis in ratios.items()}}

