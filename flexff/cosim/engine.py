"""The compiled stepping engine (cosim/c/engine.c), loaded in-process through ctypes.

The library is compiled once into the FMU cache (rebuilt when its source or the compiler
changes). `EngineRun` mirrors the C structures; the master fills it with the FMUs' function
pointers, the bus and the buffers, all allocated before the loop, then calls `run(k0, k1)` in
chunks. Timing: TET per step and per FMU, and lateness against the schedule when paced.

The mirrors are checked against the C layout (engine.c's engine_layout: the size of each
structure, the offset and size of each field) when the library loads, so a field added on one
side only is an error naming it, not memory misread. The engine checks every index of the plan
before each chunk; a plan that does not fit raises EnginePlanError before any FMI call.
"""

from __future__ import annotations

import ctypes
import functools
import tempfile
import time
from collections.abc import Mapping
from ctypes import (
    CFUNCTYPE,
    POINTER,
    Structure,
    byref,
    c_char,
    c_char_p,
    c_double,
    c_int,
    c_long,
    c_size_t,
    c_uint,
    c_void_p,
    cast,
)
from pathlib import Path
from typing import Any

import numpy as np

from flexff.cosim.timing import Pacing, StepTiming
from flexff.fmu import cache
from flexff.fmu.compile import CFLAGS, compiler_version, run_compiler
from flexff.fmu.defaults import DEFAULT_STEP

SOURCE = Path(__file__).parent / "c" / "engine.c"
HEADER = SOURCE.with_suffix(".h")  # its structures, for the programs compiled with it
TYPED_HOOK = CFUNCTYPE(c_int, c_long, c_int, c_long)  # (fmu, phase, k) -> 0 if ok
CALLS = {1: "setting its inputs", 2: "getting its outputs", 3: "the step", 4: "getting its "
         "outputs after the step", 5: "exchanging values of other types", 6: "getting its "
         "outputs (one not finite)", 7: "getting its outputs after the step (one not finite)"}
NONFINITE = (6, 7)  # a non-finite output read before the point's record, after the step
# calls made after their point was recorded (CALL_STEP, CALL_GET_AFTER, CALL_NONFINITE_AFTER)
AFTER_RECORD = (3, 4, 7)
OK, FAILED, OVERRUN, BAD_PLAN = 0, 1, 2, 3  # engine_run's results (RUN_* in engine.c)
MAX_LISTED_OVERRUNS = 16
ERROR_SIZE = 256  # Run.error
Layout = dict[str, tuple[int, int]]  # field -> (offset, size); "": the structure's own size


class EngineLayoutError(RuntimeError):
    """A ctypes mirror disagrees with the C structure it mirrors."""


class EnginePlanError(ValueError):
    """The engine refused a plan whose counts, pointers or indices do not fit."""


class _Timespec(Structure):
    _fields_ = [("tv_sec", c_long), ("tv_nsec", c_long)]


class EngineFmuPlan(Structure):
    """One FMU's calls and its place on the bus (struct FmuPlan of engine.c)."""

    _fields_ = [("fmi3", c_int), ("component", c_void_p), ("set_float64", c_void_p),
                ("get_float64", c_void_p), ("do_step", c_void_p), ("n_in", c_long),
                ("in_vr", POINTER(c_uint)), ("gather", POINTER(c_long)),
                ("gain", POINTER(c_double)), ("offset", POINTER(c_double)),
                ("in_values", POINTER(c_double)), ("n_out", c_long),
                ("out_vr", POINTER(c_uint)), ("out_values", POINTER(c_double)),
                ("read_before", c_int), ("read_after", c_int), ("typed_in", c_int),
                ("typed_out", c_int), ("task_overruns", c_void_p), ("task_seen", c_long),
                ("finite", c_int)]


class EngineRun(Structure):
    """A run's plan, buffers and measurements (struct Run of engine.c)."""

    _fields_ = [("step", c_double), ("start_time", c_double), ("steps", c_long), ("n_fmus", c_long),
                ("fmus", POINTER(EngineFmuPlan)), ("bus", POINTER(c_double)),
                ("n_bus", c_long), ("n_sources", c_long), ("sources", POINTER(c_double)),
                ("record", POINTER(c_double)), ("columns", POINTER(c_long)),
                ("n_columns", c_long), ("typed", TYPED_HOOK), ("typed_record", c_int),
                ("tet", POINTER(c_double)), ("fmu_tet", POINTER(c_double)),
                ("lateness", POINTER(c_double)), ("paced", c_int), ("period", c_double),
                ("start", _Timespec), ("max_overruns", c_long), ("grace_steps", c_long),
                ("overruns", c_long), ("counted", c_long),
                ("first_overruns", c_long * MAX_LISTED_OVERRUNS), ("failed_fmu", c_long),
                ("failed_k", c_long), ("failed_call", c_int), ("error", c_char * ERROR_SIZE),
                ("task_overruns", c_long)]


