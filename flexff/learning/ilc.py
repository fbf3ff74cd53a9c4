"""`flexff ilc`: iterative learning control on a loop's one reference, the best feedforward
force for that reference and so the limit a learned feedforward can be measured against.

Trial 0 runs the loop under PID alone; after each trial the learning filter (learning.ilc_filter)
gives the next trial's force, read as a CSV [[source]], each trial on the one run path with a
fresh noise seed. The folder gets each trial's table, feedforward.csv (the best trial's force)
and ilc.json as each trial ends (an interrupted iteration continues), e2.png at the end;
ilc.json's `noise_floor` is the part of e2 the loop's encoders cause (learning.ilc_loops).
A trial whose e2 on an axis passes DIVERGENCE times its best, whose plant gives a value that
is not finite or whose run fails ends the iteration: ilc.json's `diverged` says which and why,
the best trial stays the result, one line says so (divergence_line).

Docs: "ILC and the noise floor" (docs/explanation/ilc-noise-floor.md).
"""

from __future__ import annotations

import json
import math
import shutil
from collections.abc import Callable
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np
from matplotlib.figure import Figure
from tqdm import tqdm

from flexff.cosim.csv_text import TIME
from flexff.cosim.master import CosimError
from flexff.cosim.plots import save_figure
from flexff.cosim.recording import atomic_write
from flexff.cosim.run import output_folder
from flexff.cosim.schema import RecordConfig, RunConfig
from flexff.fmu.errors import InputError, RunError
from flexff.learning.ilc_filter import GAIN, LearningFilter, check_cutoff, check_gain
from flexff.learning.ilc_loops import IlcLoop, InverseModel, MachineLoop, Trial

ITERATIONS = 10  # learning trials after PID alone
RESULT = "feedforward.csv"
STATE = "ilc.json"
NOISE_FLOOR = "noise_floor"  # ilc.json's key: e2 per axis of the measurement noise's share
CUTOFF_SHARE = 0.15  # Q's default corner, a share of the loop's rate
# a trial whose e2 on an axis exceeds this many times that axis's best so far has diverged: a
# converging iteration's e2 wanders near its floor by a few per cent from trial to trial (the
# drive's and the manipulator's, 10 trials), a diverging one grows geometrically
DIVERGENCE = 2.0
DIVERGED = "diverged"  # ilc.json's key: the trial that ended the iteration, and why


