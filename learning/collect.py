"""Data collection: every trajectory of a set as a PID-only closed-loop co-simulation, written
in the dataset format of learning.dataset.

The folder gets one NAME.npz per trajectory (float64 arrays of equal length: `time`, the six
reference signals, the encoders `theta_s1..3`, the true position `x, y`, and the force the
controller applied to the wrist, Fx = Fx_fb + Fx_ff, likewise Fy) and, last, `manifest.json`
(set, sample rate, plant variant and parameters, every trajectory's reference table and seed).
A set saved at a lower rate than the 1 kHz run (hardware: 100 Hz) keeps every n-th sample of
the run: plain decimation, no anti-alias filter (the preprocessing low-pass filters at 1.8 Hz;
encoder noise above the new Nyquist frequency folds into the band).

Every file is written to a temporary name and renamed, so a folder never holds half a file.
Running again into the same folder resumes: a trajectory whose file loads and holds exactly its
reference is skipped, a missing or unreadable one is run, and leftover temporary files of an
interrupted run are deleted (so one collection per folder at a time). A folder of another set,
another dataset format or version, or with files of other trajectories is refused before
anything runs. A failed trajectory does not stop the others; the manifest is only written once
every trajectory has its file. Runs go to local processes, or to a Dask scheduler whose workers
see the same file system as this process.
"""

from __future__ import annotations

import json
import os
import tempfile
import time
import traceback
from collections.abc import Iterable, Iterator
from concurrent.futures import ProcessPoolExecutor, as_completed
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from tqdm import tqdm

from cosim.config import parse_config
from cosim.recording import Recording, atomic_write
from cosim.run import simulate_config
from cosim.scenario import reference_signals, resolve
from cosim.schema import ConfigError, RunConfig
from learning.dataset import (ENCODER_SIGNALS, FORMAT, MANIFEST, POSITION_SIGNALS,
                              REFERENCE_SIGNALS, SIGNALS, VERSION)
from learning.trajectories import TrajectorySet, TrajectorySpec, trajectory_set
from plant.model import VARIANTS
from plant.system import plant_system

CURRENTS = ("i1", "i2", "i3")
FORCES = ("Fx_fb", "Fy_fb", "Fx_ff", "Fy_ff")
RECORDED = REFERENCE_SIGNALS + ENCODER_SIGNALS + POSITION_SIGNALS + FORCES + CURRENTS
START_VALUES = ("x_start", "y_start")  # per trajectory: where its reference starts


class DataFolderError(ValueError):
    """The output folder belongs to another set, format or trajectory definition."""


class CollectionError(RuntimeError):
    """Some trajectories failed (the others were written); `report` says which and why."""

    def __init__(self, report: CollectionReport) -> None:
        lines = [f"{o.name}: {o.error}" for o in report.failed]
        super().__init__(f"{len(report.failed)} of {report.total} trajectories of set "
                         f"{report.set_name!r} failed (run again into {report.path} to retry "
                         f"them):\n" + "\n".join(lines))
        self.report = report


@dataclass(frozen=True)
class Outcome:
    """One trajectory run: wall seconds and the largest commanded current, or its error."""

    name: str
    seconds: float = 0.0
    max_current: float = 0.0  # A, over the three motors and the whole 1 kHz run
    saturated: float = 0.0  # fraction of the 1 kHz samples with a commanded |i| >= i_max
    error: str | None = None


@dataclass(frozen=True)
class CollectionReport:
    """What a collection did: the trajectories it ran, skipped (already there) and lost."""

    path: Path
    set_name: str
    ran: tuple[Outcome, ...]
    skipped: tuple[str, ...]
    failed: tuple[Outcome, ...]
    seconds: float

    @property
    def total(self) -> int:
        return len(self.ran) + len(self.skipped) + len(self.failed)

    @property
    def ok(self) -> bool:
        return not self.failed


@dataclass(frozen=True)
class _Job:
    config: RunConfig
    path: Path
    decimation: int


def collect(set_name: str, out: str | Path, workers: int | None = None,
            scheduler: str | None = None, progress: bool = True,
            limit: int | None = None) -> Path:
    """Collect trajectory set `set_name` into folder `out` (resuming what is there); return it.

    Raises CollectionError after the other trajectories finished if any failed, and
    DataFolderError if `out` holds another set. `limit` collects the first `limit` trajectories
    only (the manifest then lists just those).
    """
    report = run_collection(set_name, out, workers, scheduler, progress, limit)
    if not report.ok:
        raise CollectionError(report)
    return report.path


