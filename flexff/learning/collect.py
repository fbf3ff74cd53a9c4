"""Data collection: every trajectory of a set as a PID-only closed-loop co-simulation, written
in the dataset format of learning.dataset.

The loop is flexff's own or any run configuration with flexff's controller (learning.loop);
each trajectory replaces its reference, stop time, start values and seed. Files are written
atomically and the manifest last; running again into the same folder resumes, and a folder of
another set, format or loop is refused before anything runs. A failed trajectory does not stop
the others; an error that would fail all cancels the rest. Runs go to local processes or a
Dask scheduler (cosim.executor).

Docs: "Learning", section The data (docs/explanation/learning.md); the folder: "File formats"
(docs/reference/file-formats.md); "Run on a Dask cluster" (docs/how-to/dask-cluster.md).
"""

from __future__ import annotations

import errno
import json
import tempfile
import time
from collections.abc import Iterable, Iterator, Mapping
from concurrent.futures.process import BrokenProcessPool
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np
from tqdm import tqdm

from flexff.cosim.config_error import ConfigError
from flexff.cosim.executor import Finished, check_workers, execute
from flexff.cosim.recording import Recording, atomic_write
from flexff.cosim.run import simulate_config
from flexff.cosim.scenario import Scenario, reference_signals, resolve
from flexff.cosim.schema import RecordConfig, RunConfig
from flexff.fmu.cache import file_sha256
from flexff.fmu.errors import InputError, RunError
from flexff.learning.dataset import (
    COLLECTED,
    CURRENT_SIGNALS,
    ENCODER_SIGNALS,
    FORMAT,
    LABEL_SIGNALS,
    MANIFEST,
    POSITION_SIGNALS,
    REFERENCE_SIGNALS,
    SIGNALS,
    VERSION,
    save_signals,
    write_manifest,
)
from flexff.learning.encoders import warn_set_on_loop
from flexff.learning.loop import (
    OWN_TAPS,
    Tap,
    current_limit,
    dataset_taps,
    default_loop,
    loop_differences,
    loop_record,
    on_reference,
    plant_record,
)
from flexff.learning.trajectories import TrajectorySet, TrajectorySpec, trajectory_set
from flexff.plant.signals import CURRENTS, FEEDBACK_FORCES, FEEDFORWARD_FORCES, names

PROGRESS = "collection.json"  # the loop of a collection under way, until the manifest is written
STOPPING = (errno.ENOSPC, errno.EDQUOT, errno.EROFS, errno.EACCES)  # fail every trajectory


class DataFolderError(InputError):
    """The output folder belongs to another set, format, loop or trajectory definition."""


class CollectionError(RunError):
    """Some trajectories failed (the others were written); `report` says which and why."""

    def __init__(self, report: CollectionReport) -> None:
        cancelled = f", {len(report.cancelled)} not run" if report.cancelled else ""
        super().__init__(f"{len(report.failed)} of {report.total} trajectories of set "
                         f"{report.set_name!r} failed{cancelled} (run again into {report.path} "
                         f"to retry them):\n" + "\n".join(report.problems()))
        self.report = report


@dataclass(frozen=True)
class Outcome:
    """One trajectory run: wall seconds and the largest commanded current, or its error (one
    line), or that it was cancelled before it started."""

    name: str
    seconds: float = 0.0
    max_current: float = 0.0  # A, over the three motors and the whole 1 kHz run
    saturated: float = 0.0  # share of the run's samples with a commanded |i| >= i_max (NaN:
    # a plant FMU by path, whose limit is not known)
    error: str | None = None
    stops_all: bool = False  # the error would fail every trajectory alike (a full disk)
    cancelled: bool = False


