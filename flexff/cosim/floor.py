"""The speed floor: the master's loop in C alone (cosim/c/floor.c, compiled with the engine).

The program loads the FMU libraries a Master has extracted, builds the engine's plan from the
Master's bus layout and call plan (same calls, same order, same times) and runs every point in
one call of the engine (cosim/c/engine.c): the engine's own loop, with no Python between its
chunks. It returns its record of the bus, which must equal the Master's bit for bit, with the
best time per step over a few repeats.
"""

from __future__ import annotations

import json
import subprocess
import tempfile
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np

from flexff.cosim import engine
from flexff.cosim.master import Master
from flexff.fmu.compile import cached_program

SOURCE = Path(__file__).parent / "c" / "floor.c"


def loop_program() -> Path:
    """The floor program (floor.c and the engine), from the fmu/ cache when its sources and
    the compiler are unchanged."""
    return cached_program("floor", [SOURCE, engine.SOURCE], [engine.HEADER])


def _plan_text(layout: dict[str, Any], steps: int) -> str:
    lines = ["flexff-cosim-plan 1",
             f"{layout['step']!r} {len(layout['signals'])} {layout['n_sources']} {steps} "
             f"{len(layout['fmus'])}"]
    for s in layout["fmus"]:
        lines += [s["library"], s["guid"], s["name"], str(len(s["parameters"]))]
        lines += [f"{vr} {'I' if kind == 'Integer' else 'R'} {float(value)!r}"
                  for vr, kind, value in s["parameters"]]
        lines += [str(len(s["inputs"]))] + [f"{vr} {index}" for vr, index in s["inputs"]]
        lines += [f"{len(s['outputs'])} {s['output_offset']}"] + [str(vr) for vr in s["outputs"]]
        lines.append(f"{int(s['read_before'])} {int(s['read_after'])}")
    return "\n".join(lines) + "\n"


def run_c_loop(master: Master, sources: Mapping[str, np.ndarray | float], steps: int,
               repeats: int = 3) -> tuple[dict[str, np.ndarray], float]:
    """The bus at every point (by signal name) and the best microseconds per step of the
    floor on `master`'s FMUs and plan; `master` need not have run."""
    layout = master.layout()
    table = np.empty((steps + 1, layout["n_sources"]))
    for j, name in enumerate(layout["signals"][:layout["n_sources"]]):
        table[:, j] = np.broadcast_to(np.asarray(sources[name], dtype=float), (steps + 1,))
    with tempfile.TemporaryDirectory() as tmp:
        plan, src, rec = (Path(tmp) / n for n in ("plan.txt", "sources.bin", "record.bin"))
        plan.write_text(_plan_text(layout, steps))
        table.tofile(src)
        result = subprocess.run([str(loop_program()), str(plan), str(src), str(rec),
                                 str(repeats)], capture_output=True, text=True)
        if result.returncode != 0:
            raise RuntimeError(f"the C floor failed: {result.stderr.strip()}")
        bus = np.fromfile(rec).reshape(steps + 1, len(layout["signals"]))
    us_per_step = json.loads(result.stdout)["us_per_step"]
    return {n: bus[:, j].copy() for j, n in enumerate(layout["signals"])}, us_per_step
