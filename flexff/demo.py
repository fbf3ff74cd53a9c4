"""`flexff demo`: the whole pipeline on the embedded defaults, as far as it is built.

1. build and validate the plant FMUs (both variants);
2. collect the `sim` data set (PID-only co-simulations of the thesis's trajectories);
3. train the physics-guided model with the `fast` preset and export it to ONNX;
4. co-simulate the thesis evaluation reference without feedforward and with the rigid-body
   feedforward, and print the comparison table with the thesis's Table 5.2 column.

The learned feedforward's own co-simulation joins the table when its FMU exists. Every step
reuses what an earlier run left in the output folder (FMU cache, collected files, run folder).
"""

from __future__ import annotations

import json
import time
from pathlib import Path

from cosim.config import config_examples, parse_config
from cosim.run import run_config
from fmu.build import build_fmu
from fmu.validation import validate_fmu
from plant.system import plant_system

# the thesis's Table 5.2, "without FF" column (scaled 1e-4 there)
THESIS_WITHOUT_FF = {"x": {"e2": 42.930e-4, "einf": 142.23e-4},
                     "y": {"e2": 42.940e-4, "einf": 140.00e-4}}


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


def _train_and_export(data: Path, out: Path) -> Path:
    from learning.export import export
    from learning.train import train

    run = out / "runs" / "pgnn"
    metrics = (json.loads((run / "metrics.json").read_text()) if (run / "metrics.json").is_file()
               else train("pgnn", "fast", data, run))
    print(f"   pgnn: test MSE {metrics['test_mse']:.3g} (normalized; the thesis's best, TCN: "
          f"19.1e-6), {metrics['parameters']} parameters, "
          f"{metrics['seconds_per_epoch']:.2f} s per epoch")
    return export(run, out / "pgnn.onnx")


def _evaluate(out: Path) -> dict[str, dict]:
    results = {}
    for name, label in (("thesis-eval-pid", "PID alone"),
                        ("thesis-eval-model-ff", "rigid-body FF")):
        config = parse_config(config_examples()[name], name=name)
        results[label] = run_config(config, out / "evaluation" / name)
    return results


def _table(results: dict[str, dict]) -> str:
    pid = results["PID alone"]
    lines = ["| scenario | e2 x | e2 y | einf x | einf y | e2 ratio x | e2 ratio y |",
             "|---|---|---|---|---|---|---|"]
    t = THESIS_WITHOUT_FF
    lines.append(f"| thesis Table 5.2, without FF | {t['x']['e2']:.3e} | {t['y']['e2']:.3e} | "
                 f"{t['x']['einf']:.3e} | {t['y']['einf']:.3e} | | |")
    for label, m in results.items():
        ratio = [pid[a]["e2"] / m[a]["e2"] for a in "xy"]
        lines.append(f"| {label} | {m['x']['e2']:.3e} | {m['y']['e2']:.3e} | "
                     f"{m['x']['einf']:.3e} | {m['y']['einf']:.3e} | {ratio[0]:.1f} | "
                     f"{ratio[1]:.1f} |")
    return "\n".join(lines)


def run_demo(output: str | Path) -> int:
    """Run the demo into folder `output`; print what it finds; 0 on success."""
    from learning.collect import run_collection

    out = Path(output)
    out.mkdir(parents=True, exist_ok=True)
    start = _stage("1/4 plant FMUs")
    if not _build_plants(out):
        return 1
    _done(start)
    start = _stage("2/4 sim data set (44 + 4 trajectories, PID only)")
    report = run_collection("sim", out / "data-sim")
    if not report.ok:
        return 1
    print(f"   {len(report.ran)} run, {len(report.skipped)} already there -> {report.path}")
    _done(start)
    start = _stage("3/4 physics-guided model (fast preset), ONNX export")
    print(f"   wrote {_train_and_export(report.path, out)}")
    _done(start)
    start = _stage("4/4 thesis evaluation reference (nominal plant), e2 [m/sqrt(s)], einf [m]")
    table = _table(_evaluate(out))
    (out / "comparison.md").write_text(table + "\n")
    print(table)
    _done(start)
    print(f"\nresults in {out}/ (plots in evaluation/*/, the table in comparison.md)")
    return 0
