"""The loops iterative learning control (learning.ilc) runs: what a trial is on each kind.

An IlcLoop runs one trial with its feedforward from a table and says what the plant received,
how far it missed the reference and what the learning filter's model is. ManipulatorLoop is
flexff's manipulator (built-in controller's Fx_ff, Fy_ff; its built-in plant's noise seeded
per trial and its noise floor measured); MachineLoop any loop with a [machine] description,
on the references its sources give, each axis's feedforward input learned, the filter's model
`model(machine, trial 0's recording)` (an inverse model of the axes' motion).
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

from flexff.cosim.config import expanded
from flexff.cosim.config_error import ConfigError
from flexff.cosim.machine import Machine
from flexff.cosim.metrics import error_norms, machine_axes, named_axes, tracking_metrics
from flexff.cosim.recording import Recording
from flexff.cosim.run import simulate
from flexff.cosim.scenario import resolve, source_signals
from flexff.cosim.schema import RunConfig
from flexff.fmu.errors import InputError
from flexff.fmu.expressions import evaluate
from flexff.learning import machine_loop
from flexff.learning.ilc_filter import LearningFilter, filter_along, learning_filter
from flexff.learning.linear_model import identify_linear
from flexff.learning.loop import dataset_taps, with_feedforward, with_feedforward_table
from flexff.plant.parameters import NOMINAL, PlantParameters
from flexff.plant.signals import AXES, FEEDBACK_FORCES, FEEDFORWARD_FORCES, TRUE_POSITION, names
from flexff.plant.variants import VARIANTS

EXACT_ENCODERS = {"noise_std": 0.0, "encoder_quantization": 0.0}  # a plant measuring exactly


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


class ManipulatorLoop:
    """flexff's manipulator loop (its built-in controller, a [reference])."""

    axes: tuple[str, ...] = AXES
    columns: tuple[str, ...] = names(FEEDFORWARD_FORCES)
    unit = "m"

    def __init__(self, config: RunConfig) -> None:
        if config.reference is None:
            raise InputError(f"{config.origin}: the loop has no [reference]: iterative learning "
                             f"repeats one reference; add a [reference] table")
        self.config = config

    def identity(self) -> Any:
        return json.loads(json.dumps(expanded(with_feedforward(self.config)), default=str))

    def trial(self, table: Path, trial: int) -> Trial:
        seed = self.seed(trial)
        recording, applied, error = self._run(with_feedforward_table(self._seeded(seed), table))
        return Trial(recording, applied, error, seed)

    def _run(self, config: RunConfig) -> tuple[Recording, np.ndarray, np.ndarray]:
        """The recording, the force the plant received (feedforward as the controller read it
        plus feedback, (n, 2) [N]) and the tracking error (n, 2) [m]."""
        recording, scenario = run_trial(config)
        taps = dataset_taps(scenario)
        applied = np.column_stack([taps[ff].read(recording) + taps[fb].read(recording)
                                   for ff, fb in zip(names(FEEDFORWARD_FORCES),
                                                     names(FEEDBACK_FORCES))])
        error = np.column_stack([recording[f"{a}_ref"] - taps[a].read(recording)
                                 for a in names(TRUE_POSITION)])
        return recording, applied, error

    def learning_filter(self, recording: Recording, cutoff_hz: float) -> LearningFilter:
        return learning_filter(recording.signals, self.config.step, self._plant_model(),
                               cutoff_hz)

    def metrics(self, recording: Recording) -> dict[str, dict[str, float]]:
        return tracking_metrics(recording, named_axes(self.axes))

    def noise_floor(self, table: Path) -> dict[str, float] | None:
        """The e2 per axis that the built-in plant's encoder noise and quantization cause
        with the force table `table`: the e2 of the difference of its tracking errors with them
        (the loop's own seed) and without. None for a loop without a built-in plant (an FMU's
        noise cannot be switched off) or whose plant measures exactly."""
        loop = self.config
        if loop.builtin("plant") is None:
            return None
        measured = self._plant_parameters()
        if measured.noise_std == 0.0 and measured.encoder_quantization <= 0.5:
            return None
        exact = replace(loop, fmus=tuple(replace(f, parameters={**f.parameters,
                                                                **EXACT_ENCODERS})
                                         if f.builtin == "plant" else f for f in loop.fmus))
        noisy, clean = (self._run(with_feedforward_table(c, table))[2] for c in (loop, exact))
        return {a: error_norms(noisy[:, k] - clean[:, k], loop.step)["e2"]
                for k, a in enumerate(AXES)}

    def seed(self, trial: int) -> int | None:
        """Trial `trial`'s noise seed of the built-in plant (None without one): a fresh one
        each trial, so that the iteration learns what repeats, not one noise sequence."""
        plant = self.config.builtin("plant")
        return None if plant is None else int(plant.options.get("seed", 0)) + 1 + trial

    def _seeded(self, seed: int | None) -> RunConfig:
        if seed is None:
            return self.config
        return replace(self.config, fmus=tuple(
            replace(f, options={**f.options, "seed": seed}) if f.builtin == "plant" else f
            for f in self.config.fmus))

    def _plant_parameters(self) -> PlantParameters:
        """The true parameters of the loop's built-in plant: its variant's with the loop's
        values (the nominal ones for a plant FMU by path)."""
        plant = self.config.builtin("plant")
        if plant is None:
            return NOMINAL
        known = set(PlantParameters.names())
        return VARIANTS[plant.options["variant"]].parameters.with_values(
            **{k: float(v) for k, v in plant.parameters.items() if k in known})

    def _plant_model(self) -> PlantParameters:
        """The parameters of the loop's plant model (_plant_parameters), its tool (where it
        has one) counted at the wrist, for below its mount's mode it moves with the wrist."""
        parameters = self._plant_parameters()
        plant = self.config.builtin("plant")
        if plant is None or not VARIANTS[plant.options["variant"]].parasitic_mode:
            return parameters
        return parameters.with_values(m_ee=parameters.m_ee + parameters.m_tool)


