"""run_config: one configured run, from TOML (or SSP) to a folder of results.

The folder gets the record (cosim.recording), metrics.json (cosim.metrics and what built-ins
add), the plots (cosim.plots), the FMUs' messages (cosim.fmu_log) and run.json (the checked
configuration in the general form and what the record holds). Record, metrics, plots and
timing are fed chunk by chunk (RunSink), the messages line by line, so memory does not grow
with the run. A run holds its folder's lock (cosim.folder_lock), checks folder, memory and disk
(cosim.disk) before it starts, and, when an FMU fails, Ctrl-C or SIGTERM stops it or the disk
is full, keeps the record so far and writes run.json before raising.

The run folder: "File formats" (docs/reference/file-formats.md); errors and exit codes: "Exit
codes and errors" (docs/reference/exit-codes.md).
"""

from __future__ import annotations

import dataclasses
import errno
import json
import tempfile
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from flexff.cosim.builtins import registered
from flexff.cosim.config import FAULTS, RECORDED, expanded, load_config
from flexff.cosim.config_error import ConfigError
from flexff.cosim.disk import check_disk
from flexff.cosim.fmu_log import LOG_NAME, FmuLog
from flexff.cosim.folder_lock import folder_lock
from flexff.cosim.handover import Worker
from flexff.cosim.master import CosimError, Master, Streamed
from flexff.cosim.memory import MemoryNeeded, check_memory
from flexff.cosim.metrics import (
    SUMMARY,
    TrackedAxis,
    Tracking,
    machine_axes,
    metrics_axes,
    named_axes,
    summary_metrics,
)
from flexff.cosim.plots import RunPlots, plot_tet
from flexff.cosim.plugins import metrics_warnings, short_names
from flexff.cosim.realtime import realtime_process
from flexff.cosim.recording import (
    PARQUET_NAME,
    RecordError,
    Recording,
    RecordWriter,
    atomic_write,
    signal_name,
)
from flexff.cosim.scenario import Scenario, resolve, sampled_reference
from flexff.cosim.schema import RunConfig
from flexff.cosim.timing import OverrunError, Pacing
from flexff.cosim.watchdog import watchdog

METRICS_NAME, RUN_JSON_NAME = "metrics.json", "run.json"  # in the run's folder


def load_run_config(path: str | Path) -> RunConfig:
    """A run configuration from a TOML file or an SSP file (by its suffix).

    >>> config = api.load("run.toml")  # flexff config example third-party-fmus > run.toml
    """
    if Path(path).suffix.lower() == ".ssp":
        from flexff.cosim.ssp import load_ssp
        return load_ssp(path)
    return load_config(path)


def output_folder(path: str | Path) -> Path:
    """Create the folder `path` (and its parents) and check that a file can be written in it:
    an existing file, a read-only file system or a missing permission is an OSError naming
    the path, raised before any work."""
    path = Path(path)
    existing = next((p for p in (path, *path.parents) if p.exists()), None)
    if existing is not None and not existing.is_dir():
        raise NotADirectoryError(errno.ENOTDIR, "is a file, not a folder", str(existing))
    path.mkdir(parents=True, exist_ok=True)
    try:
        with tempfile.TemporaryFile(dir=path):
            pass
    except OSError as error:  # named after the folder, not the probe's temporary file
        raise OSError(error.errno, error.strerror, str(path)) from None
    return path


def check_recording_memory(config: RunConfig, signals: int) -> None:
    """Refuse a run whose (steps + 1) x `signals` float64 values do not fit into the
    available memory, before anything allocates them (ConfigError naming run.stop and
    run.step)."""
    try:
        check_memory((config.steps + 1) * signals, f"recording {signals} signals at "
                                                   f"{config.steps + 1} points")
    except MemoryNeeded as error:
        raise ConfigError(config.origin, "run.stop, run.step",
                          f"{error}: record fewer signals ([record] signals), shorten "
                          f"run.stop or enlarge run.step") from None


def _check_source_memory(config: RunConfig) -> None:
    """A streamed run holds its sampled reference whole: refuse one that does not fit."""
    if config.reference is None:
        return
    signals = _reference_count(config)
    try:
        check_memory((config.steps + 1) * signals, f"sampling the reference's {signals} "
                                                   f"signals at {config.steps + 1} points")
    except MemoryNeeded as error:
        raise ConfigError(config.origin, "run.stop, run.step",
                          f"{error}: shorten run.stop or enlarge run.step") from None


def _least_signals(config: RunConfig) -> int:
    """The columns any run of `config` holds: time, the reference, the recorded signals."""
    return (1 + _reference_count(config) * (config.reference is not None)
            + len(config.record.signals or ()))


