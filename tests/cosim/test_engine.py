"""The engine's C side guards its Python side: the ctypes mirrors are checked against the
layout engine.c reports (and the fuzz driver's fmi2CallbackFunctions against the FMI header),
and a plan whose indices do not fit is refused before any FMI call."""

import subprocess
from ctypes import Structure, byref, c_int, c_long, c_uint

import numpy as np
import pytest

from flexff.cosim.engine import (
    MIRRORS,
    TYPED_HOOK,
    EngineFmuPlan,
    EngineLayoutError,
    EnginePlanError,
    EngineRun,
    Layout,
    c_layouts,
    check_layout,
    library,
    pointer,
)
from flexff.fmu.compile import compiler, fmi_headers
from tests.fmu_fuzz_driver import Callbacks


def _fields(mirror: type[Structure]) -> list[tuple]:
    return [tuple(field) for field in mirror._fields_]


def _variant(mirror: type[Structure], fields: list[tuple]) -> type[Structure]:
    return type(mirror.__name__, (Structure,), {"_fields_": fields})


@pytest.fixture(scope="module")
def layouts() -> dict[str, Layout]:
    return c_layouts(library())


def test_the_mirrors_match_the_engine(layouts):
    assert set(layouts) == set(MIRRORS)
    for c_name, mirror in MIRRORS.items():
        check_layout(mirror, c_name, layouts[c_name])


def _without_gain():
    return _variant(EngineFmuPlan, [f for f in _fields(EngineFmuPlan) if f[0] != "gain"])


def _long_flag():
    return _variant(EngineFmuPlan, [("fmi3", c_long), *_fields(EngineFmuPlan)[1:]])


def _extra_field():
    return _variant(EngineFmuPlan, [*_fields(EngineFmuPlan), ("spare", c_int)])


def _short_array():
    return _variant(EngineRun, [(n, c_long * 15) if n == "first_overruns" else (n, t)
                                for n, t in _fields(EngineRun)])


@pytest.mark.parametrize("make, c_name, message", [
    (_without_gain, "FmuPlan", "field 'gain' is at offset 64, 8 bytes in C, absent in ctypes"),
    (_long_flag, "FmuPlan", "field 'fmi3' is at offset 0, 4 bytes in C, at offset 0, 8 bytes"),
    (_extra_field, "FmuPlan", "field 'spare' is absent in C"),
    (_short_array, "Run", "field 'first_overruns' is at offset 200, 128 bytes in C, at offset "
                          "200, 120 bytes in ctypes"),
], ids=["missing", "type", "extra", "array"])
def test_a_wrong_mirror_is_caught(layouts, make, c_name, message):
    with pytest.raises(EngineLayoutError, match="does not match the C structure") as caught:
        check_layout(make(), c_name, layouts[c_name])
    assert message in str(caught.value)


def test_the_fuzz_drivers_callbacks_match_the_fmi_header(tmp_path):
    """tests/fmu_fuzz_driver.py mirrors fmi2CallbackFunctions by hand too."""
    for name, text in fmi_headers().items():
        (tmp_path / name).write_text(text)
    fields = [name for name, _ in Callbacks._fields_]
    lines = "".join(f'    printf("{n} %zu %zu\\n", offsetof(T, {n}), sizeof(((T *)0)->{n}));\n'
                    for n in fields)
    (tmp_path / "layout.c").write_text(
        '#include <stddef.h>\n#include <stdio.h>\n#include "fmi2Functions.h"\n'
        "typedef fmi2CallbackFunctions T;\n"
        f'int main(void) {{\n    printf("- 0 %zu\\n", sizeof(T));\n{lines}    return 0;\n}}\n')
    subprocess.run([compiler(), "-std=c99", f"-I{tmp_path}", str(tmp_path / "layout.c"), "-o",
                    str(tmp_path / "layout")], check=True)
    output = subprocess.run([str(tmp_path / "layout")], capture_output=True, text=True,
                            check=True).stdout
    layout = {("" if name == "-" else name): (int(offset), int(size))
              for name, offset, size in (line.split() for line in output.splitlines())}
    check_layout(Callbacks, "fmi2CallbackFunctions", layout)


def _run(bus: np.ndarray, gather: np.ndarray, columns: np.ndarray | None, steps: int = 2):
    """A one-FMU plan whose FMU is never called (dummy pointers): the plan is refused first.
    Returns the run and what it points into, which must outlive it."""
    values, vr = np.zeros(gather.size), np.zeros(gather.size, dtype=np.uint32)
    out = bus[1:2]
    plan = EngineFmuPlan(0, 1, 1, 1, 1, gather.size, pointer(vr, c_uint), pointer(gather, c_long),
                        None, None, pointer(values), 1, pointer(vr, c_uint), pointer(out))
    plans = (EngineFmuPlan * 1)(plan)
    buffers = np.zeros((steps + 1, bus.size)), np.zeros(steps), np.zeros(steps), np.zeros(steps)
    record, tet, fmu_tet, lateness = buffers
    run = EngineRun(step=1e-3, steps=steps, n_fmus=1, fmus=plans, bus=pointer(bus),
                    n_bus=bus.size, n_sources=0, sources=pointer(bus), record=pointer(record),
                    columns=pointer(columns, c_long),
                    n_columns=bus.size if columns is None else columns.size, typed=TYPED_HOOK(),
                    tet=pointer(tet), fmu_tet=pointer(fmu_tet), lateness=pointer(lateness))
    return run, (bus, gather, columns, values, vr, plans, buffers)


@pytest.mark.parametrize("gather, columns, points, message", [
    ([0, 7], None, (0, 1), "fmu 0: input 1 reads bus index 7"),
    ([0, -1], None, (0, 1), "fmu 0: input 1 reads bus index -1"),
    ([0], [2, 3], (0, 1), "recorded column 1 is bus index 3, the bus has 3"),
    ([0], None, (0, 4), "points 0 .. 3 asked for, the run has points 0 .. 2"),
], ids=["input index", "negative index", "column", "points"])
def test_a_plan_that_does_not_fit_is_refused(gather, columns, points, message):
    run, alive = _run(np.zeros(3), np.array(gather, dtype=np.int64),
                      None if columns is None else np.array(columns, dtype=np.int64))
    with pytest.raises(EnginePlanError, match="the engine refused the run's plan") as caught:
        library().engine_run(byref(run), *points)
    assert message in str(caught.value)
    assert alive


def test_outputs_outside_the_bus_are_refused():
    bus = np.zeros(3)
    run, alive = _run(bus, np.array([0], dtype=np.int64), None)
    outside = np.zeros(1)  # not a block of the bus
    run.fmus[0].out_values = pointer(outside)
    with pytest.raises(EnginePlanError, match="fmu 0: its 1 outputs do not lie inside the bus"):
        library().engine_run(byref(run), 0, 1)
    assert alive
