"""What running an FMU in its own process costs per step, beside Ecos's proxyfmu.

flexff's master steps the FMU in-process, isolated (cosim.isolation) and isolated in its sandbox
(cosim.sandbox); Ecos (`ecospy`, where an interpreter with it is at hand) steps it in-process
and through proxyfmu, its FMU-in-a-process. The variants run in turn, `repeats` rounds, and
each figure is the best microseconds per step of its rounds, so that a busy machine's noise
falls alike on all. Part of `flexff bench --processes` (flexff.process_bench).
"""

from __future__ import annotations

import subprocess
from pathlib import Path
from typing import Any

import numpy as np

from flexff.cosim.recording import Recording
from flexff.cosim.sandbox import DEFAULT, Sandbox
from flexff.fmu.defaults import DEFAULT_STEP
from flexff.fmu_bench import master_us_per_step

ECOS_STEPS = """import ctypes, os, sys, time
tbb = os.path.join(sys.prefix, "lib", "libtbb.so.12")
if os.path.exists(tbb):
    ctypes.CDLL(tbb, ctypes.RTLD_GLOBAL)
from ecospy import EcosSimulation, EcosSimulationStructure
fmu, steps, step, proxy = sys.argv[1], int(sys.argv[2]), float(sys.argv[3]), sys.argv[4] == "1"
structure = EcosSimulationStructure()
structure.add_model("fmu", f"proxyfmu://localhost?file={fmu}" if proxy else fmu)
with EcosSimulation(structure=structure, step_size=step) as simulation:
    simulation.init()
    start = time.perf_counter()
    simulation.step(steps)
    print("us_per_step", 1e6 * (time.perf_counter() - start) / steps)
"""
FLEXFF: dict[str, tuple[bool, Sandbox | None]] = {  # variant: (isolated, its sandbox)
    "in_process": (False, None), "isolated": (True, None), "sandboxed": (True, DEFAULT)}


def _ecos_us_per_step(python: str, fmu: Path, steps: int, step: float, proxy: bool
                      ) -> float | str:
    """Ecos's microseconds per step, or why it did not run."""
    done = subprocess.run([python, "-c", ECOS_STEPS, str(fmu), str(steps), str(step),
                           "1" if proxy else "0"], capture_output=True, text=True)
    lines = [line for line in done.stdout.splitlines() if line.startswith("us_per_step ")]
    if done.returncode != 0 or not lines:
        last = (done.stderr or done.stdout).strip().splitlines()[-1:] or ["no output"]
        return f"failed (exit {done.returncode}): {last[0][:300]}"
    return float(lines[-1].split()[1])


def isolation_benchmark(fmu: Path, steps: int = 20_000, step: float = DEFAULT_STEP,
                        repeats: int = 5, ecos_python: str | None = None) -> dict[str, Any]:
    """Best µs per step of each variant (module doc), their ratios to Ecos's proxyfmu, and
    whether flexff's three records are equal."""
    best: dict[str, float] = {}
    ecos: dict[str, float | str] = {}
    records: dict[str, Recording] = {}
    for _ in range(repeats):
        for name, (isolate, sandbox) in FLEXFF.items():
            us, records[name] = master_us_per_step(fmu, {}, steps, step, 1, isolate, sandbox)
            best[name] = min(best.get(name, us), us)
        for name, proxy in (("ecos_in_process", False), ("ecos_proxyfmu", True)):
            if ecos_python is not None and not isinstance(ecos.get(name, 0.0), str):
                us_or_why = _ecos_us_per_step(ecos_python, fmu, steps, step, proxy)
                ecos[name] = (us_or_why if isinstance(us_or_why, str)
                              else min(float(ecos.get(name, us_or_why)), us_or_why))
    inside = records["in_process"]
    results: dict[str, Any] = {
        "steps": steps, "repeats": repeats,
        **{f"{name}_us_per_step": us for name, us in best.items()},
        "same_outputs": all(np.array_equal(inside[n], r[n]) for r in records.values()
                            for n in inside.signals),
        **{(f"{name}_us_per_step" if isinstance(v, float) else name): v
           for name, v in ecos.items()}}
    proxyfmu = ecos.get("ecos_proxyfmu")
    if isinstance(proxyfmu, float):
        results["isolated_vs_proxyfmu"] = best["isolated"] / proxyfmu
        results["sandboxed_vs_proxyfmu"] = best["sandboxed"] / proxyfmu
    return results
