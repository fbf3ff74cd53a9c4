"""run_config: one configured run, from TOML (or SSP) to a folder of results.

The folder gets signals.npz (and signals.csv, see cosim.recording) with every recorded signal
named `fmu.output` (sources by their own names), and in a manipulator run the manipulator's
signals under their short names as well; metrics.json (cosim.metrics: wall time and real-time
factor, and the tracking errors where the run has a reference and a true position; with a
learned feedforward also `feedforward_range`, where the reference leaves the model's training
range); the plots (cosim.plots); and run.json, the checked configuration in the general form.
The built-in FMUs are built into the fmu/ cache and loaded from a temporary copy.

A run that an FMU's failure stops (an isolated FMU's crash or hang among them) writes the
record up to its last completed point and run.json, then raises CosimError naming the FMU, the
call, the time and the folder.

Before anything runs, the output folder must take a file and the recording must fit into the
available memory, so that neither shows only after the simulation.
"""

from __future__ import annotations

import dataclasses
import errno
import json
import tempfile
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from flexff.controllers.training_range import MARGIN, training_range_excess
from flexff.cosim.config import expanded, load_config
from flexff.cosim.master import CosimError, Master
from flexff.cosim.memory import MemoryNeeded, check_memory
from flexff.cosim.metrics import run_metrics
from flexff.cosim.plots import PLOT_SIGNALS, plot_tet, write_plots
from flexff.cosim.realtime import realtime_process
from flexff.cosim.recording import Recording, atomic_write, save_recording
from flexff.cosim.references import Reference
from flexff.cosim.scenario import Scenario, resolve
from flexff.cosim.schema import ConfigError, RunConfig
from flexff.cosim.timing import OverrunError, Pacing
from flexff.plant.signals import (
    CURRENTS,
    ENCODERS,
    FEEDBACK_FORCES,
    FEEDFORWARD_FORCES,
    REFERENCE,
    TORQUES,
    TRUE_POSITION,
    TRUE_VELOCITY,
    names,
)

# the manipulator's signals (plant.signals), kept under their short names in recordings
MANIPULATOR_SIGNALS = names(REFERENCE, FEEDFORWARD_FORCES, CURRENTS, FEEDBACK_FORCES, ENCODERS,
                            TRUE_POSITION, TRUE_VELOCITY, TORQUES)


def load_run_config(path: str | Path) -> RunConfig:
    """A run configuration from a TOML file or an SSP file (by its suffix)."""
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


def _least_signals(config: RunConfig) -> int:
    """The columns any run of `config` holds: time, the reference, the recorded signals."""
    return (1 + len(Reference.SIGNALS) * (config.reference is not None)
            + len(config.record.signals or ()))


def simulate(scenario: Scenario, progress: bool | None = None, pacing: Pacing | None = None,
             cpu: int | None = None) -> Recording:
    """Run a resolved scenario; the recording holds its [record] signals (all by default)
    plus those the metrics and plots need. With `pacing` the steps follow the wall clock, in a
    process set up for real time (cosim.realtime: pinned to `cpu`, SCHED_FIFO, locked memory
    where permitted); the recording's timing then carries that setup's report."""
    wanted: Sequence[str] | None = scenario.config.record.signals
    with scenario.master() as master:
        if wanted is not None:
            for name in wanted:
                try:
                    master.resolve(name)
                except ValueError as error:
                    raise ConfigError(scenario.config.origin, "record.signals",
                                      str(error)) from None
            extra = [n for n in PLOT_SIGNALS if n not in wanted and _known(master, n)]
            wanted = list(wanted) + extra
        recorded = len(master.signals) + len(master.typed_signals) if wanted is None else \
            len(wanted)
        check_recording_memory(scenario.config, 1 + len(master.sources) + recorded)
        if pacing is None:
            return master.run(scenario.sources, scenario.steps, wanted, progress)
        with realtime_process(cpu) as process:
            recording = master.run(scenario.sources, scenario.steps, wanted, progress, pacing)
        return dataclasses.replace(recording, timing=dataclasses.replace(
            recording.timing, process=process))