def _reference_count(config: RunConfig) -> int:
    """The signals a run's [reference] gives (none without one)."""
    reference = sampled_reference(config)
    return 0 if reference is None else len(reference.signals())


def _wanted(scenario: Scenario, master: Master, axes: Sequence[TrackedAxis]) -> list[str]:
    """The signals a run records: its [record] signals (all by default) plus those the
    metrics and plots of its tracked `axes` and a [machine]'s dataset need."""
    wanted = scenario.config.record.signals
    if wanted is None:
        return [*master.signals, *master.typed_signals]
    for name in wanted:
        try:
            master.resolve(name)
        except ValueError as error:
            raise ConfigError(scenario.config.origin, "record.signals", str(error)) from None
    tracked = sorted({n for a in axes for n in (*a.reference.names, *a.position.names,
                                                *(e for e in (a.feedforward, a.effort) if e))})
    return [*wanted, *(n for n in dict.fromkeys((*tracked, *_machine_signals(scenario.config)))
                       if n not in wanted and _known(master, n))]


def _machine_signals(config: RunConfig) -> tuple[str, ...]:
    """What a dataset, ILC and the evaluation read of a run of a loop with a [machine]: each
    axis's reference derivatives, measured position's signals and effort."""
    if config.machine is None:
        return ()
    return tuple(n for a in config.machine.axes
                 for n in (*a.derivatives, *sorted(a.measured.names), a.effort))


def simulate(scenario: Scenario, progress: bool | None = None, pacing: Pacing | None = None,
             cpu: int | None = None) -> Recording:
    """Run a resolved scenario, its record held in memory (all of it: run_config streams it
    into a folder instead); the recording holds its [record] signals (all by default) plus
    those the metrics and plots need. With `pacing` the steps follow the wall clock, in a
    process set up for real time (cosim.realtime: pinned to `cpu`, SCHED_FIFO, locked memory
    where permitted); the recording's timing then carries that setup's report."""
    with scenario.master() as master:
        wanted = _wanted(scenario, master, tracked_axes(scenario, master))
        check_recording_memory(scenario.config, 1 + len(wanted))
        if pacing is None:
            return master.run(scenario.sources, scenario.steps, wanted, progress)
        with realtime_process(cpu) as process:
            recording = master.run(scenario.sources, scenario.steps, wanted, progress, pacing)
        return dataclasses.replace(recording, timing=dataclasses.replace(
            recording.timing, process=process))


class RunSink:
    """Where run_config's run hands its record, chunk by chunk: the record's file
    (RecordWriter) under the names `kept` gives (file name -> recorded name), every `every`-th
    point (k = 0, every, 2 every, ...), the tracking
    metrics of the tracked `axes` where the record holds them, and the plots if `plot`."""

    def __init__(self, folder: Path, recorded: Sequence[str], kept: dict[str, str],
                 points: int, step: float, plot: bool, every: int = 1,
                 axes: Sequence[TrackedAxis] = ()) -> None:
        self.writer, self.kept, self.every = RecordWriter(folder), kept, every
        self.tracking = Tracking(recorded, step, axes) \
            if axes and Tracking.tracks(recorded, axes) else None
        self.plots = RunPlots(recorded, points, step, axes) if plot else None
        self.last_time: float | None = None  # of the last point handed over

    def write(self, k0: int, time: np.ndarray, columns: Mapping[str, np.ndarray]) -> None:
        if time.size:
            self.last_time = float(time[-1])
        kept = slice((-k0) % self.every, None, self.every)
        self.writer.write(time[kept], {name: columns[source][kept]
                                       for name, source in self.kept.items()})
        if self.tracking is not None:
            self.tracking.add(columns)
        if self.plots is not None:
            self.plots.add(k0, columns)


def tracked_axes(scenario: Scenario, master: Master) -> tuple[TrackedAxis, ...]:
    """The axes a run's metrics and plots track: its machine description's (a short form's
    included; each feedforward input as the signal that feeds it, for the plots); without
    one, each reference position `<axis>_ref` (of its [reference], or a [[source]] signal of
    that name) whose `<axis>` the run has (named_axes)."""
    config = scenario.config
    if config.machine is not None:
        fed = {f"{k.consumer}.{k.input}": k.from_name for k in scenario.links if not k.affine}
        return tuple(dataclasses.replace(a, feedforward=fed.get(a.feedforward or ""))
                     for a in machine_axes(config.machine))
    reference = sampled_reference(config)
    signals = {} if reference is None else reference.signals()
    positions = (*(() if reference is None else reference.positions),
                 *(n for n in scenario.sources if n not in signals))
    return named_axes(tuple(axis for axis in (p.removesuffix("_ref") for p in positions
                                              if p.endswith("_ref"))
                            if axis and _known(master, axis)))