def ilc(config: RunConfig, out: str | Path, iterations: int | None = None,
        cutoff_hz: float | None = None, progress: bool = True,
        say: Callable[[str], None] = print, model: InverseModel | None = None,
        floor: bool = True, gain: float | None = None) -> dict[str, Any]:
    """Run PID alone and `iterations` learning trials of `config` (continuing the iteration in
    `out` where one with the same loop, cutoff and gain is there); return the content of
    ilc.json. `iterations`, `cutoff_hz` and the learning `gain` default to the loop's
    `[machine.ilc]` settings, else ITERATIONS, the cutoff below and GAIN. A diverging
    iteration stops (DIVERGENCE), keeps its best trial and says so in one line.
    The loop's [machine] description says what it learns: each axis's feedforward input
    (learning.ilc_loops.MachineLoop), through the learning filter of `model` (by default the
    model its `[machine.ilc] model` names, else the linear model identified on trial 0).
    Q's corner `cutoff_hz` defaults to CUTOFF_SHARE of the rate (measured on the drive
    example, 12 trials: 35x PID alone at 20 Hz, 48x at 60 Hz, 163x at 150 Hz, where the rigid
    model still holds below its 250 Hz mount). `floor` measures the noise floor after the last
    trial (two more runs; learning.ilc_labels, which wants only the force, leaves it out)."""
    settings = config.machine.ilc if config.machine is not None else None
    if iterations is None:
        iterations = (settings and settings.iterations) or ITERATIONS
    if iterations < 1:
        raise InputError(f"--iterations must be at least 1, got {iterations}")
    gain = gain if gain is not None else (settings and settings.gain) or GAIN
    check_gain(gain)
    plain = replace(config, record=RecordConfig(csv=False))
    loop: IlcLoop = MachineLoop(plain, model)
    if cutoff_hz is None:
        cutoff_hz = (settings and settings.cutoff_hz) or CUTOFF_SHARE / config.step
    check_cutoff(cutoff_hz, config.step)
    out = output_folder(out)
    (out / "tables").mkdir(exist_ok=True)
    identity = {"loop": loop.identity(), "cutoff_hz": cutoff_hz, "gain": gain}
    state = _resumed(out, identity)
    if not state["trials"]:
        _write_table(out / "tables" / "trial-000.csv", plain.step,
                     np.zeros((plain.steps + 1, len(loop.columns))), loop.columns)
    done = len(state["trials"])
    stopped = DIVERGED in state
    if done:
        say(f"{out}: {done} trial(s) there" + (", continuing" if done <= iterations
                                                and not stopped else ""))
    if stopped:
        say(divergence_line(state))
    filter_: LearningFilter | None = None
    ran = done <= iterations and not stopped
    with tqdm(total=iterations + 1, initial=min(done, iterations + 1), unit="trial",
              disable=not progress or stopped, desc="ILC") as bar:
        for trial in range(done, iterations + 1 if ran else done):
            ran_trial, reason = _trial(loop, out / "tables" / f"trial-{trial:03d}.csv", trial)
            if ran_trial is not None:
                if filter_ is None:
                    filter_ = replace(loop.learning_filter(ran_trial.recording, cutoff_hz),
                                      gain=gain)
                _write_table(out / "tables" / f"trial-{trial + 1:03d}.csv", plain.step,
                             filter_.update(ran_trial.applied, ran_trial.error), loop.columns)
                state["trials"].append(_trial_record(trial, ran_trial.seed,
                                                     loop.metrics(ran_trial.recording),
                                                     state["trials"]))
                reason = _growth(state["trials"], loop.axes)
            if reason is not None:
                state[DIVERGED] = {"trial": trial, "reason": reason}
            _finish(out, state, loop)
            bar.update()
            if reason is not None:
                say(divergence_line(state))
                break
            bar.set_postfix_str(", ".join(f"e2 {a} {state['trials'][-1][a]['e2']:.3g}"
                                          for a in loop.axes))
    if floor and (ran or NOISE_FLOOR not in state):
        state[NOISE_FLOOR] = loop.noise_floor(out / RESULT)
        _finish(out, state, loop)
        ran = True
    if ran or not (out / "e2.png").is_file():  # a finished iteration's plot stays (1 s)
        plot_trials(state["trials"], out / "e2.png", state.get(NOISE_FLOOR), loop.axes,
                    loop.unit)
    return state


def _trial(loop: IlcLoop, table: Path, trial: int) -> tuple[Trial | None, str | None]:
    """Run one trial: the trial, or None and why it diverged (its run failed, or its plant
    gave a value that is not finite). Trial 0, PID alone, is the loop's own: its failure is
    an error, not the iteration's."""
    try:
        ran = loop.trial(table, trial)
    except CosimError as error:
        if trial == 0:
            raise
        return None, f"its run failed: {str(error).splitlines()[0]}"
    if not (np.all(np.isfinite(ran.applied)) and np.all(np.isfinite(ran.error))):
        if trial == 0:
            raise RunError("under PID alone the loop's effort or position is not finite: "
                           "the loop itself is unstable on this reference")
        return None, "the plant gave a value that is not finite"
    return ran, None


def _growth(trials: list[dict[str, Any]], axes: tuple[str, ...]) -> str | None:
    """Why the last of `trials` diverged (its e2 on an axis beyond DIVERGENCE times that axis's
    best before), None while it did not."""
    if len(trials) < 2:
        return None
    last = trials[-1]
    for axis in axes:
        best = min(t[axis]["e2"] for t in trials[:-1])
        if not last[axis]["e2"] <= DIVERGENCE * best:
            return (f"e2 on {axis} grew to {last[axis]['e2']:.3g}, "
                    f"{last[axis]['e2'] / best:.3g}x its best {best:.3g}")
    return None