def _known(master: Master, name: str) -> bool:
    try:
        master.resolve(name)
    except ValueError:
        return False
    return True


def simulate_config(config: RunConfig, progress: bool | None = None) -> Recording:
    """Resolve a configuration (built-ins into a temporary folder) and run it."""
    check_recording_memory(config, _least_signals(config))
    with tempfile.TemporaryDirectory(prefix="flexff-fmus-") as folder:
        return simulate(resolve(config, folder), progress)


def feedforward_range(scenario: Scenario) -> dict[str, Any] | None:
    """Where the reference of a learned-feedforward run leaves the model's training range
    (controllers.training_range): {"margin", "outside": [features, farthest first]}, or None
    for a model exported without its range."""
    learned = scenario.config.learned_feedforward
    if learned is None:
        raise ValueError("the run has no learned feedforward")
    model = learned.options["model"]
    excess = training_range_excess(model, scenario.reference(), scenario.step)
    if excess is None:
        return None
    return {"margin": MARGIN, "outside": [dataclasses.asdict(e) for e in excess]}


def range_warning(metrics: dict[str, Any]) -> str | None:
    """A line saying the learned feedforward extrapolates in this run, or None."""
    outside = (metrics.get("feedforward_range") or {}).get("outside")
    if not outside:
        return None
    worst = outside[0]
    return (f"warning: the reference leaves the learned model's training range in "
            f"{len(outside)} features (worst: {worst['signal']}, {worst['spans']:.2g} spans "
            f"beyond): the feedforward extrapolates; train on motion like this reference")


def _write_json(path: Path, data: dict[str, Any]) -> None:
    text = json.dumps(data, indent=2, default=str) + "\n"
    atomic_write(path, lambda tmp: tmp.write_text(text))


def _kept(recording: Recording, config: RunConfig) -> Recording:
    """The recorded signals the configuration asked for, and in a manipulator run (one with a
    reference or one of flexff's built-in FMUs) the manipulator's short names beside their
    full ones."""
    names = config.record.signals
    signals = dict(recording.signals) if names is None else {n: recording[n] for n in names}
    manipulator = config.reference is not None or any(f.builtin for f in config.fmus)
    for short in MANIPULATOR_SIGNALS if manipulator else ():
        if short not in signals and short in recording and (names is None or any(
                n.partition(".")[2] == short for n in names)):
            signals[short] = recording[short]
    return Recording(recording.time, signals)


def run_config(config: RunConfig | str | Path, output_dir: str | Path,
               progress: bool | None = None, pacing: Pacing | None = None,
               cpu: int | None = None) -> dict[str, Any]:
    """Run one configuration (or the TOML / SSP file at that path) into `output_dir`; return
    the metrics written to metrics.json. A paced run (`pacing`) also writes tet.png, and one
    that its overruns stopped raises OverrunError after writing what it recorded."""
    if not isinstance(config, RunConfig):
        config = load_run_config(config)
    check_recording_memory(config, _least_signals(config))
    out = output_folder(output_dir)
    with tempfile.TemporaryDirectory(prefix="flexff-fmus-") as folder:
        scenario = resolve(config, folder)
        try:
            recording = simulate(scenario, progress, pacing, cpu)
        except CosimError as error:
            if error.recording is None or not error.recording.time.size:
                raise
            save_recording(_kept(error.recording, config), out, csv=config.record.csv)
            _write_json(out / "run.json", expanded(config))
            raise CosimError(f"{error}; the record up to t = {error.recording.time[-1]:.9g} s "
                             f"is in {out}") from None
        metrics = run_metrics(recording)
        if config.learned_feedforward is not None:
            metrics["feedforward_range"] = feedforward_range(scenario)
    save_recording(_kept(recording, config), out, csv=config.record.csv)
    write_plots(recording, out)
    if pacing is not None:
        plot_tet(recording.timing, out / "tet.png")
    _write_json(out / "run.json", expanded(config))
    _write_json(out / "metrics.json", metrics)
    if recording.timing.stopped_at is not None:
        raise OverrunError(f"{recording.timing.stop_message()}; the record up to there is in "
                           f"{out}")
    return metrics