def _known(master: Master, name: str) -> bool:
    try:
        master.resolve(name)
    except ValueError:
        return False
    return True


def simulate_config(config: RunConfig, progress: bool | None = None) -> Recording:
    """Resolve a configuration (built-ins into a temporary folder) and run it.

    >>> recording = api.simulate(config, progress=False)
    >>> len(recording["vdp.x0"]) == len(recording.time)
    True
    """
    check_recording_memory(config, _least_signals(config))
    with tempfile.TemporaryDirectory(prefix="flexff-fmus-") as folder:
        return simulate(resolve(config, folder), progress)


def builtin_metrics(scenario: Scenario) -> dict[str, Any]:
    """The entries the run's built-ins add to metrics.json (cosim.builtins: a learned
    feedforward's `feedforward_range`, where the reference leaves the model's training
    range); the first FMU's where two give the same entry."""
    metrics: dict[str, Any] = {}
    for f in scenario.config.fmus:
        hook = registered()[f.builtin].metrics if f.builtin else None
        if hook is not None:
            for key, value in hook(f, scenario.reference(), scenario.step).items():
                metrics.setdefault(key, value)
    return metrics


def run_warnings(metrics: Mapping[str, Any]) -> list[str]:
    """The lines the machine packages' metrics warnings (cosim.plugins) make of a run's
    metrics; none where they hold no entry of a built-in (builtin_metrics), whose packages a
    plain run does not load."""
    if all(k in SUMMARY for k in set(metrics) - set(metrics_axes(metrics))):
        return []
    return [line for warning in metrics_warnings() if (line := warning(metrics))]


def _write_json(path: Path, data: dict[str, Any]) -> None:
    text = json.dumps(data, indent=2, default=str) + "\n"
    atomic_write(path, lambda tmp: tmp.write_text(text))


def _kept(recorded: Sequence[str], config: RunConfig) -> dict[str, str]:
    """The record's columns, file name -> recorded name: the signals the configuration asked
    for, and in a run of the machine packages (one with a [reference] or a built-in FMU) the
    short names they register (cosim.plugins.short_names) beside their full ones."""
    names = config.record.signals
    kept = {n: n for n in (recorded if names is None else names)}
    packaged = config.reference is not None or any(f.builtin for f in config.fmus)
    for short in short_names() if packaged else ():
        if short in kept or (names is not None and not any(
                n.partition(".")[2] == short for n in names)):
            continue
        try:
            kept[short] = signal_name(recorded, short)
        except KeyError:
            pass
    return kept


def run_config(config: RunConfig | str | Path, output_dir: str | Path,
               progress: bool | None = None, pacing: Pacing | None = None,
               cpu: int | None = None) -> dict[str, Any]:
    """Run one configuration (or the TOML / SSP file at that path) into `output_dir`, its
    record written while it runs; return the metrics written to metrics.json. The run holds
    the folder's lock while it writes (cosim.folder_lock: a second run into the same folder
    is refused). A paced run (`pacing`) also writes tet.png, and one that its overruns
    stopped raises OverrunError after writing what it recorded. A run that fails or is
    interrupted (Ctrl-C, SIGTERM) keeps its record up to its last chunk, joined, and writes
    run.json, whose `recorded` says what the record holds.

    >>> metrics = api.run(config, "out", progress=False)
    >>> metrics["real_time_factor"] > 0
    True"""
    if not isinstance(config, RunConfig):
        config = load_run_config(config)
    _check_source_memory(config)
    out = output_folder(output_dir)
    with folder_lock(out):
        return _run_locked(config, out, progress, pacing, cpu)