def divergence_line(state: dict[str, Any]) -> str:
    """One line: which trial diverged, why, and which trial the iteration keeps."""
    diverged = state[DIVERGED]
    return (f"ILC diverged at trial {diverged['trial']} ({diverged['reason']}): stopped, "
            f"keeping trial {state['best']}, the best so far; a lower cutoff or gain, or a "
            f"better model of the plant, may converge")


def _trial_record(trial: int, seed: int | None, metrics: dict[str, dict[str, float]],
                  before: list[dict[str, Any]]) -> dict[str, Any]:
    """One trial's line in ilc.json: its norms per axis and their ratio PID alone / trial."""
    pid = before[0] if before else metrics
    return {"trial": trial, "seed": seed, **{a: {**m, "e2_ratio": (
        pid[a]["e2"] / m["e2"] if m["e2"] > 0 else None)} for a, m in metrics.items()}}


def _finish(out: Path, state: dict[str, Any], loop: IlcLoop) -> None:
    """After a trial: the best trial's table as the result, and ilc.json."""
    trials = state["trials"]
    best = min(trials, key=lambda t: math.hypot(*(t[a]["e2"] for a in loop.axes)))["trial"]
    state["best"] = best
    atomic_write(out / RESULT, lambda tmp: shutil.copyfile(
        out / "tables" / f"trial-{best:03d}.csv", tmp))
    text = json.dumps(state, indent=2) + "\n"
    atomic_write(out / STATE, lambda tmp: tmp.write_text(text, "utf-8"))


def _resumed(out: Path, identity: dict[str, Any]) -> dict[str, Any]:
    """ilc.json of an earlier iteration of the same loop, cutoff and gain in `out` (its trials
    whose next table is there), a fresh state in an empty folder; InputError for another
    iteration's folder. A record from before the gain was a setting learned with GAIN."""
    path = out / STATE
    if not path.is_file():
        return {**identity, "trials": []}
    try:
        state = json.loads(path.read_text("utf-8"))
        state.setdefault("gain", GAIN)
        same = all(state[k] == v for k, v in identity.items())
        trials = state["trials"]
    except (ValueError, KeyError, TypeError):
        raise InputError(f"{path}: not the record of an ILC run: choose another output "
                         f"folder") from None
    if not same:
        raise InputError(f"{out} holds an ILC run of another loop, cutoff or gain: choose "
                         f"another output folder, or delete it to start again")
    kept = 0  # the trials, in order, whose next table is there
    while kept < len(trials) and trials[kept]["trial"] == kept and (
            out / "tables" / f"trial-{kept + 1:03d}.csv").is_file():
        kept += 1
    return {**state, "trials": trials[:kept]}


def _write_table(path: Path, step: float, force: np.ndarray, columns: tuple[str, ...]) -> None:
    """The feedforward (n, len(columns)) at t = 0, step, ... as a CSV time table."""
    time = np.arange(force.shape[0]) * step
    header = ",".join([TIME, *columns])
    atomic_write(path, lambda tmp: np.savetxt(tmp, np.column_stack([time, force]),
                                              fmt="%.17g", delimiter=",", header=header,
                                              comments=""))


def plot_trials(trials: list[dict[str, Any]], path: Path,
                floor: dict[str, float] | None, axes: tuple[str, ...], unit: str) -> Path:
    """e2 per axis against trial (log scale), trial 0 being PID alone, and the noise `floor`
    per axis (dashed) where there is one."""
    figure = Figure(figsize=(6.5, 4))
    ax = figure.subplots()
    numbers = [t["trial"] for t in trials]
    for axis in axes:
        line, = ax.semilogy(numbers, [t[axis]["e2"] for t in trials], "o-", ms=4,
                            label=f"e2 {axis}")
        if floor is not None:
            ax.axhline(floor[axis], ls="--", lw=1, color=line.get_color(),
                       label=f"noise floor {axis}")
    ax.set(xlabel="trial (0: PID alone)", ylabel=f"e2 [{unit}/√s]",
           title="iterative learning control: tracking error per trial")
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(loc="upper right")
    return save_figure(figure, path)
