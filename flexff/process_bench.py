"""`flexff bench --processes`: a run's whole cost, as a user times it: whole processes side by
side on one third-party FMU and step, each tool writing its default record.

flexff (`python -m flexff run`), fmpy (`simulate_fmu` and `write_csv`) and Ecos (`ecospy`,
where an interpreter with it is at hand) run in turn `repeats` times after one uncounted run;
each figure is the median wall time and peak resident memory (os.wait4). `flexff --help`, a
bare `python -c pass` and `import flexff.cosim.run` are timed as whole processes too. Python's
bytecode cache is used as on a user's machine (PYTHONDONTWRITEBYTECODE is not passed on).
`isolation` gives the cost per step of the FMU in its own process, beside Ecos's proxyfmu
(flexff.isolation_bench).

Docs: "Benchmarks" (docs/results/benchmarks.md).
"""

from __future__ import annotations

import os
import statistics
import subprocess
import sys
import tempfile
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from flexff.fmu.defaults import DEFAULT_STEP
from flexff.fmu.errors import InputError
from flexff.isolation_bench import isolation_benchmark

FMPY = """import sys
from fmpy import simulate_fmu
from fmpy.util import write_csv
fmu, stop, step, out = sys.argv[1], float(sys.argv[2]), float(sys.argv[3]), sys.argv[4]
write_csv(out + "/result.csv", simulate_fmu(fmu, stop_time=stop, output_interval=step))
"""
ECOS = """import ctypes, os, sys
tbb = os.path.join(sys.prefix, "lib", "libtbb.so.12")
if os.path.exists(tbb):
    ctypes.CDLL(tbb, ctypes.RTLD_GLOBAL)
from ecospy import EcosSimulation, EcosSimulationStructure
fmu, stop, step, out = sys.argv[1], float(sys.argv[2]), float(sys.argv[3]), sys.argv[4]
structure = EcosSimulationStructure()
structure.add_model("fmu", fmu)
with EcosSimulation(structure=structure, step_size=step) as simulation:
    simulation.add_csv_writer(out + "/result.csv")
    simulation.init()
    simulation.step_until(stop)
"""
ISOLATION_STEPS = 20_000  # steps of the isolation benchmark (flexff.isolation_bench)
CONFIG = '[fmu.fmu]\npath = "{fmu}"\n\n[run]\nstep = {step!r}\nstop = {stop!r}\n'


# Times one command and reads its peak memory, as a small process of its own: Linux's peak
# resident memory of a process starts at that of the process it was forked from (exec keeps the
# higher of the two), so the bench's own (numpy, pyarrow: about 40 MiB) would be every small
# tool's floor; this launcher's is Python's bare 10 MiB.
LAUNCHER = """import os, subprocess, sys, time
start = time.perf_counter()
child = subprocess.Popen(sys.argv[1:], stdout=subprocess.DEVNULL)
_, status, usage = os.wait4(child.pid, 0)
print(time.perf_counter() - start, usage.ru_maxrss, os.waitstatus_to_exitcode(status))
"""


def _measure(command: Sequence[str], env: dict[str, str] | None = None) -> tuple[float, float]:
    """(wall seconds, peak resident MiB) of one process running `command`."""
    launched = subprocess.run([sys.executable, "-c", LAUNCHER, *command], capture_output=True,
                              text=True, env=env)
    wall, peak_kib, code = launched.stdout.split()
    if launched.returncode != 0 or int(code) != 0:
        raise RuntimeError(f"{command[:3]} failed ({code}): {launched.stderr[-500:]}")
    return float(wall), int(peak_kib) / 1024


def _has_ecospy(python: str) -> bool:
    probe = subprocess.run([python, "-c", "import importlib.util as u; "
                            "print(u.find_spec('ecospy') is not None)"],
                           capture_output=True, text=True)
    return probe.stdout.strip() == "True"


def _median(runs: list[tuple[float, float]]) -> dict[str, float]:
    return {"wall_s": statistics.median(r[0] for r in runs),
            "peak_mib": statistics.median(r[1] for r in runs)}


def process_benchmark(fmu: Path, steps: Sequence[int] = (200_000, 2_000_000),
                      step: float = DEFAULT_STEP, repeats: int = 3,
                      ecos_python: str | None = None) -> dict[str, Any]:
    """The module doc's figures for `fmu` at each number of `steps`, with each peer's time
    over flexff's (`speedup_vs_*`: how many times faster flexff's whole process is)."""
    if repeats < 1 or any(n < 1 for n in steps):
        raise InputError("bench --processes needs at least one repeat and one step")
    env = {**os.environ, "PYTHONPATH": os.pathsep.join(
        filter(None, (str(Path(__file__).resolve().parents[1]), os.environ.get("PYTHONPATH"))))}
    env.pop("PYTHONDONTWRITEBYTECODE", None)
    python = ecos_python or sys.executable
    ecos = _has_ecospy(python)
    results: dict[str, Any] = {"fmu": fmu.name, "step_s": step, "repeats": repeats,
                               "ecos": ecos or f"ecospy is not installed for {python}"}
    startup: dict[str, list[tuple[float, float]]] = {"python_bare": [], "flexff_help": [],
                                                     "import_plain_run": []}
    commands = {"python_bare": [sys.executable, "-c", "pass"],
                "flexff_help": [sys.executable, "-m", "flexff", "--help"],
                "import_plain_run": [sys.executable, "-c", "import flexff.cosim.run"]}
    for run in range(repeats + 1):  # the first writes the bytecode caches, and is not counted
        for name, command in commands.items():
            measured = _measure(command, env)
            if run:
                startup[name].append(measured)
    results["startup"] = {n: _median(r) for n, r in startup.items()}
    with tempfile.TemporaryDirectory(prefix="flexff-bench-") as tmp:
        for size, n in enumerate(steps):
            stop = n * step
            config = Path(tmp) / "run.toml"
            config.write_text(CONFIG.format(fmu=fmu.as_posix(), step=step, stop=stop))
            tools = {"flexff": [sys.executable, "-m", "flexff", "run", str(config), "-o",
                                f"{tmp}/flexff"],
                     "fmpy": [sys.executable, "-c", FMPY, str(fmu), str(stop), str(step), tmp]}
            if ecos:
                tools["ecos"] = [python, "-c", ECOS, str(fmu), str(stop), str(step), tmp]
            runs: dict[str, list[tuple[float, float]]] = {t: [] for t in tools}
            for run in range(0 if size == 0 else 1, repeats + 1):  # run 0 is not counted
                for tool, command in tools.items():
                    measured = _measure(command, env)
                    if run:
                        runs[tool].append(measured)
            figures: dict[str, Any] = {t: _median(r) for t, r in runs.items()}
            for tool in tools:
                if tool != "flexff":
                    figures[f"speedup_vs_{tool}"] = statistics.median(
                        p[0] / f[0] for p, f in zip(runs[tool], runs["flexff"]))
            results[f"{n}_steps"] = figures
    results["isolation"] = isolation_benchmark(fmu, ISOLATION_STEPS, step, repeats,
                                               python if ecos else None)
    return results