def _run_locked(config: RunConfig, out: Path, progress: bool | None, pacing: Pacing | None,
                cpu: int | None) -> dict[str, Any]:
    """run_config's run, in the folder `out` it holds the lock of; it plots by default where
    it tracks an axis."""
    with tempfile.TemporaryDirectory(prefix="flexff-fmus-") as folder, \
            FmuLog(out / LOG_NAME) as log:
        scenario = resolve(config, folder)
        with scenario.master(log.write) as master:
            axes = tracked_axes(scenario, master)
            recorded = _wanted(scenario, master, axes)
            plot = bool(axes) if config.record.plot is None else config.record.plot
            check_disk(out, config, len(_kept(recorded, config)))
            sink = RunSink(out, recorded, _kept(recorded, config), config.steps + 1,
                           config.step, plot, config.record.every, axes)
            (out / METRICS_NAME).unlink(missing_ok=True)  # an earlier run's
            log.forget_earlier()
            _write_run_json(sink, scenario, out, complete=False)  # until the run has ended
            try:
                with watchdog(f"the record up to its last chunk is in {sink.writer.parts}",
                              lambda: [Path(folder), *master.scratch()]):
                    streamed = _stream(master, scenario, sink, recorded, progress, pacing, cpu)
            except RecordError as error:
                raise _unwritten(error, sink, scenario, out, complete=False) from None
            except (CosimError, KeyboardInterrupt) as error:
                if sink.last_time is None:
                    raise
                _close_record(sink, scenario, out, complete=False)
                held = sink.writer.held()
                kept = (f"the record up to t = {held['last_time']:.9g} s "
                        f"({held['points']} points) is in {out}")
                if isinstance(error, KeyboardInterrupt):
                    raise type(error)(kept) from None
                raise CosimError(f"{error}; {kept}") from None
        duration = (streamed.points - 1) * config.step
        metrics = summary_metrics(sink.tracking.metrics() if sink.tracking else {}, duration,
                                  streamed.wall_s, streamed.timing)
        metrics |= builtin_metrics(scenario)
    complete = streamed.timing.stopped_at is None
    try:
        _close_record(sink, scenario, out, complete)
    except RecordError as error:
        raise _unwritten(error, sink, scenario, out, complete) from None
    if sink.plots is not None:
        sink.plots.write(out)
    if pacing is not None:
        plot_tet(streamed.timing, out / "tet.png")
    _write_json(out / METRICS_NAME, metrics)
    if streamed.timing.stopped_at is not None:
        raise OverrunError(f"{streamed.timing.stop_message()}; the record up to there is in "
                           f"{out}")
    return metrics


def _close_record(sink: RunSink, scenario: Scenario, out: Path, complete: bool) -> None:
    """Join the record and write run.json (_write_run_json)."""
    sink.writer.close(csv=scenario.config.record.csv)
    _write_run_json(sink, scenario, out, complete)


def _write_run_json(sink: RunSink, scenario: Scenario, out: Path, complete: bool) -> None:
    """run.json: the configuration in the general form, under `recorded` what the record
    holds (its points, the times of its first and last, and whether the run reached its end;
    written first with `complete` false, so that a killed run's says so) and, under
    `description_faults`, each FMU's faults that the run went on despite
    (fmu.description_faults)."""
    config = scenario.config
    faults = {f.name: [str(fault) for fault in f.described().faults] for f in scenario.fmus}
    faults = {name: found for name, found in faults.items() if found}
    _write_json(out / RUN_JSON_NAME, {**expanded(config), RECORDED: {
        **sink.writer.held(), "every": config.record.every, "complete": complete},
        **({FAULTS: faults} if faults else {})})


def _unwritten(error: RecordError, sink: RunSink, scenario: Scenario, out: Path,
               complete: bool) -> RecordError:
    """The error of a record file that could not be written (a full disk), saying what was
    kept: the chunks written before (left as they are, since joining them takes as much space
    again) or the joined record, and run.json saying so where it can still be written."""
    try:
        _write_run_json(sink, scenario, out, complete)
    except OSError:
        pass  # the one written at the start says the record is incomplete
    held = sink.writer.held()
    where = sink.writer.parts if sink.writer.parts.is_dir() else out / PARQUET_NAME
    kept = (f"the record up to t = {held['last_time']:.9g} s ({held['points']} points) is in "
            f"{where}" if held["points"] else "no point of the record was kept")
    return RecordError(error.errno, f"{error.strerror}; {kept}", error.filename)


def _stream(master: Master, scenario: Scenario, sink: RunSink, recorded: Sequence[str],
            progress: bool | None, pacing: Pacing | None, cpu: int | None) -> Streamed:
    """master.stream, paced in a process set up for real time where `pacing` is given (each
    chunk then split, written and counted by a thread of its own, cosim.handover)."""
    if pacing is None:
        return master.stream(scenario.sources, scenario.steps, sink, recorded, progress,
                             keep_timing=False)
    worker = Worker()  # before the loop's thread takes SCHED_FIFO and its core
    try:
        with realtime_process(cpu) as process:
            streamed = master.stream(scenario.sources, scenario.steps, sink, recorded,
                                     progress, pacing, keep_timing=False, worker=worker)
    finally:
        worker.join()
    return dataclasses.replace(streamed, timing=dataclasses.replace(streamed.timing,
                                                                    process=process))