@dataclass(frozen=True)
class CollectionReport:
    """What a collection did: the trajectories it ran, skipped (already there) and lost."""

    path: Path
    set_name: str
    ran: tuple[Outcome, ...]
    skipped: tuple[str, ...]
    failed: tuple[Outcome, ...]
    seconds: float
    cancelled: tuple[str, ...] = ()  # not run: an error that fails every one stopped them

    @property
    def total(self) -> int:
        return len(self.ran) + len(self.skipped) + len(self.failed) + len(self.cancelled)

    @property
    def ok(self) -> bool:
        return not self.failed and not self.cancelled

    def problems(self) -> list[str]:
        """One line per failed trajectory, and one in all for those failed by the error that
        stopped the collection (a full disk), with the number cancelled."""
        lines = [f"{o.name}: FAILED: {o.error}" for o in self.failed if not o.stops_all]
        stopping = [o.name for o in self.failed if o.stops_all]
        if stopping:
            first = next(o for o in self.failed if o.stops_all)
            names = ", ".join(stopping[:5]) + (", ..." if len(stopping) > 5 else "")
            lines.append(f"stopped: {first.error} ({len(stopping)} failed with it: {names}; "
                         f"{len(self.cancelled)} not run): fix the cause (a full disk, an "
                         f"unwritable folder) and run the same command again to resume")
        return lines


@dataclass(frozen=True)
class _Job:
    config: RunConfig
    path: Path
    decimation: int
    taps: Mapping[str, Tap]
    current_limit: float | None  # A: the plant's i_max (None: not known)


@dataclass(frozen=True)
class _Folder:
    """What a dataset folder holds already: the sha256 its manifest lists per file, and the
    loop it records (None: collected by an earlier flexff, on the set's own loop)."""

    listed: Mapping[Any, Any]  # file -> sha256 as the manifest's JSON has them (unchecked)
    loop: Mapping[str, Any] | None


def collect(set_name: str, out: str | Path, workers: int | None = None,
            scheduler: str | None = None, progress: bool = True,
            limit: int | None = None, config: RunConfig | None = None, draws: int = 1) -> Path:
    """Collect trajectory set `set_name` into folder `out` (resuming what is there); return it.

    `config`: the loop to run (learning.loop; default: the set's built-in plant under PID).
    Raises CollectionError after the other trajectories finished if any failed, and
    DataFolderError if `out` holds another set or loop. `limit` collects the first `limit`
    trajectories only (the manifest then lists just those). `draws`: how many times the set's
    training trajectories are drawn (learning.trajectories.trajectory_set); a folder of fewer
    draws is completed, its trajectories are the same.
    """
    report = run_collection(set_name, out, workers, scheduler, progress, limit, config, draws)
    if not report.ok:
        raise CollectionError(report)
    return report.path


def run_collection(set_name: str, out: str | Path, workers: int | None = None,
                   scheduler: str | None = None, progress: bool = True,
                   limit: int | None = None, config: RunConfig | None = None, draws: int = 1
                   ) -> CollectionReport:
    """`collect`, returning the report instead of raising for failed trajectories."""
    start = time.perf_counter()
    trajectories = trajectory_set(set_name, draws)
    if limit is not None and limit < 1:
        raise InputError(f"limit must be at least 1, got {limit}")
    check_workers(workers)
    specs = trajectories.trajectories[:limit]
    out = Path(out)
    folder = _check_folder(out, trajectories)
    loop = config or default_loop(trajectories.variant)
    warn_set_on_loop(set_name, trajectories.variant, loop)
    decimation = _decimation(loop, trajectories)
    configs = [trajectory_config(spec, trajectories, loop) for spec in specs]
    with tempfile.TemporaryDirectory(prefix="flexff-fmus-") as fmus:
        scenario = resolve(configs[0], fmus)  # checks the wiring, fills the FMU cache
        taps, record = dataset_taps(scenario), loop_record(scenario)
    _check_loop(out, folder.loop, record, config is None)
    recorded = RecordConfig(tuple(dict.fromkeys(t.signal for t in taps.values())), csv=False)
    jobs: list[_Job] = []
    skipped: list[_Job] = []
    for c in configs:
        job = _Job(replace(c, record=recorded), out / f"{c.name}.npz", decimation, taps,
                   current_limit(loop))
        (skipped if _present(job, folder.listed.get(job.path.name)) else jobs).append(job)
    out.mkdir(parents=True, exist_ok=True)
    for stale in out.glob(".*.tmp"):  # left by an interrupted run (atomic_write's names)
        stale.unlink()
    if not (out / MANIFEST).is_file():
        text = json.dumps(record, indent=2) + "\n"
        atomic_write(out / PROGRESS, lambda tmp: tmp.write_text(text))
    outcomes = list(_execute(jobs, workers, scheduler, progress, len(specs), set_name))
    failed = tuple(o for o in outcomes if o.error is not None)
    cancelled = tuple(o.name for o in outcomes if o.cancelled)
    if not failed and not cancelled:
        _write_manifest(out, trajectories, specs, scenario, taps, record)
        (out / PROGRESS).unlink(missing_ok=True)
    return CollectionReport(out, set_name,
                            tuple(o for o in outcomes if o.error is None and not o.cancelled),
                            tuple(j.config.name for j in skipped), failed,
                            time.perf_counter() - start, cancelled)


