"""From a checked RunConfig to what the master runs: the FMUs in order and the source signals.

The order is feedforward (if any: rigid-body, or a learned ONNX model step by step or
precomputed over the run's reference) -> controller -> plant; the reference signals are the
external sources. Without a feedforward FMU, Fx_ff and Fy_ff are constant zero sources, so the
controller's inputs stay connected by name either way. FMUs come from fmu.build.build_fmu,
which keeps a cache by content hash: a run rebuilds only what changed.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from controllers.feedback import DEFAULTS, controller_system, parasitic_mode_hz
from controllers.feedforward import FORCE_OUTPUTS, rigid_body_feedforward_system
from controllers.learned_feedforward import learned_feedforward_system
from cosim.config import RunConfig
from cosim.master import SlaveSpec
from cosim.references import Reference
from fmu.build import build_fmu
from fmu.system import System
from plant.system import plant_system


def controller_for(config: RunConfig) -> System:
    """The feedback controller the configuration asks for, sampled at the run's step."""
    c, variant = config.controller, config.plant.variant
    if c.notch is False and DEFAULTS[variant].notch:
        # the variant's defaults would add the notch: design without it at its crossover
        crossover = c.crossover_hz or DEFAULTS[variant].crossover_hz
        return controller_system("nominal", crossover, None, c.encoders, config.step)
    notch_hz = parasitic_mode_hz() if c.notch is True else (c.notch or None)
    return controller_system(variant, c.crossover_hz, notch_hz, c.encoders, config.step)


def build_slaves(config: RunConfig, folder: str | Path) -> list[SlaveSpec]:
    """Build (or fetch from the cache) every FMU of the run into `folder`, in stepping order."""
    folder = Path(folder)
    slaves = []
    ff = config.feedforward
    if ff.kind != "none":
        system = (rigid_body_feedforward_system(config.step) if ff.kind == "model" else
                  learned_feedforward_system(ff.model, config.step, reference_samples(
                      config.reference.build(config.step), config.steps)
                      if ff.mode == "precomputed" else None))
        slaves.append(SlaveSpec("feedforward", build_fmu(system, folder / "feedforward.fmu")))
    controller = build_fmu(controller_for(config), folder / "controller.fmu")
    slaves.append(SlaveSpec("controller", controller))
    parameters: dict[str, float | int] = dict(config.plant.parameters)
    if config.plant.seed is not None:
        parameters["seed"] = config.plant.seed
    plant = build_fmu(plant_system(config.plant.variant), folder / "plant.fmu")
    slaves.append(SlaveSpec("plant", plant, parameters))
    return slaves


def reference_samples(reference: Reference, steps: int) -> dict[str, np.ndarray]:
    """The reference signals at points 0 .. steps: cut, or held at rest after its end."""
    signals = reference.signals()
    n = min(steps + 1, reference.t.size)
    out = {}
    for name, values in signals.items():
        column = np.empty(steps + 1)
        column[:n] = values[:n]
        column[n:] = values[n - 1] if name in ("x_ref", "y_ref") else 0.0
        out[name] = column
    return out


def source_signals(config: RunConfig) -> dict[str, np.ndarray | float]:
    """Every external signal of the run: the reference, and zero forces without feedforward."""
    sources: dict[str, np.ndarray | float] = dict(
        reference_samples(config.reference.build(config.step), config.steps))
    if config.feedforward.kind == "none":
        sources.update({v.name: 0.0 for v in FORCE_OUTPUTS})
    return sources
