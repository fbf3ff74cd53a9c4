"""The compiled stepping engine (cosim/c/engine.c), loaded in-process through ctypes.

The library is compiled once into the FMU cache (rebuilt when its source or the compiler
changes). `EngineRun` mirrors the C structures; the master fills it with the FMUs' function
pointers, the bus and the buffers, all allocated before the loop, then calls `run(k0, k1)` in
chunks. Timing: TET per step and per FMU, and lateness against the schedule when paced.
"""

from __future__ import annotations

import ctypes
import functools
import tempfile
import time
from ctypes import CFUNCTYPE, POINTER, Structure, c_double, c_int, c_long, c_uint, c_void_p, cast
from pathlib import Path
from typing import Any

import numpy as np

from flexff.cosim.timing import Pacing, StepTiming
from flexff.fmu import cache
from flexff.fmu.compile import CFLAGS, compiler_version, run_compiler

SOURCE = Path(__file__).parent / "c" / "engine.c"
TYPED_HOOK = CFUNCTYPE(c_int, c_long, c_int, c_long)  # (slave, phase, k) -> 0 if ok
CALLS = {1: "setting its inputs", 2: "getting its outputs", 3: "the step", 4: "getting its "
         "outputs after the step", 5: "exchanging values of other types"}
OK, FAILED, OVERRUN = 0, 1, 2
MAX_LISTED_OVERRUNS = 16


class _Timespec(Structure):
    _fields_ = [("tv_sec", c_long), ("tv_nsec", c_long)]


class EngineSlave(Structure):
    """One FMU's calls and its place on the bus (struct Slave of engine.c)."""

    _fields_ = [("fmi3", c_int), ("component", c_void_p), ("set_float64", c_void_p),
                ("get_float64", c_void_p), ("do_step", c_void_p), ("n_in", c_long),
                ("in_vr", POINTER(c_uint)), ("gather", POINTER(c_long)),
                ("gain", POINTER(c_double)), ("offset", POINTER(c_double)),
                ("in_values", POINTER(c_double)), ("n_out", c_long),
                ("out_vr", POINTER(c_uint)), ("out_values", POINTER(c_double)),
                ("read_before", c_int), ("read_after", c_int), ("typed_in", c_int),
                ("typed_out", c_int)]


class EngineRun(Structure):
    """A run's plan, buffers and measurements (struct Run of engine.c)."""

    _fields_ = [("step", c_double), ("steps", c_long), ("n_slaves", c_long),
                ("slaves", POINTER(EngineSlave)), ("bus", POINTER(c_double)),
                ("n_bus", c_long), ("n_sources", c_long), ("sources", POINTER(c_double)),
                ("record", POINTER(c_double)), ("columns", POINTER(c_long)),
                ("n_columns", c_long), ("typed", TYPED_HOOK), ("typed_record", c_int),
                ("tet", POINTER(c_double)), ("slave_tet", POINTER(c_double)),
                ("lateness", POINTER(c_double)), ("paced", c_int), ("period", c_double),
                ("start", _Timespec), ("max_overruns", c_long), ("grace_steps", c_long),
                ("overruns", c_long), ("counted", c_long),
                ("first_overruns", c_long * MAX_LISTED_OVERRUNS), ("failed_slave", c_long),
                ("failed_k", c_long), ("failed_call", c_int)]


@functools.cache
def library() -> ctypes.CDLL:
    """The compiled engine, from the cache when its source and the compiler are unchanged."""
    text = SOURCE.read_text()
    key = cache.digest({SOURCE.name: text, "cflags": " ".join(CFLAGS),
                        "compiler": compiler_version()})
    path = cache.cached_path(key, ".engine.so")
    if not path.exists():
        with tempfile.TemporaryDirectory() as tmp:
            built = Path(tmp) / "engine.so"
            run_compiler([SOURCE], built, [])
            cache.store(key, ".engine.so", built)
    lib = ctypes.CDLL(str(path))
    lib.engine_run.argtypes = [POINTER(EngineRun), c_long, c_long]
    lib.engine_run.restype = c_int
    return lib


def pointer(array: np.ndarray | None, ctype: type[ctypes._SimpleCData[Any]] = c_double
            ) -> ctypes._Pointer[Any] | None:
    """A ctypes pointer to a numpy array's data (None: NULL); the array must outlive it."""
    if array is None:
        return None
    return array.ctypes.data_as(POINTER(ctype))


def function_address(dll: ctypes.CDLL, name: str) -> int:
    """The address of an exported function of a loaded FMU binary."""
    address = cast(getattr(dll, name), c_void_p).value
    if address is None:
        raise RuntimeError(f"the FMU's {name} is a null pointer")
    return address


def start_schedule(run: EngineRun, lead: float = 1e-3) -> None:
    """Point 0 is due `lead` seconds from now, on CLOCK_MONOTONIC (the engine's clock)."""
    ns = time.clock_gettime_ns(time.CLOCK_MONOTONIC) + int(lead * 1e9)
    run.start.tv_sec, run.start.tv_nsec = divmod(ns, 1_000_000_000)


def idle_timing(seconds: float, period: float = 1e-3) -> StepTiming:
    """The engine's paced loop with no FMU in it for `seconds` at `period`: what the machine
    alone does to the schedule (the lateness an empty loop sees, as cyclictest measures), the
    floor beneath every paced run's lateness and overruns."""
    steps = max(1, round(seconds / period))
    tet, lateness = np.zeros(steps + 1), np.zeros(steps + 1)
    scratch = np.zeros(1)  # bus, sources and record: no column, so nothing is written there
    run = EngineRun(step=period, steps=steps, bus=pointer(scratch), sources=pointer(scratch),
                    record=pointer(scratch), typed=TYPED_HOOK(),
                    tet=pointer(tet), slave_tet=pointer(scratch), lateness=pointer(lateness),
                    paced=1, period=period)
    start_schedule(run)
    library().engine_run(ctypes.byref(run), 0, steps + 1)
    listed = tuple(run.first_overruns[:min(run.overruns, MAX_LISTED_OVERRUNS)])
    return StepTiming(period, (), tet[:steps], np.zeros((steps, 0)), lateness[:steps],
                      Pacing(), run.overruns, listed, None)