def run_collection(set_name: str, out: str | Path, workers: int | None = None,
                   scheduler: str | None = None, progress: bool = True,
                   limit: int | None = None) -> CollectionReport:
    """`collect`, returning the report instead of raising for failed trajectories."""
    start = time.perf_counter()
    trajectories = trajectory_set(set_name)
    if limit is not None and limit < 1:
        raise ValueError(f"limit must be at least 1, got {limit}")
    specs = trajectories.trajectories[:limit]
    out = Path(out)
    _check_folder(out, trajectories)
    jobs, skipped = [], []
    for spec in specs:
        job = _Job(run_config(spec, trajectories), out / f"{spec.name}.npz",
                   trajectories.decimation)
        (skipped if _present(job) else jobs).append(job)
    out.mkdir(parents=True, exist_ok=True)
    for stale in out.glob(".*.tmp"):  # left by an interrupted run (atomic_write's names)
        stale.unlink()
    outcomes = list(_execute(jobs, workers, scheduler, progress, len(specs), set_name))
    failed = tuple(o for o in outcomes if o.error is not None)
    if not failed:
        _write_manifest(out, trajectories, specs)
    return CollectionReport(out, set_name, tuple(o for o in outcomes if o.error is None),
                            tuple(j.config.name for j in skipped), failed,
                            time.perf_counter() - start)


def run_config(spec: TrajectorySpec, trajectories: TrajectorySet) -> RunConfig:
    """The checked PID-only run configuration of one trajectory."""
    return parse_config({
        "run": {"step": trajectories.step, "stop": trajectories.duration},
        "reference": dict(spec.reference),
        "plant": {"variant": spec.variant, "seed": spec.seed},
        "feedforward": {"kind": "none"},
        "record": {"signals": list(RECORDED), "csv": False},
    }, name=spec.name, source=f"{trajectories.name} trajectory {spec.name}")


def dataset_signals(recording: Recording, decimation: int = 1) -> dict[str, np.ndarray]:
    """A recording as the dataset's signals (every `decimation`-th sample), in SIGNALS order."""
    values = {"time": recording.time, **{n: recording[n] for n in
                                         REFERENCE_SIGNALS + ENCODER_SIGNALS + POSITION_SIGNALS},
              "Fx": recording["Fx_fb"] + recording["Fx_ff"],
              "Fy": recording["Fy_fb"] + recording["Fy_ff"]}
    return {n: np.ascontiguousarray(values[n][::decimation], dtype=np.float64) for n in SIGNALS}


# -- folder -----------------------------------------------------------------------------------
def _check_folder(out: Path, trajectories: TrajectorySet) -> None:
    """Refuse a folder that holds another set, format or version, or foreign trajectories."""
    if out.exists() and not out.is_dir():
        raise DataFolderError(f"{out} exists and is not a folder")
    manifest = out / MANIFEST
    if manifest.is_file():
        try:
            found = json.loads(manifest.read_text())
        except (json.JSONDecodeError, UnicodeDecodeError):
            found = None
        if not isinstance(found, dict) or found.get("format") != FORMAT:
            raise DataFolderError(f"{out} holds a {MANIFEST} that is not a {FORMAT!r} manifest; "
                                  f"collect into another folder")
        if found.get("version") != VERSION or found.get("set") != trajectories.name:
            raise DataFolderError(
                f"{out} holds set {found.get('set')!r} in dataset version "
                f"{found.get('version')!r}; this collects set {trajectories.name!r} in version "
                f"{VERSION}: collect into another folder (or delete this one)")
    names = {s.name for s in trajectories.trajectories}
    foreign = sorted(p.name for p in out.glob("*.npz") if p.stem not in names)
    if foreign:
        raise DataFolderError(f"{out} holds files that are no trajectories of set "
                              f"{trajectories.name!r} ({', '.join(foreign[:5])}"
                              f"{', ...' if len(foreign) > 5 else ''}): collect into another "
                              f"folder (or delete this one)")


