"""bench_fmu: cost of one co-simulation step of an FMU, through fmpy and in plain C.

Both loops do the same work per step (fmi2SetReal of every input at its start value,
fmi2DoStep, fmi2GetReal of every output) on a fresh instance with default parameters; the
ratio shows how much of a Python master's step time is interpreter overhead. The sums of all
outputs read by both loops must agree, which checks that they really ran the same steps.
"""

from __future__ import annotations

import json
import subprocess
import tempfile
import time
from ctypes import c_double, c_uint
from pathlib import Path

import numpy as np

from fmu import cache
from fmu.compile import CFLAGS, compiler_version, fmi_headers, run_compiler
from fmu.runner import Slave

BENCH_SOURCE = Path(__file__).parent / "c" / "bench_loop.c"


def _bench_program() -> Path:
    """The compiled C bench loop, from the cache when its source and compiler are unchanged."""
    source = BENCH_SOURCE.read_text()
    key = cache.digest({"bench_loop.c": source, "cflags": " ".join(CFLAGS),
                        "compiler": compiler_version()})
    program = cache.cached_path(key, ".bench")
    if not program.exists():
        with tempfile.TemporaryDirectory() as tmp:
            for name, text in fmi_headers().items():
                (Path(tmp) / name).write_text(text)
            exe = Path(tmp) / "bench_loop"
            run_compiler([BENCH_SOURCE], exe, [Path(tmp)], extra_flags=(), libraries=("-ldl",))
            cache.store(key, ".bench", exe)
    return program


def _python_loop(s: Slave, steps: int, step: float, repeats: int) -> tuple[float, float, float]:
    """Best seconds per step cycle and per bare fmi2DoStep through fmpy's FMU2Slave calls, and
    the checksum of the outputs the cycle recorded (summed afterwards, in the C loop's order)."""
    inputs, outputs = s.names("input"), s.names("output")
    vr_in = (c_uint * len(inputs))(*(s.variables[n].valueReference for n in inputs))
    u = (c_double * len(inputs))(*(float(s.variables[n].start) for n in inputs))
    vr_out = (c_uint * len(outputs))(*(s.variables[n].valueReference for n in outputs))
    y = (c_double * len(outputs))()
    y_view = np.frombuffer(y)
    record = np.empty((repeats * steps, len(outputs)))
    fmu, c = s.fmu, s.fmu.component
    best_cycle, best_step, k = float("inf"), float("inf"), 0
    for _ in range(repeats):
        start = time.perf_counter()
        for _ in range(steps):
            fmu.fmi2SetReal(c, vr_in, len(inputs), u)
            fmu.fmi2DoStep(c, k * step, step, 1)
            fmu.fmi2GetReal(c, vr_out, len(outputs), y)
            record[k] = y_view
            k += 1
        best_cycle = min(best_cycle, time.perf_counter() - start)
    for _ in range(repeats):
        start = time.perf_counter()
        for _ in range(steps):
            fmu.fmi2DoStep(c, k * step, step, 1)
            k += 1
        best_step = min(best_step, time.perf_counter() - start)
    checksum = 0.0
    for value in record.ravel().tolist():
        checksum += value
    return best_cycle / steps, best_step / steps, checksum


def bench_fmu(path: str | Path, steps: int = 10000, step: float = 1e-3, repeats: int = 5) -> dict:
    """Microseconds per co-simulation step through fmpy and in C, their ratio, and a cross-check.

    A step cycle is fmi2SetReal(inputs), fmi2DoStep, fmi2GetReal(outputs) with the outputs
    recorded; `python_us_per_do_step` times the bare fmi2DoStep call through fmpy.
    """
    with Slave(path) as s:
        s.initialize()
        py_cycle, py_step, py_checksum = _python_loop(s, steps, step, repeats)
        inputs, outputs = s.names("input"), s.names("output")
        args = [str(len(inputs)), *(str(s.variables[n].valueReference) for n in inputs),
                *(repr(float(s.variables[n].start)) for n in inputs),
                str(len(outputs)), *(str(s.variables[n].valueReference) for n in outputs)]
        run = subprocess.run([str(_bench_program()), str(s.library), s.model_description.guid,
                              str(steps), repr(step), str(repeats), *args],
                             capture_output=True, text=True, check=True)
    c_result = json.loads(run.stdout)
    python_us = 1e6 * py_cycle
    return {
        "steps": steps,
        "step": step,
        "repeats": repeats,
        "python_us_per_step": python_us,
        "python_us_per_do_step": 1e6 * py_step,
        "c_us_per_step": c_result["us_per_step"],
        "ratio": python_us / c_result["us_per_step"],
        "same_outputs": c_result["checksum"] == py_checksum,
    }
