"""ILC-labelled training data: on each training reference, the force iterative learning
control converges to, as the labels of the reference's own motion.

A set collected under PID alone pairs the force the loop applied with the motion the noisy,
counted encoders saw: the feedback's reaction to the noise is in the labels, and the motion
is the PID loop's, millimetres off the reference. ILC (learning.ilc) finds, for one
reference, the feedforward that tracks it to the noise floor, learning only what repeats
from trial to trial. Run on every training reference of a set, it gives each reference the
force that a perfect feedforward would give there: `ilc_labelled_set` writes a dataset with
those forces as labels and the reference as the motion (its encoder angles by the nominal
inverse kinematics), so every model trains on it as on a collected set. The test split is
copied unchanged: no model learns from it.

Docs: "ILC and the noise floor" (docs/explanation/ilc-noise-floor.md).
"""

from __future__ import annotations

import functools
from collections.abc import Callable
from dataclasses import replace
from pathlib import Path
from typing import Any

import casadi as ca
import numpy as np
from tqdm import tqdm

from flexff.controllers.features import nominal_model
from flexff.cosim.csv_text import read_time_table
from flexff.cosim.executor import execute
from flexff.cosim.schema import RunConfig
from flexff.fmu.errors import InputError, RunError
from flexff.learning.dataset import (
    ENCODER_SIGNALS,
    LABEL_SIGNALS,
    POSITION_SIGNALS,
    REFERENCE_SIGNALS,
    Trajectory,
    load_dataset,
    write_dataset,
)
from flexff.learning.ilc import RESULT, ilc
from flexff.learning.loop import on_reference
from flexff.learning.machine_loop import feedforward_signal
from flexff.learning.samples import evaluate_samples
from flexff.plant.kinematics import SHOULDER_INDEX

ITERATIONS = 2  # learning trials per reference: the evaluation reference's ILC reaches the
# noise floor at its second (e2 x / y 1.17e-5 / 1.70e-5 m/sqrt(s) after one, 1.00e-6 /
# 1.87e-6 after two, the floor 0.93e-6 / 1.75e-6)
FOLDER = "ilc"  # beside the set: one ILC folder per training reference
# how models train on such a set: its motion is the reference, exact, so its angles are not
# counted in encoder counts; its forces hold no reaction to encoder noise, so the low-pass
# need not cut as low as for a collected set; and it needs no training noise. The rigid-body
# model identified on the hardware stand-in's set so left 0.18 / 0.30 mN rms (x / y)
# unexplained, against 3.8 / 5.5 mN with the hardware environment's preprocessing (counted
# angles, 1 Hz) and 0.46 / 0.60 mN at 1 Hz uncounted. The physics-guided ensemble's e2 on the
# evaluation reference: 0.97 / 1.82 um/sqrt(s) without training noise, 1.37 / 1.94 with the
# thesis's (0.1 mm, 10 mN)
PREPROCESSING: dict[str, Any] = {"quantize_encoders": False, "cutoff_hz": 5.0,
                                 "position_noise_m": 0.0, "force_noise_n": 0.0}


def ilc_labelled_set(data: str | Path, out: str | Path, loop: RunConfig,
                     iterations: int = ITERATIONS, progress: bool = True,
                     say: Callable[[str], None] = print, workers: int | None = None) -> Path:
    """The dataset folder `out`: the set `data` with each training trajectory's labels the
    force ILC converged to on its reference on `loop` (`iterations` trials after PID alone,
    with the trajectory's noise seed; each in out/ilc/NAME, continued where it is there),
    its motion the reference's; the test split as it is. Runs in up to `workers` processes
    (default: one per core granted)."""
    dataset = load_dataset(data)
    out = Path(out)
    training = [t for t in dataset.trajectories if t.split != "test"]
    jobs = [(_on_its_reference(loop, t, data), out / FOLDER / t.name, iterations)
            for t in training]
    say(f"iterative learning control on the {len(jobs)} training references of {data} "
        f"({iterations} trials each after PID alone) into {out / FOLDER}")
    forces: dict[str, Path] = {}
    with tqdm(total=len(jobs), unit="reference", desc="ILC labels",
              disable=not progress) as bar, execute(_learned_force, jobs, workers) as running:
        for finished in running:
            name = training[finished.index].name
            if finished.result is None:
                raise finished.error or RunError(f"ILC on reference {name} cancelled")
            forces[name] = finished.result
            bar.update()
    trajectories = [t if t.split == "test" else _labelled(t, forces[t.name])
                    for t in dataset.trajectories]
    return write_dataset(out, dataset.set, dataset.sample_rate_hz, dataset.plant, trajectories)


def _on_its_reference(loop: RunConfig, trajectory: Trajectory, data: str | Path) -> RunConfig:
    """`loop` on the trajectory's reference with its noise seed; InputError where the
    trajectory has no [reference] table a run takes."""
    try:
        return on_reference(loop, trajectory.reference, trajectory.name, seed=trajectory.seed)
    except InputError as error:
        raise InputError(f"{data}: trajectory {trajectory.name!r} has no reference a run takes "
                         f"({error}): ILC labels need each training trajectory's [reference] "
                         f"table, as flexff data collect writes it; imported logs and a "
                         f"synthetic set's splines have none") from None


def _learned_force(job: tuple[RunConfig, Path, int]) -> Path:
    """ILC on one reference (in a worker process); the table of its best force."""
    config, folder, iterations = job
    ilc(config, folder, iterations, progress=False, say=lambda _: None, floor=False)
    return folder / RESULT


def _labelled(trajectory: Trajectory, table: Path) -> Trajectory:
    """`trajectory` with the ILC force of `table` (a 1 kHz time table) as its labels and its
    reference as its motion: positions, and encoder angles by inverse kinematics."""
    signals = trajectory.signals
    time = signals["time"]
    columns = tuple(feedforward_signal(a) for a in POSITION_SIGNALS)  # x_ff, y_ff
    learned = read_time_table(table, columns)
    reference = {name: signals[name] for name in REFERENCE_SIGNALS}
    position = np.column_stack([reference["x_ref"], reference["y_ref"]])
    angles = evaluate_samples(_inverse_kinematics(), position)
    labelled = {"time": time, **reference,
                **dict(zip(ENCODER_SIGNALS, angles.T)),
                **dict(zip(POSITION_SIGNALS, position.T)),
                **{label: np.interp(time, learned.time, learned.columns[applied])
                   for label, applied in zip(LABEL_SIGNALS, columns)}}
    return replace(trajectory, signals=labelled)


@functools.cache
def _inverse_kinematics() -> ca.Function:
    """Wrist position (2) -> the three motors' angles, by the nominal geometry (the one the
    features' forward kinematics uses)."""
    model = nominal_model()
    position = ca.SX.sym("pos", 2)
    q = model.coordinates(position, model.parameter_values())
    return ca.Function("motor_angles", [position], [q[list(SHOULDER_INDEX)]])
