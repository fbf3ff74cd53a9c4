"""`flexff data collect --loop LOOP.toml`: any machine's closed loop (a run configuration with a
[machine] description: the user's plant and controller FMUs, flexff's or their own) run on an
excitation set (learning.excitation) under its feedback alone, recorded as a machine dataset
(learning.machine_dataset) at the loop's step.

Every trajectory starts where the loop rests (rest_positions: its measured positions at the
start of a one-step run, the plant's initial outputs) and leads from there into the
excitation (learning.excitation's starts): no trajectory begins with a step the controller
answers with a spike of effort. The excitation's tables are written to `references/` first;
each trajectory runs in a worker process (cosim.executor, one per core) and its .npz is
written as it ends, so an interrupted collection keeps what it finished: the same command
again runs only the rest. A folder of another loop or excitation is refused (collection.json
records both).
"""

from __future__ import annotations

import json
import tempfile
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from tqdm import tqdm

from flexff.cosim.config import expanded
from flexff.cosim.csv_text import TIME
from flexff.cosim.executor import execute
from flexff.cosim.recording import atomic_write
from flexff.cosim.run import simulate_config
from flexff.cosim.schema import RunConfig
from flexff.fmu.errors import InputError, RunError
from flexff.learning.excitation import CLASSES, excitation_set, write_table
from flexff.learning.machine_dataset import (
    MachineDataset,
    load_machine_dataset,
    save_trajectory,
    write_machine_manifest,
)
from flexff.learning.machine_loop import loop_machine, on_references, record_signals

SETTINGS = "collection.json"
SOURCE = "flexff data collect --loop"


@dataclass(frozen=True)
class _Job:
    loop: RunConfig
    table: Path
    duration: float
    name: str
    folder: Path


def _collect_one(job: _Job) -> None:
    run = on_references(job.loop, job.table, job.duration, job.name)
    recording = simulate_config(run, progress=False)
    machine = loop_machine(job.loop)
    save_trajectory(job.folder / f"{job.name}.npz", machine,
                    {"time": recording.time, **record_signals(recording, machine)})


def collect_machine(loop: RunConfig, out: str | Path, n_train: int = 24, n_test: int = 6,
                    duration: float = 20.0, seed: int = 0, classes: Sequence[str] = CLASSES,
                    workers: int | None = None, progress: bool = True) -> MachineDataset:
    """Run `loop` on `n_train` + `n_test` excitation trajectories of `duration` s and write
    the dataset folder `out`; return it loaded."""
    machine = loop_machine(loop)
    folder = Path(out)
    folder.mkdir(parents=True, exist_ok=True)
    starts = rest_positions(loop)
    centres = [0.5 * (a.limits.low + a.limits.high) for a in machine.axes]
    settings = {"loop": json.loads(json.dumps(expanded(loop), default=str)),
                "n_train": n_train, "n_test": n_test, "duration": duration, "seed": seed,
                "classes": list(classes),
                # where the loop rests, recorded where it is not every range's centre (a
                # collection made before trajectories started there started at the centre)
                **({"starts": dict(zip((a.name for a in machine.axes), starts))}
                   if starts != centres else {})}
    _check_folder(folder, settings)
    excitations = excitation_set(machine, n_train, n_test, duration, 1.0 / loop.step, seed,
                                 classes, origin=loop.origin, starts=starts)
    (folder / "references").mkdir(exist_ok=True)
    entries, jobs = {}, []
    for excitation in excitations:
        table = folder / "references" / f"{excitation.name}.csv"
        if not table.is_file():
            write_table(excitation, table)
        entries[excitation.name] = {"name": excitation.name, "split": excitation.split,
                                    "file": f"{excitation.name}.npz",
                                    "reference": {"kind": excitation.kind,
                                                  "table": f"references/{excitation.name}.csv"}}
        if not (folder / f"{excitation.name}.npz").is_file():
            jobs.append(_Job(loop, table, duration, excitation.name, folder))
    failed = []
    with tqdm(total=len(excitations), initial=len(excitations) - len(jobs), unit="run",
              desc="collect", disable=not progress) as bar, \
            execute(_collect_one, jobs, workers) as execution:
        for finished in execution:
            if finished.error is not None:
                failed.append(f"{jobs[finished.index].name}: {finished.error}")
            bar.update()
    if failed:
        raise RunError(f"{len(failed)} of {len(jobs)} runs failed, the others are kept in "
                       f"{folder} (run the command again for the rest): {failed[0]}")
    write_machine_manifest(folder, machine, 1.0 / loop.step, list(entries.values()), SOURCE)
    return load_machine_dataset(folder, machine)


def rest_positions(loop: RunConfig) -> list[float]:
    """Where each axis of the loop rests when it starts: its measured position (the machine's
    expression) at the start of a one-step run with the references held at the ranges'
    centres and no feedforward; the plant's initial outputs, which no reference moves yet."""
    machine = loop_machine(loop)
    held = {TIME: np.array([0.0, loop.step])}
    for axis in machine.axes:
        centre = 0.5 * (axis.limits.low + axis.limits.high)
        held[axis.reference] = np.full(2, centre)
        held |= {name: np.zeros(2) for name in axis.derivatives}
    with tempfile.TemporaryDirectory(prefix="flexff-rest-") as folder:
        table = Path(folder) / "held.csv"
        np.savetxt(table, np.column_stack(list(held.values())), fmt="%.17g", delimiter=",",
                   header=",".join(held), comments="")
        recording = simulate_config(on_references(loop, table, loop.step, "rest"),
                                    progress=False)
    signals = record_signals(recording, machine)
    return [float(signals[axis.measured_signal][0]) for axis in machine.axes]


def _check_folder(folder: Path, settings: dict[str, Any]) -> None:
    """Record the collection's settings in an empty folder; refuse a folder of others."""
    path = folder / SETTINGS
    if path.is_file():
        if json.loads(path.read_text("utf-8")) != settings:
            raise InputError(f"{folder} holds a collection of another loop or excitation: "
                             f"choose another folder, or delete it to start again")
        return
    if any(folder.iterdir()):
        raise InputError(f"{folder} is not empty and holds no collection: choose an empty "
                         f"folder")
    text = json.dumps(settings, indent=2) + "\n"
    atomic_write(path, lambda tmp: tmp.write_text(text, "utf-8"))