MIRRORS: dict[str, type[Structure]] = {"struct timespec": _Timespec, "FmuPlan": EngineFmuPlan,
                                       "Run": EngineRun}  # C name -> ctypes mirror


def c_layouts(lib: ctypes.CDLL) -> dict[str, Layout]:
    """The layout engine.c reports of each structure, by C name."""
    structure, field = c_char_p(), c_char_p()
    offset, size = c_size_t(), c_size_t()
    layouts: dict[str, Layout] = {}
    i = 0
    while lib.engine_layout(i, byref(structure), byref(field), byref(offset), byref(size)) == 0:
        name = (structure.value or b"").decode()
        layouts.setdefault(name, {})[(field.value or b"").decode()] = (offset.value, size.value)
        i += 1
    return layouts


def check_layout(mirror: type[Structure], c_name: str, layout: Layout) -> None:
    """Raise EngineLayoutError naming the first field where `mirror` and the C layout of
    `c_name` differ (missing on either side, at another offset or of another size), then their
    sizes."""
    ours: Layout = {"": (0, ctypes.sizeof(mirror))}
    for name, *_ in mirror._fields_:
        described = getattr(mirror, name)
        ours[name] = (described.offset, described.size)
    fields = [*(n for n in layout if n), *(n for n in ours if n and n not in layout)]
    for name in [*fields, ""]:
        if ours.get(name) == layout.get(name):
            continue
        c_side, py_side = (f"at offset {v[0]}, {v[1]} bytes" if v else "absent"
                           for v in (layout.get(name), ours.get(name)))
        what = (f"field {name!r} is {c_side} in C, {py_side} in ctypes" if name else
                f"its size is {layout[''][1]} bytes in C, {ours[''][1]} in ctypes")
        raise EngineLayoutError(f"{mirror.__module__}.{mirror.__qualname__} does not match the "
                                f"C structure {c_name}: {what}")


def _check_result(result: Any, func: Any, args: tuple[Any, ...]) -> Any:
    """engine_run's errcheck: a plan the engine refused raises, with the engine's reason."""
    if result == BAD_PLAN:
        run = getattr(args[0], "_obj", None) or args[0].contents  # byref() or pointer()
        raise EnginePlanError(f"the engine refused the run's plan: {run.error.decode()}")
    return result


@functools.cache
def library() -> ctypes.CDLL:
    """The compiled engine, from the cache when its source and the compiler are unchanged."""
    key = cache.digest({SOURCE.name: SOURCE.read_text(), HEADER.name: HEADER.read_text(),
                        "cflags": " ".join(CFLAGS), "compiler": compiler_version()})
    path = cache.cached_path(key, ".engine.so")
    if not path.exists():
        with tempfile.TemporaryDirectory() as tmp:
            built = Path(tmp) / "engine.so"
            run_compiler([SOURCE], built, [])
            cache.store(key, ".engine.so", built)
    lib = ctypes.CDLL(str(path))
    lib.engine_layout.argtypes = [c_long, POINTER(c_char_p), POINTER(c_char_p),
                                  POINTER(c_size_t), POINTER(c_size_t)]
    lib.engine_layout.restype = c_int
    check_layouts(c_layouts(lib))
    lib.engine_run.argtypes = [POINTER(EngineRun), c_long, c_long]
    lib.engine_run.restype = c_int
    lib.engine_run.errcheck = _check_result
    return lib


def check_layouts(layouts: Mapping[str, Layout]) -> None:
    """Every mirror against the C layout of its structure; C structures no mirror covers are
    an error too."""
    if set(layouts) != set(MIRRORS):
        raise EngineLayoutError(f"cosim/c/engine.c reports the structures {sorted(layouts)}, "
                                f"cosim/engine.py mirrors {sorted(MIRRORS)}")
    for c_name, mirror in MIRRORS.items():
        check_layout(mirror, c_name, layouts[c_name])


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


def idle_timing(seconds: float, period: float = DEFAULT_STEP) -> StepTiming:
    """The engine's paced loop with no FMU in it for `seconds` at `period`: what the machine
    alone does to the schedule (the lateness an empty loop sees, as cyclictest measures), the
    floor beneath every paced run's lateness and overruns."""
    steps = max(1, round(seconds / period))
    tet, lateness = np.zeros(steps + 1), np.zeros(steps + 1)
    scratch = np.zeros(1)  # bus, sources and record: no column, so nothing is written there
    run = EngineRun(step=period, steps=steps, bus=pointer(scratch), sources=pointer(scratch),
                    record=pointer(scratch), typed=TYPED_HOOK(),
                    tet=pointer(tet), fmu_tet=pointer(scratch), lateness=pointer(lateness),
                    paced=1, period=period)
    start_schedule(run)
    library().engine_run(ctypes.byref(run), 0, steps + 1)
    listed = tuple(run.first_overruns[:min(run.overruns, MAX_LISTED_OVERRUNS)])
    return StepTiming(period, (), tet[:steps], np.zeros((steps, 0)), lateness[:steps],
                      Pacing(), run.overruns, run.task_overruns, listed, None)