def trajectory_config(spec: TrajectorySpec, trajectories: TrajectorySet,
                      loop: RunConfig | None = None) -> RunConfig:
    """The checked run configuration of one trajectory on `loop` (default: the set's built-in
    plant under PID), recording every signal."""
    loop = loop or default_loop(trajectories.variant)
    return replace(on_reference(loop, spec.reference, spec.name, trajectories.duration,
                                spec.seed), record=RecordConfig(None, csv=False))


def dataset_signals(recording: Recording, decimation: int = 1,
                    taps: Mapping[str, Tap] = OWN_TAPS) -> dict[str, np.ndarray]:
    """A recording as the dataset's signals (every `decimation`-th sample), in SIGNALS order
    and then the currents the controller commanded (CURRENT_SIGNALS), each read at its tap
    (learning.loop.dataset_taps; default: flexff's own loop)."""
    values = {"time": recording.time, **{n: taps[n].read(recording) for n in
                                         REFERENCE_SIGNALS + ENCODER_SIGNALS + POSITION_SIGNALS
                                         + CURRENT_SIGNALS},
              **{label: taps[fb].read(recording) + taps[ff].read(recording)  # feedback + ff
                 for label, fb, ff in zip(LABEL_SIGNALS, names(FEEDBACK_FORCES),
                                          names(FEEDFORWARD_FORCES))}}
    return {n: np.ascontiguousarray(values[n][::decimation], dtype=np.float64)
            for n in (*SIGNALS, *CURRENT_SIGNALS)}


def _decimation(loop: RunConfig, trajectories: TrajectorySet) -> int:
    """Run steps per saved sample: the loop's step must divide the set's sample period."""
    period = 1.0 / trajectories.sample_rate_hz
    ratio = period / loop.step
    if abs(ratio - round(ratio)) > 1e-9 * ratio or round(ratio) < 1:
        raise ConfigError(loop.origin, "run.step", f"{loop.step:g} s does not divide the "
                          f"{trajectories.name} set's sample period of {period:g} s")
    return round(ratio)


# -- folder -----------------------------------------------------------------------------------
def _check_folder(out: Path, trajectories: TrajectorySet) -> _Folder:
    """Refuse a folder that holds another set, format or version, or foreign trajectories;
    return what it holds."""
    if out.exists() and not out.is_dir():
        raise DataFolderError(f"{out} exists and is not a folder")
    manifest = out / MANIFEST
    listed: dict[Any, Any] = {}
    loop = None
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
        entries = found.get("trajectories")
        listed = {e.get("file"): e.get("sha256") for e in entries if isinstance(e, dict)} \
            if isinstance(entries, list) else {}
        loop = found.get("loop")
    elif (out / PROGRESS).is_file():
        try:
            loop = json.loads((out / PROGRESS).read_text())
        except (json.JSONDecodeError, UnicodeDecodeError):
            raise DataFolderError(f"{out / PROGRESS} is damaged: collect into another folder "
                                  f"(or delete this one)") from None
    names = {s.name for s in trajectories.trajectories}
    foreign = sorted(p.name for p in out.glob("*.npz") if p.stem not in names)
    if foreign:
        raise DataFolderError(f"{out} holds files that are no trajectories of set "
                              f"{trajectories.name!r} ({', '.join(foreign[:5])}"
                              f"{', ...' if len(foreign) > 5 else ''}): collect into another "
                              f"folder (or delete this one)")
    return _Folder(listed, loop)


