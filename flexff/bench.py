"""`flexff bench`: speed figures measured in one run, as JSON (ratios where they matter)."""

from __future__ import annotations

import platform
import tempfile
from pathlib import Path
from typing import Any

import numpy as np

from controllers.feedback import controller_system
from controllers.learned_feedforward import learned_feedforward_system
from cosim.floor import run_c_loop
from cosim.libcosim import run_libcosim, time_libcosim_engine
from cosim.master import Master, SlaveSpec
from cosim.references import thesis_evaluation
from cosim.scenario import reference_samples
from fmu.bench import bench_fmu
from fmu.build import build_fmu
from plant.system import plant_system

CLOSED_LOOP_STEP = 1e-3
CLOSED_LOOP_STOP = 15.0  # the thesis's evaluation reference


def closed_loop_benchmark(folder: Path, repeats: int = 3) -> dict[str, Any]:
    """Real-time factor of PID + nominal plant on the thesis's evaluation reference through
    cosim.master, libcosim's master (fed and read through libcosimpy every step, and its engine
    alone: all steps in one call) and the same loop in C, best of `repeats` runs each (libcosim
    steps its FMUs on a thread pool, whose hand-offs make its times vary from run to run).
    Cross-checks: the C loop must record
    the master's numbers bit for bit; libcosim's Jacobi timing (cosim.libcosim) moves the
    end effector by up to `libcosim_max_position_gap_m`."""
    steps = int(round(CLOSED_LOOP_STOP / CLOSED_LOOP_STEP))
    slaves = [SlaveSpec("controller", build_fmu(controller_system("nominal"),
                                                folder / "controller.fmu")),
              SlaveSpec("plant", build_fmu(plant_system("nominal"), folder / "plant.fmu"))]
    reference = reference_samples(thesis_evaluation(CLOSED_LOOP_STEP), steps)
    sources = {"x_ref": reference["x_ref"], "y_ref": reference["y_ref"],
               "Fx_ff": 0.0, "Fy_ff": 0.0}
    ours = []
    for _ in range(repeats):
        with Master(slaves, list(sources), CLOSED_LOOP_STEP) as master:
            if not ours:
                c_record, c_us = run_c_loop(master, sources, steps, repeats)
            ours.append(master.run(sources, steps, progress=False))
    best = min(r.wall_s for r in ours)
    theirs = [run_libcosim(slaves, sources, CLOSED_LOOP_STEP, steps, ["x", "y"])
              for _ in range(repeats)]
    engine_s = min(time_libcosim_engine(slaves, sources, CLOSED_LOOP_STEP, steps)
                   for _ in range(repeats))
    master_us, engine_us = 1e6 * best / steps, 1e6 * engine_s / steps
    libcosim_us = 1e6 * min(r.wall_s for r in theirs) / steps
    us = {"master": master_us, "libcosim": libcosim_us, "libcosim_engine": engine_us, "c": c_us}
    gap = max(float(np.abs(theirs[0][n] - ours[0][n][1:]).max()) for n in ("x", "y"))
    return {
        "reference": "thesis-eval", "stop_s": CLOSED_LOOP_STOP, "steps": steps,
        "us_per_step": us,
        "real_time_factor": {k: CLOSED_LOOP_STEP / (v * 1e-6) for k, v in us.items()},
        "ratio_master_over_c": master_us / c_us,
        "ratio_libcosim_over_master": libcosim_us / master_us,
        "ratio_libcosim_engine_over_master": engine_us / master_us,
        "c_equals_master": all(np.array_equal(c_record[n], ours[0][n]) for n in ours[0].signals),
        "libcosim_max_position_gap_m": gap,
    }


def untrained_models(folder: Path) -> dict[str, Path]:
    """ONNX exports of every model kind at the fast preset's sizes, trained for one epoch on a
    small synthetic dataset: what a step costs does not depend on the weights."""
    from learning.evaluate import MODELS
    from learning.export import export
    from learning.synthetic import synthetic_dataset
    from learning.train import train

    data = synthetic_dataset(folder / "data", n_train=3, n_test=1, duration=3.0, rate_hz=100.0,
                             seed=1)
    models = {}
    for kind in MODELS:
        train(kind, "fast", data, folder / "runs" / kind, progress=False, epochs=1)
        models[kind] = export(folder / "runs" / kind, folder / f"{kind}.onnx")
    return models


def learned_feedforward_benchmark(folder: Path, models: dict[str, Path],
                                  repeats: int = 2) -> dict[str, Any]:
    """Real-time factor of the closed loop (feedforward FMU + PID + nominal plant, thesis
    evaluation reference, through cosim.master) with each learned model, step by step and
    precomputed, best of `repeats`; its cost over the loop without feedforward."""
    steps = int(round(CLOSED_LOOP_STOP / CLOSED_LOOP_STEP))
    reference = reference_samples(thesis_evaluation(CLOSED_LOOP_STEP), steps)
    loop = [SlaveSpec("controller", build_fmu(controller_system("nominal"),
                                              folder / "controller.fmu")),
            SlaveSpec("plant", build_fmu(plant_system("nominal"), folder / "plant.fmu"))]

    def seconds(slaves: list[SlaveSpec], sources: dict[str, Any]) -> float:
        walls = []
        for _ in range(repeats):  # a Master runs once
            with Master(slaves, list(sources), CLOSED_LOOP_STEP) as master:
                walls.append(master.run(sources, steps, progress=False).wall_s)
        return min(walls)

    base = seconds(loop, {"x_ref": reference["x_ref"], "y_ref": reference["y_ref"],
                          "Fx_ff": 0.0, "Fy_ff": 0.0})
    results: dict[str, Any] = {"reference": "thesis-eval", "steps": steps,
                               "without_feedforward_us_per_step": 1e6 * base / steps}
    for kind, model in models.items():
        for mode in ("step", "precomputed"):
            system = learned_feedforward_system(
                model, CLOSED_LOOP_STEP, reference if mode == "precomputed" else None)
            ff = SlaveSpec("feedforward", build_fmu(system, folder / f"{kind}-{mode}.fmu"))
            wall = seconds([ff, *loop], dict(reference))
            results[f"{kind}_{mode}"] = {
                "us_per_step": 1e6 * wall / steps,
                "real_time_factor": CLOSED_LOOP_STOP / wall,
                "ratio_over_without_feedforward": wall / base}
    return results


def run_benchmarks(steps: int = 20000, repeats: int = 5,
                   models: dict[str, Path] | None = None) -> dict[str, Any]:
    """Cost of a 1 ms plant step through fmpy's low-level API and in plain C, per variant, of
    the closed loop through our master, libcosim and C, and of the closed loop with each
    learned feedforward FMU (`models`: kind -> .onnx; default: untrained exports)."""
    results: dict[str, Any] = {"machine": platform.processor() or platform.machine(),
                               "python": platform.python_version(), "plant_step": {}}
    with tempfile.TemporaryDirectory() as tmp:
        for variant in ("nominal", "hardware"):
            path = build_fmu(plant_system(variant), Path(tmp) / f"plant_{variant}.fmu")
            figures = bench_fmu(path, steps=steps, repeats=repeats)
            figures["real_time_factor_fmpy"] = 1e3 / figures["python_us_per_step"]
            results["plant_step"][variant] = figures
        results["closed_loop"] = closed_loop_benchmark(Path(tmp))
        results["learned_feedforward"] = learned_feedforward_benchmark(
            Path(tmp), models or untrained_models(Path(tmp)))
    return results