def _present(job: _Job) -> bool:
    """Whether job's file is already there, complete and of exactly its trajectory.

    A file that does not load (or lacks signals) is run again; one that loads but holds
    another reference or time grid is refused: the folder is from other trajectory definitions.
    """
    try:
        with np.load(job.path) as data:
            signals = {n: data[n] for n in SIGNALS}
    except Exception:  # noqa: BLE001  (missing, truncated, not a zip, lacks a signal: run it)
        return False
    c = job.config
    expected = {n: v[::job.decimation] for n, v in reference_signals(c).items()}
    expected["time"] = (np.arange(c.steps + 1) * c.step)[::job.decimation]
    if not all(np.array_equal(signals[n], v) for n, v in expected.items()):
        raise DataFolderError(f"{job.path} does not hold trajectory {c.name!r} as this flexff "
                              f"defines it (another set or trajectory version): collect into "
                              f"another folder (or delete this one)")
    return True


def _write_manifest(out: Path, trajectories: TrajectorySet,
                    specs: Iterable[TrajectorySpec]) -> None:
    parameters = {p.name: p.start for p in plant_system(trajectories.variant).parameters
                  if p.name not in START_VALUES}
    manifest = {
        "format": FORMAT, "version": VERSION, "set": trajectories.name,
        "sample_rate_hz": trajectories.sample_rate_hz,
        "plant": {"variant": trajectories.variant, "parameters": parameters},
        "trajectories": [{"name": s.name, "split": s.split, "file": f"{s.name}.npz",
                          "reference": s.reference, "seed": s.seed} for s in specs],
    }
    text = json.dumps(manifest, indent=2) + "\n"
    atomic_write(out / MANIFEST, lambda tmp: tmp.write_text(text))


# -- running ----------------------------------------------------------------------------------
def _collect_one(job: _Job) -> Outcome:
    """Run one trajectory and write its file; every error is returned, never raised."""
    name = job.config.name
    try:
        recording = simulate_config(job.config, progress=False)
        signals = dataset_signals(recording, job.decimation)

        def write(tmp: Path) -> None:
            with open(tmp, "wb") as handle:  # a file object keeps numpy from adding ".npz"
                np.savez(handle, **signals)

        atomic_write(job.path, write)
        currents = np.abs(np.vstack([recording[n] for n in CURRENTS])).max(axis=0)
        variant = job.config.builtin("plant").options["variant"]
        limit = float(VARIANTS[variant].parameters.i_max)
        return Outcome(name, recording.wall_s, float(currents.max()),
                       float(np.mean(currents >= limit)))
    except Exception as error:  # noqa: BLE001  (reported; the other trajectories go on)
        detail = "" if isinstance(error, ConfigError) else \
            "\n" + "".join(traceback.format_exception(error)[-3:])
        return Outcome(name, error=f"{type(error).__name__}: {error}{detail}")


def _execute(jobs: list[_Job], workers: int | None, scheduler: str | None, progress: bool,
             total: int, set_name: str) -> Iterator[Outcome]:
    """Run the jobs in parallel, yielding outcomes as they finish, under a progress bar."""
    failed = 0
    with tqdm(total=total, initial=total - len(jobs), disable=not progress, unit="traj",
              desc=f"collect {set_name}") as bar:
        for outcome in (_on_dask(jobs, scheduler) if scheduler is not None
                        else _on_processes(jobs, workers)):
            if outcome.error is not None:
                failed += 1
                bar.set_postfix(failed=failed)
            bar.update(1)
            yield outcome


def _on_processes(jobs: list[_Job], workers: int | None) -> Iterator[Outcome]:
    if not jobs:
        return
    with tempfile.TemporaryDirectory(prefix="flexff-warm-") as folder:
        resolve(jobs[0].config, folder)  # fills the FMU cache once, not in every worker
    workers = min(workers or os.cpu_count() or 1, len(jobs))
    with ProcessPoolExecutor(max_workers=workers) as pool:
        futures = {pool.submit(_collect_one, job): job for job in jobs}
        for future in as_completed(futures):
            yield _result(future, futures[future])


def _on_dask(jobs: list[_Job], scheduler: str) -> Iterator[Outcome]:
    if not jobs:
        return
    try:
        from dask.distributed import Client
        from dask.distributed import as_completed as dask_completed
    except ImportError:
        raise RuntimeError("running on a Dask cluster needs dask.distributed: "
                           "pip install 'dask[distributed]'") from None
    with Client(scheduler) as client:
        futures = client.map(_collect_one, jobs, pure=False)
        by_future = dict(zip(futures, jobs))
        for future in dask_completed(futures):
            yield _result(future, by_future[future])


def _result(future, job: _Job) -> Outcome:
    """The future's outcome, or its error (a worker that died) as a failed outcome."""
    try:
        return future.result()
    except Exception as error:  # noqa: BLE001
        return Outcome(job.config.name, error=f"{type(error).__name__}: {error}")