def _check_loop(out: Path, found: Mapping[str, Any] | None, wanted: Mapping[str, Any],
                own: bool) -> None:
    """Refuse a folder collected on another loop than `wanted` (loop_record's form); one that
    records none is of an earlier flexff, which ran the set's `own` loop alone."""
    if found is None:
        if not own and any(p.is_file() for p in out.glob("*.npz")):
            raise DataFolderError(f"{out} holds trajectories collected on the set's own loop "
                                  f"(by an earlier flexff): collect into another folder (or "
                                  f"delete this one)")
        return
    differences = loop_differences(found, wanted)
    if differences:
        shown = "; ".join(differences[:3]) + ("; ..." if len(differences) > 3 else "")
        raise DataFolderError(f"{out} was collected on another loop ({shown}): collect into "
                              f"another folder (or delete this one)")


def _present(job: _Job, listed: str | None) -> bool:
    """Whether job's file is already there, complete and of exactly its trajectory.

    A file that does not load (or lacks signals), or differs from the sha256 `listed` for it
    in the folder's manifest, is run again; one that loads but holds another reference or time
    grid is refused: the folder is from other trajectory definitions.
    """
    try:
        with np.load(job.path) as data:
            signals = {n: data[n] for n in (*SIGNALS, *CURRENT_SIGNALS)}
    except Exception:
        return False
    if listed is not None and file_sha256(job.path) != listed:
        return False
    c = job.config
    expected = {n: v[::job.decimation] for n, v in reference_signals(c).items()}
    expected["time"] = (np.arange(c.steps + 1) * c.step)[::job.decimation]
    if not all(np.array_equal(signals[n], v) for n, v in expected.items()):
        raise DataFolderError(f"{job.path} does not hold trajectory {c.name!r} as this flexff "
                              f"defines it (another set or trajectory version): collect into "
                              f"another folder (or delete this one)")
    return True


def _write_manifest(out: Path, trajectories: TrajectorySet, specs: Iterable[TrajectorySpec],
                    scenario: Scenario, taps: Mapping[str, Tap],
                    record: Mapping[str, Any]) -> None:
    write_manifest(out, trajectories.name, trajectories.sample_rate_hz,
                   plant_record(scenario, taps, record),
                   [{"name": s.name, "split": s.split, "file": f"{s.name}.npz",
                     "reference": s.reference, "seed": s.seed} for s in specs], COLLECTED,
                   {"loop": record})


# -- running ----------------------------------------------------------------------------------
def _collect_one(job: _Job) -> Outcome:
    """Run one trajectory and write its file; every error is returned (one line), never
    raised."""
    name = job.config.name
    try:
        recording = simulate_config(job.config, progress=False)
        save_signals(job.path, dataset_signals(recording, job.decimation, job.taps))
        currents = np.abs(np.vstack([job.taps[n].read(recording)
                                     for n in names(CURRENTS)])).max(axis=0)
        saturated = (float("nan") if job.current_limit is None else
                     float(np.mean(currents >= job.current_limit)))
        return Outcome(name, recording.wall_s, float(currents.max()), saturated)
    except Exception as error:
        return Outcome(name, error=_one_line(error),
                       stops_all=isinstance(error, OSError) and error.errno in STOPPING)


def _one_line(error: BaseException) -> str:
    return f"{type(error).__name__}: {' '.join(str(error).split())}"


def _execute(jobs: list[_Job], workers: int | None, scheduler: str | None, progress: bool,
             total: int, set_name: str) -> Iterator[Outcome]:
    """Run the jobs in parallel (cosim.executor), yielding outcomes as they finish, under a
    progress bar; after the first error that would fail every trajectory, the jobs not started
    are cancelled."""
    failed = 0
    with tqdm(total=total, initial=total - len(jobs), disable=not progress, unit="traj",
              desc=f"collect {set_name}") as bar, \
            execute(_collect_one, jobs, workers, scheduler) as running:
        stopped = False
        for finished in running:
            outcome = _outcome(jobs[finished.index], finished)
            if outcome.error is not None:
                failed += 1
                bar.set_postfix(failed=failed)
            bar.update(1)
            yield outcome
            if outcome.stops_all and not stopped:
                stopped = True
                running.cancel()


def _outcome(job: _Job, finished: Finished[Outcome]) -> Outcome:
    """The outcome of a job, also when it was cancelled or its worker died."""
    name = job.config.name
    if finished.cancelled:
        return Outcome(name, cancelled=True)
    if finished.error is not None:
        return Outcome(name, error=_one_line(finished.error),
                       stops_all=isinstance(finished.error, BrokenProcessPool))
    assert finished.result is not None
    return finished.result
