"""The loop iterative learning control (learning.ilc) runs: what a trial is.

An IlcLoop runs one trial with its feedforward from a table and says what the plant received,
how far it missed the reference and what the learning filter's model is. MachineLoop is any
loop with a [machine] description (the manipulator's short form gives its own), on the
references its sources give, each axis's feedforward input learned; the filter's model is
`model(loop, trial 0's recording)`, an inverse model of the axes' motion: the one its
`[machine.ilc] model` names (registered by a machine package, cosim.inverse_models), else the
linear model identified on trial 0. `[machine.ilc] seed` draws the loop's noise anew each trial.
"""

from __future__ import annotations

import json
import tempfile
from collections.abc import Callable
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any, Protocol

import casadi as ca
import numpy as np

from flexff.cosim.builtins import registered
from flexff.cosim.config import expanded
from flexff.cosim.config_error import ConfigError
from flexff.cosim.inverse_models import inverse_model
from flexff.cosim.metrics import error_norms, machine_axes, tracking_metrics
from flexff.cosim.recording import Recording
from flexff.cosim.run import simulate
from flexff.cosim.scenario import resolve, source_signals
from flexff.cosim.schema import FmuConfig, RunConfig
from flexff.fmu.expressions import evaluate
from flexff.fmu.importer import read_fmu
from flexff.learning import machine_loop
from flexff.learning.ilc_filter import LearningFilter, filter_along
from flexff.learning.linear_model import identify_linear


@dataclass(frozen=True)
class Trial:
    """One trial's record, the effort the plant received (n, axes) and the tracking error
    (n, axes), and the noise seed it ran with (None: the loop's own)."""

    recording: Recording
    applied: np.ndarray
    error: np.ndarray
    seed: int | None


class IlcLoop(Protocol):
    """What the iteration needs of a loop."""

    axes: tuple[str, ...]  # the axes, in the order of the tables' columns
    columns: tuple[str, ...]  # the feedforward tables' columns beside time
    unit: str  # the positions' unit

    def identity(self) -> Any:
        """The loop as an iteration in a folder must match to be continued (JSON)."""

    def trial(self, table: Path, trial: int) -> Trial:
        """Run trial number `trial` with its feedforward from `table`."""

    def learning_filter(self, recording: Recording, cutoff_hz: float) -> LearningFilter:
        """The learning filter along the reference of `recording` (trial 0's)."""

    def metrics(self, recording: Recording) -> dict[str, dict[str, float]]:
        """e2, einf, rms per axis."""

    def noise_floor(self, table: Path) -> dict[str, float] | None:
        """e2 per axis that the measurement noise causes with `table` (None: unknown)."""


def run_trial(config: RunConfig) -> tuple[Recording, Any]:
    """Run `config` once; its recording and its resolved scenario."""
    with tempfile.TemporaryDirectory(prefix="flexff-fmus-") as folder:
        scenario = resolve(config, folder)
        return simulate(scenario, progress=False), scenario


InverseModel = Callable[[RunConfig, Recording], ca.Function]  # -> (pos, vel, acc) -> effort


def identified_on_trial(loop: RunConfig, recording: Recording) -> ca.Function:
    """The linear model of the machine's prior identified on one trial: the effort the loop
    commanded against the reference's motion (learning.linear_model)."""
    machine = machine_loop.loop_machine(loop)
    motion: dict[str, np.ndarray] = {}
    for axis in machine.axes:
        motion.update(zip(axis.motion, (recording[n] for n in (axis.reference,
                                                              *axis.derivatives[:2]))))
    efforts = {a.name: recording[a.effort] for a in machine.axes}
    return identify_linear(machine, motion, efforts).casadi_function()


def described_model(loop: RunConfig) -> InverseModel:
    """The model the loop's description names (`[machine.ilc] model`), else identified_on_trial."""
    name = machine_loop.loop_machine(loop).ilc.model
    return identified_on_trial if name is None else inverse_model(name)


