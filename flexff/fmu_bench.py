"""bench_fmu: cost of one co-simulation step of an FMU, through fmpy and in plain C.

Both loops do the same work per step (fmi2SetReal of every input at its start value,
fmi2DoStep, fmi2GetReal of every output) on a fresh instance with default parameters; the
ratio shows how much of a Python master's step time is interpreter overhead. The sums of all
outputs read by both loops must agree, which checks that they really ran the same steps.
"""

from __future__ import annotations

import json
import subprocess
import time
from ctypes import c_double, c_int, c_size_t, c_uint
from pathlib import Path
from typing import Any

import numpy as np

from flexff.fmu.compile import cached_program
from flexff.fmu.slave import Slave, bare_calls

BENCH_SOURCE = Path(__file__).parent / "c" / "bench_loop.c"


def _python_loop(s: Slave, steps: int, step: float, repeats: int) -> dict[str, float]:
    """Best seconds per step cycle through fmpy's FMU2Slave calls and through the bare C
    pointers the co-simulation master uses (fmu.slave.bare_calls), per bare fmi2DoStep
    through fmpy, and the checksum of the outputs the first cycle recorded (summed afterwards,
    in the C loop's order)."""
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
    checksum = 0.0
    for value in record.ravel().tolist():
        checksum += value
    return {name: seconds / steps for name, seconds in best.items()} | {"checksum": checksum}


def bench_fmu(path: str | Path, steps: int = 10000, step: float = 1e-3,
              repeats: int = 5) -> dict[str, Any]:
    """Microseconds per co-simulation step through fmpy and in C, their ratio, and a cross-check.

    A step cycle is fmi2SetReal(inputs), fmi2DoStep, fmi2GetReal(outputs) with the outputs
    recorded; `python_bare_us_per_step` is the same cycle through the bare C pointers the
    co-simulation master calls; `python_us_per_do_step` times fmi2DoStep alone through fmpy.
    """
    with Slave(path) as s:
        s.initialize()
        python = _python_loop(s, steps, step, repeats)
        inputs, outputs = s.names("input"), s.names("output")
        args = [str(len(inputs)), *(str(s.variables[n].valueReference) for n in inputs),
                *(repr(float(s.variables[n].start)) for n in inputs),
                str(len(outputs)), *(str(s.variables[n].valueReference) for n in outputs)]
        run = subprocess.run([str(cached_program("bench", [BENCH_SOURCE])), str(s.library),
                              s.model_description.guid,
                              str(steps), repr(step), str(repeats), *args],
                             capture_output=True, text=True, check=True)
    c_result = json.loads(run.stdout)
    python_us = 1e6 * python["cycle"]
    return {
        "steps": steps,
        "step": step,
        "repeats": repeats,
        "python_us_per_step": python_us,
        "python_bare_us_per_step": 1e6 * python["bare_cycle"],
        "python_us_per_do_step": 1e6 * python["do_step"],
        "c_us_per_step": c_result["us_per_step"],
        "ratio": python_us / c_result["us_per_step"],
        "same_outputs": c_result["checksum"] == python["checksum"],
    }