InverseModel = Callable[[Machine, Recording], ca.Function]  # -> (pos, vel, acc) -> effort


def identified_on_trial(machine: Machine, recording: Recording) -> ca.Function:
    """The linear model of the machine's prior identified on one trial: the effort the loop
    commanded against the reference's motion (learning.linear_model)."""
    motion: dict[str, np.ndarray] = {}
    for axis in machine.axes:
        motion.update(zip(axis.motion, (recording[n] for n in (axis.reference,
                                                              *axis.derivatives[:2]))))
    efforts = {a.name: recording[a.effort] for a in machine.axes}
    return identify_linear(machine, motion, efforts).casadi_function()


class MachineLoop:
    """A loop with a [machine] description: each axis's feedforward input learned on the
    references the loop's sources give (`<axis>_ref`, `v<axis>_ref`, `a<axis>_ref`)."""

    def __init__(self, config: RunConfig, model: InverseModel) -> None:
        self.config, self.model = config, model
        self.machine = machine_loop.loop_machine(config)
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
        recording, applied, error = self._run(machine_loop.with_feedforward(self.config, table))
        return Trial(recording, applied, error, None)

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
                            self.model(self.machine, recording), cutoff_hz)

    def metrics(self, recording: Recording) -> dict[str, dict[str, float]]:
        return tracking_metrics(recording, machine_axes(self.machine))

    def noise_floor(self, table: Path) -> dict[str, float] | None:
        """The e2 per axis that the loop's measurement causes with the feedforward `table`:
        the e2 of the difference of its tracking errors as it is and with the description's
        `exact` start values. None where the description gives none (unknown)."""
        if not self.machine.exact:
            return None
        exact = machine_loop.with_start_values(self.config, self.machine.exact, "machine.exact")
        noisy, clean = (self._run(machine_loop.with_feedforward(c, table))[2]
                        for c in (self.config, exact))
        return {a: error_norms(noisy[:, k] - clean[:, k], self.config.step)["e2"]
                for k, a in enumerate(self.axes)}
