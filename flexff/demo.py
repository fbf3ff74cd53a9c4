"""`flexff demo`: the whole pipeline on the embedded defaults.

1. build and validate the plant FMUs (both variants);
2. `flexff evaluate --env sim` with the fast preset: collect the `sim` data set, train the four
   models, export them to ONNX, co-simulate the thesis evaluation reference with PID alone, the
   rigid-body feedforward and each learned feedforward FMU, and print the comparison with the
   thesis's Table 5.2.

Every step reuses what an earlier run left in the output folder (FMU cache, collected files,
finished training runs), so an interrupted demo continues where it stopped.
"""

from __future__ import annotations

import time
from pathlib import Path

from flexff.fmu.build import build_fmu
from flexff.fmu.validation import validate_fmu
from flexff.plant.system import plant_system


def _stage(title: str) -> float:
    print(f"\n== {title}", flush=True)
    return time.perf_counter()


def _done(start: float) -> None:
    print(f"   ({time.perf_counter() - start:.1f} s)", flush=True)


def _build_plants(out: Path) -> bool:
    ok = True
    for variant in ("nominal", "hardware"):
        path = build_fmu(plant_system(variant), out / f"plant_{variant}.fmu")
        problems = validate_fmu(path)
        ok &= not problems
        print(f"   {path}: {'valid' if not problems else '; '.join(problems)}")
    return ok


def run_demo(output: str | Path, device: str = "auto") -> int:
    """Run the demo into folder `output`, training on `device` ('auto', 'cpu', 'cuda';
    learning.devices); print what it finds; 0 on success."""
    from flexff.learning.devices import pick_device
    from flexff.learning.evaluate import evaluate

    pick_device(device)  # a device that is not there fails before the FMUs are built

    out = Path(output)
    out.mkdir(parents=True, exist_ok=True)
    start = _stage("1/2 plant FMUs")
    if not _build_plants(out):
        return 1
    _done(start)
    start = _stage("2/2 evaluation (sim): data, training (fast preset), ONNX export, "
                   "co-simulation of the thesis evaluation reference")
    evaluate("sim", out, "fast", say=lambda line: print(f"   {line}", flush=True),
             device=device)
    _done(start)
    print("\n" + (out / "table.md").read_text())
    print(f"results in {out}/ (summary.json, table.md, paths.png, errors.png, forces.png, "
          f"the .onnx models, one folder per co-simulation in cosim/)")
    return 0