class MachineLoop:
    """A loop with a [machine] description: each axis's feedforward input learned on the
    references the loop's sources give (`<axis>_ref`, `v<axis>_ref`, `a<axis>_ref`)."""

    def __init__(self, config: RunConfig, model: InverseModel | None = None) -> None:
        self.config = config
        self.model = model or described_model(config)
        self.machine = machine_loop.loop_machine(config)
        self.seed_target = self._seed_target()
        given = set(source_signals(config))
        for k, axis in enumerate(self.machine.axes):
            missing = [n for n in (axis.reference, *axis.derivatives[:2]) if n not in given]
            if missing:
                raise ConfigError(config.origin, f"machine.axis[{k}]", (
                    f"the loop's sources give no {', '.join(missing)}: iterative learning "
                    f"repeats one reference; give the axis's reference, velocity and "
                    f"acceleration in a CSV [[source]] (learning.excitation writes one)"))
        self.axes = tuple(a.name for a in self.machine.axes)
        self.columns = tuple(machine_loop.feedforward_signal(a) for a in self.axes)
        units = {a.unit for a in self.machine.axes}
        self.unit = units.pop() if len(units) == 1 else "unit"

    def identity(self) -> Any:
        return json.loads(json.dumps(expanded(machine_loop.with_feedforward(self.config)),
                                     default=str))

    def trial(self, table: Path, trial: int) -> Trial:
        seed = self.seed(trial)
        recording, applied, error = self._run(machine_loop.with_feedforward(
            self._seeded(seed), table))
        return Trial(recording, applied, error, seed)

    def seed(self, trial: int) -> int | None:
        """Trial `trial`'s noise seed: the loop's own (0 where it gives none) + 1 + `trial`,
        a fresh one each trial so that the iteration learns what repeats, not one noise
        sequence; None where the description names no seed or the loop's FMU lacks it."""
        target = self.seed_target
        if target is None:
            return None
        fmu, name, option = target
        own = (fmu.options if option else fmu.parameters).get(name, 0)
        return int(own) + 1 + trial

    def _seed_target(self) -> tuple[FmuConfig, str, bool] | None:
        """(the FMU, the seed's name, whether it is a built-in's option), or None."""
        given = self.machine.ilc.seed
        if given is None:
            return None
        instance, name = given.split(".", 1)
        fmu = next((f for f in self.config.fmus if f.name == instance), None)
        if fmu is None:
            return None
        if fmu.builtin is not None:
            options = {o.key for o in registered()[fmu.builtin].options}
            return (fmu, name, True) if name in options else None
        assert fmu.path is not None  # an FMU is built in or has a path
        variable = read_fmu(fmu.path).variables.get(name)
        return (fmu, name, False) if variable is not None and variable.settable else None

    def _seeded(self, seed: int | None) -> RunConfig:
        target = self.seed_target
        if seed is None or target is None:
            return self.config
        fmu, name, option = target
        seeded = (replace(fmu, options={**fmu.options, name: seed}) if option
                  else replace(fmu, parameters={**fmu.parameters, name: seed}))
        return replace(self.config, fmus=tuple(seeded if f is fmu else f
                                               for f in self.config.fmus))

    def _run(self, config: RunConfig) -> tuple[Recording, np.ndarray, np.ndarray]:
        """The recording, the efforts (n, axes) and the tracking errors (n, axes)."""
        recording, _ = run_trial(config)
        applied = np.column_stack([recording[a.effort] for a in self.machine.axes])
        error = np.column_stack([
            recording[a.reference] - evaluate(a.evaluated, {
                n: recording[n] for n in a.evaluated.names}, f"machine.axis[{k}]")
            for k, a in enumerate(self.machine.axes)])
        return recording, applied, error

    def learning_filter(self, recording: Recording, cutoff_hz: float) -> LearningFilter:
        motion = tuple(np.column_stack([recording[n] for n in names])
                       for names in zip(*((a.reference, *a.derivatives[:2])
                                          for a in self.machine.axes)))
        return filter_along((motion[0], motion[1], motion[2]), self.config.step,
                            self.model(self.config, recording), cutoff_hz)

    def metrics(self, recording: Recording) -> dict[str, dict[str, float]]:
        return tracking_metrics(recording, machine_axes(self.machine))

    def noise_floor(self, table: Path) -> dict[str, float] | None:
        """The e2 per axis that the loop's measurement causes with the feedforward `table`:
        the e2 of the difference of its tracking errors as it is and with the description's
        `exact` start values. None where the description gives none (unknown) or where the
        loop measures exactly already (both runs alike)."""
        if not self.machine.exact:
            return None
        exact = machine_loop.with_start_values(self.config, self.machine.exact, "machine.exact")
        noisy, clean = (self._run(machine_loop.with_feedforward(c, table))[2]
                        for c in (self.config, exact))
        if np.array_equal(noisy, clean):
            return None
        return {a: error_norms(noisy[:, k] - clean[:, k], self.config.step)["e2"]
                for k, a in enumerate(self.axes)}
