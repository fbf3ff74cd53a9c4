"""The feedforward FMU of any exported model: the builder its model card asks for, a machine's
(controllers.machine_feedforward) or the manipulator's (controllers.learned_feedforward)."""

from __future__ import annotations

from pathlib import Path

from flexff.fmu.defaults import DEFAULT_STEP
from flexff.fmu.network_runtime import RUNTIMES
from flexff.fmu.system import System


def exported_feedforward_system(model: str | Path, step: float = DEFAULT_STEP,
                                task: bool = False, runtime: str = RUNTIMES[0]) -> System:
    """The System of the feedforward FMU running the exported `model` (flexff export) at the
    step `step`; with `task` its network runs in its own task; `runtime` computes the graph
    ("c" or "onnxruntime")."""
    from flexff.controllers.model_card import read_card  # onnx

    if read_card(model).machine is not None:
        from flexff.controllers.machine_feedforward import learned_machine_feedforward_system

        return learned_machine_feedforward_system(model, step, task, runtime)
    from flexff.controllers.learned_feedforward import learned_feedforward_system

    return learned_feedforward_system(model, step, task=task, runtime=runtime)
