"""bench_fmu: cost of one co-simulation step of an FMU, through fmpy and in plain C.

Both do the same FMI calls per step (fmi2SetReal of every input at its start value,
fmi2DoStep, fmi2GetReal of every output) on a fresh instance with default parameters: Python
through fmpy, and C through the C floor (cosim.floor), the co-simulation engine's own loop on a
plan of this one FMU with its inputs fed from sources. The ratio shows how much of a Python
master's step time is interpreter overhead. Both record every output, and the records must be
equal, which checks that they really ran the same steps. The co-simulation master itself
(cosim.master, its engine in compiled code) runs the FMU in-process and in its own process
(cosim.isolation): the difference is what isolating an FMU costs per step, and the two
records must be equal too.
"""

from __future__ import annotations

import time
from ctypes import c_double, c_int, c_size_t, c_uint
from pathlib import Path
from typing import Any

import numpy as np

from flexff.cosim.floor import run_c_loop
from flexff.cosim.master import Master, ResolvedFmu
from flexff.cosim.recording import Recording
from flexff.cosim.sandbox import DEFAULT, Sandbox
from flexff.fmu.defaults import DEFAULT_STEP
from flexff.fmu.fmpy_instance import FmpyInstance, bare_calls


def _python_loop(s: FmpyInstance, steps: int, step: float, repeats: int
                 ) -> tuple[dict[str, float], np.ndarray]:
    """Best seconds per step cycle through fmpy's FMU2Slave calls and through the bare C
    pointers the co-simulation master uses (fmu.fmpy_instance.bare_calls), per bare fmi2DoStep
    through fmpy, and the outputs after each of the first `steps` cycles."""
    inputs, outputs = s.names("input"), s.names("output")
    vr_in = (c_uint * len(inputs))(*(s.variables[n].valueReference for n in inputs))
    u = (c_double * len(inputs))(*(float(s.variables[n].start) for n in inputs))
    vr_out = (c_uint * len(outputs))(*(s.variables[n].valueReference for n in outputs))
    y = (c_double * len(outputs))()
    y_view = np.frombuffer(memoryview(y))
    record = np.empty((repeats * steps, len(outputs)))
    fmu, c = s.fmu, s.fmu.component
    bare = bare_calls(fmu)
    n_in, n_out, h, true = c_size_t(len(inputs)), c_size_t(len(outputs)), c_double(step), c_int(1)
    best = {"cycle": float("inf"), "bare_cycle": float("inf"), "do_step": float("inf")}
    k = 0
    for _ in range(repeats):
        start = time.perf_counter()
        for _ in range(steps):
            fmu.fmi2SetReal(c, vr_in, len(inputs), u)
            fmu.fmi2DoStep(c, k * step, step, 1)
            fmu.fmi2GetReal(c, vr_out, len(outputs), y)
            record[k] = y_view
            k += 1
        best["cycle"] = min(best["cycle"], time.perf_counter() - start)
    scratch = np.empty((steps, len(outputs)))  # the bare cycle records too, elsewhere
    for _ in range(repeats):
        start = time.perf_counter()
        for i in range(steps):
            bare.set_real(bare.component, vr_in, n_in, u)
            bare.do_step(bare.component, c_double(k * step), h, true)
            bare.get_real(bare.component, vr_out, n_out, y)
            scratch[i] = y_view
            k += 1
        best["bare_cycle"] = min(best["bare_cycle"], time.perf_counter() - start)
    for _ in range(repeats):
        start = time.perf_counter()
        for _ in range(steps):
            fmu.fmi2DoStep(c, k * step, step, 1)
            k += 1
        best["do_step"] = min(best["do_step"], time.perf_counter() - start)
    return {name: seconds / steps for name, seconds in best.items()}, record[:steps]


def master_us_per_step(path: Path, starts: dict[str, float], steps: int, step: float,
                       repeats: int, isolate: bool, sandbox: Sandbox | None = DEFAULT
                       ) -> tuple[float, Recording]:
    """Best microseconds per step of the master's engine loop on this FMU alone (in-process or
    isolated, in `sandbox` or none), its inputs held at `starts`, and the record of the last
    run."""
    best = float("inf")
    fmu = ResolvedFmu("fmu", path, isolate=isolate, sandbox=sandbox)
    for _ in range(repeats):
        with Master([fmu], list(starts), step) as master:
            recording = master.run(starts, steps)
        best = min(best, recording.wall_s)
    return 1e6 * best / steps, recording


def bench_fmu(path: str | Path, steps: int = 10000, step: float = DEFAULT_STEP,
              repeats: int = 5) -> dict[str, Any]:
    """Microseconds per co-simulation step through fmpy and in C, their ratio, and a cross-check.

    A step cycle is fmi2SetReal(inputs), fmi2DoStep, fmi2GetReal(outputs) with the outputs
    recorded; `python_bare_us_per_step` is the same cycle through the bare C pointers the
    co-simulation master calls; `python_us_per_do_step` times fmi2DoStep alone through fmpy;
    `c_us_per_step` is the C floor's step on this FMU alone (the engine's: its inputs set from
    the bus, its outputs read into it, the bus recorded, the step timed; the outputs are read
    before the next step rather than after this one, which gives the same values).
    `master_us_per_step` and `isolated_us_per_step` are the master's step with the FMU in its
    process and in its own (`isolated_same_outputs`: their records are equal).
    """
    with FmpyInstance(path) as s:
        s.initialize()
        python, outputs = _python_loop(s, steps, step, repeats)
        starts = {n: float(s.variables[n].start) for n in s.names("input")}
        names = s.names("output")
    with Master([ResolvedFmu("fmu", Path(path))], list(starts), step) as master:
        floor, c_us = run_c_loop(master, starts, steps, repeats)
    master_us, inside = master_us_per_step(Path(path), starts, steps, step, repeats, False)
    isolated_us, alone = master_us_per_step(Path(path), starts, steps, step, repeats, True)
    python_us = 1e6 * python["cycle"]
    return {
        "steps": steps,
        "step": step,
        "repeats": repeats,
        "python_us_per_step": python_us,
        "python_bare_us_per_step": 1e6 * python["bare_cycle"],
        "python_us_per_do_step": 1e6 * python["do_step"],
        "c_us_per_step": c_us,
        "ratio": python_us / c_us,
        "master_us_per_step": master_us,
        "isolated_us_per_step": isolated_us,
        "isolated_same_outputs": all(np.array_equal(inside[n], alone[n])
                                     for n in inside.signals),
        "same_outputs": all(np.array_equal(floor[f"fmu.{n}"][1:], outputs[:, j])
                            for j, n in enumerate(names)),
    }
