"""`flexff bench`: speed figures measured in one run, as JSON (ratios where they matter)."""

from __future__ import annotations

import platform
import tempfile
from pathlib import Path
from typing import Any

from fmu.bench import bench_fmu
from fmu.build import build_fmu
from plant.system import plant_system


def run_benchmarks(steps: int = 20000, repeats: int = 5) -> dict[str, Any]:
    """Cost of a 1 ms plant step through fmpy's low-level API and in plain C, per variant."""
    results: dict[str, Any] = {"machine": platform.processor() or platform.machine(),
                               "python": platform.python_version(), "plant_step": {}}
    with tempfile.TemporaryDirectory() as tmp:
        for variant in ("nominal", "hardware"):
            path = build_fmu(plant_system(variant), Path(tmp) / f"plant_{variant}.fmu")
            figures = bench_fmu(path, steps=steps, repeats=repeats)
            figures["real_time_factor_fmpy"] = 1e3 / figures["python_us_per_step"]
            results["plant_step"][variant] = figures
    return results
