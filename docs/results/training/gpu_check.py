"""The figures of one GPU check (gpu_check.sh beside this) as one JSON file.

    python docs/results/training/gpu_check.py FILES --cpu-evaluation DIR --cpu-drive DIR \
        --commit SHA --date YYYY-MM-DD --machine TEXT -o docs/results/training/gpu-check.json

FILES holds what gpu_check.sh wrote ($OUT); the CPU folders are the same two evaluations on
the CPU (the same seeds, data and epochs). Out come: the CUDA tests' outcome; the training
bench's seconds per epoch (eager, CUDA graphs, the CPU), the graphs' results against the
eager ones, one against four trainings sharing the GPU; the GPU's busy share while the short
thesis evaluation trained; that evaluation's wall time and the whole one's estimated from it;
the e2 ratios on CUDA against the CPU's.

The estimate of a whole thesis evaluation: the short one's wall time (collection, ILC labels,
export, co-simulation do not depend on the epochs), plus the epochs it left out of each
training at the bench's seconds per epoch of that training alone, divided by what sharing the
GPU gained in the short evaluation (`sharing_gain`; below 1 where it lost); and without that
division (`whole_evaluation_s_no_sharing_loss`). Where the short evaluation stopped early (an
error), its wall time to there.
"""

from __future__ import annotations

import argparse
import json
import re
import statistics
import tarfile
from itertools import pairwise
from pathlib import Path
from typing import Any

WORK = r"/tmp/tmp\.\w+/"  # gpu_check.sh's work folder (mktemp -d), named WORK in the figures


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("files", type=Path, help="what gpu_check.sh wrote ($OUT)")
    parser.add_argument("--cpu-evaluation", type=Path, required=True,
                        help="the short thesis evaluation's folder, run on the CPU (where it "
                             "holds no co-simulation, CUDA's figures stand alone)")
    parser.add_argument("--cpu-drive", type=Path, required=True,
                        help="the example drive's evaluation folder, run on the CPU")
    parser.add_argument("--commit", required=True)
    parser.add_argument("--date", required=True)
    parser.add_argument("--machine", required=True)
    parser.add_argument("--note", action="append", default=[],
                        help="a line on how the check ran, kept with the figures")
    parser.add_argument("-o", "--output", type=Path, required=True)
    args = parser.parse_args()
    figures = check_figures(args.files, args.cpu_evaluation, args.cpu_drive)
    figures = {"date": args.date, "commit": args.commit, "machine": args.machine,
               "notes": args.note, **figures}
    args.output.write_text(json.dumps(figures, indent=2) + "\n")


def check_figures(files: Path, cpu_evaluation: Path, cpu_drive: Path) -> dict[str, Any]:
    """Every figure of the check in `files`, the CPU's evaluations beside it."""
    runs = _unpacked(files / "results.tgz")
    phases = _phases(files / "phases.txt")
    log = _stamped_lines(files / "evaluate.log")
    gpu = _gpu_readings(files / "gpu.csv")
    bench = json.loads((files / "bench.json").read_text())
    figures: dict[str, Any] = {
        "tests": (files / "tests.txt").read_text().strip().splitlines()[-1],
        "phases_s": _phase_seconds(phases),
        "bench": _bench(bench)}
    evaluation = _evaluation(log, gpu, runs, phases, bench)
    if evaluation:
        figures["evaluation"] = evaluation
    for name, folder, cpu in (("evaluation", "eval", cpu_evaluation),
                              ("drive", "drive", cpu_drive)):
        on_cuda = _e2_ratios({path.removeprefix(f"{folder}/"): data
                              for path, (_, data) in runs.items()})
        on_cpu = _e2_ratios({str(path.relative_to(cpu)): path.read_bytes()
                             for path in [*cpu.glob("cosim/*/metrics.json"),
                                          *cpu.glob("summary.json")]})
        if on_cuda:  # and the CPU's beside, where it ran
            figures.setdefault("e2_ratio", {})[name] = {
                scenario: {axis: {"cuda": ratio, **({"cpu": on_cpu[scenario][axis],
                                                     "change": ratio / on_cpu[scenario][axis] - 1}
                                                    if scenario in on_cpu else {})}
                           for axis, ratio in axes.items()}
                for scenario, axes in on_cuda.items()}
    return figures


def _unpacked(archive: Path) -> dict[str, tuple[float, bytes]]:
    """The files of gpu_check.sh's archive by their path (no leading './'): when each was
    last written (POSIX archive: to the microsecond) and what it holds."""
    with tarfile.open(archive) as packed:
        return {m.name.removeprefix("./"): (float(m.pax_headers.get("mtime", m.mtime)),
                                            packed.extractfile(m).read())  # type: ignore[union-attr]
                for m in packed.getmembers() if m.isfile()}


def _phases(path: Path) -> list[tuple[float, str]]:
    return [(float(when), what) for when, what in
            (line.split(" ", 1) for line in path.read_text().splitlines())]


def _phase_seconds(phases: list[tuple[float, str]]) -> dict[str, float]:
    """Seconds from the check's start to each phase's line."""
    start = phases[0][0]
    return {what: round(when - start, 1) for when, what in phases}


def _stamped_lines(path: Path) -> list[tuple[float, str]]:
    lines = []
    for line in path.read_text(errors="replace").splitlines():
        when, _, text = line.partition(" ")
        try:
            lines.append((float(when), text))
        except ValueError:
            continue
    return lines


def _gpu_readings(path: Path) -> list[tuple[float, float, float]]:
    """(time, busy share [0, 1], memory in use [GB]) every 0.1 s."""
    readings = []
    for line in path.read_text().splitlines():
        try:
            when, busy, used = (float(v) for v in line.split(","))
        except ValueError:
            continue
        readings.append((when, busy / 100, used))
    return readings


def _interval(gpu: list[tuple[float, float, float]]) -> float:
    """The median seconds between two readings."""
    return statistics.median(b[0] - a[0] for a, b in pairwise(gpu))


def _busy(gpu: list[tuple[float, float, float]], since: float, until: float) -> float | None:
    during = [busy for when, busy, _ in gpu if since <= when <= until]
    return round(statistics.mean(during), 3) if during else None


def _bench(bench: dict[str, Any]) -> dict[str, Any]:
    """Per training of the thesis preset: seconds per epoch and start on each variant, the
    graphs' speed-up and their last validation loss against the eager one; the sharing
    figures and the bench's own estimate."""
    out: dict[str, Any] = {"trainings": {}}
    for name, entry in bench["presets"]["thesis"].items():
        if "timed_as" in entry:
            continue
        row: dict[str, Any] = {"epochs": entry["epochs"]}
        for variant in ("cuda", "cuda_graphs", "cpu"):
            run = entry.get(variant, {})
            row[variant] = {k: run[k] for k in ("epoch_s", "start_s", "gpu_busy", "val",
                                                "gpu_memory_gb", "cuda_graphs", "error")
                            if run.get(k) is not None}
        if row["cpu"].get("cuda_graphs") or entry.get("cpu", {}).get("device", "cpu") != "cpu":
            row["cpu_on_cuda"] = row.pop("cpu")  # a bench before its fix: on the default device
            row["cpu"] = {}
        seconds = {v: row[v].get("epoch_s") for v in ("cuda", "cuda_graphs", "cpu")}
        for ratio, (slow, fast) in {"speedup": ("cpu", "cuda"),
                                    "graph_speedup": ("cuda", "cuda_graphs"),
                                    "graphs_speedup_over_cpu": ("cpu", "cuda_graphs")}.items():
            if seconds[slow] and seconds[fast]:
                row[ratio] = seconds[slow] / seconds[fast]
        if seconds["cpu"] and row["cuda"].get("gpu_busy"):
            row["speedup_bound"] = seconds["cpu"] / (seconds["cuda"] * row["cuda"]["gpu_busy"])
        out["trainings"][name] = row
    out.update({k: bench[k] for k in ("sharing", "sharing_graphs") if k in bench})
    out["estimate_s"] = bench.get("estimate_s", {}).get("thesis", {})
    return out


def _evaluation(log: list[tuple[float, str]], gpu: list[tuple[float, float, float]],
                runs: dict[str, tuple[float, bytes]], phases: list[tuple[float, str]],
                bench: dict[str, Any]) -> dict[str, Any]:
    """The short evaluation's wall time (to its end or its error), its training's, the GPU's
    busy share meanwhile and while the most trainings were in their epochs together (each
    training's epochs placed back from when it wrote its metrics), how much of the trainings'
    work alone those seconds did (`sharing_gain`: 1 for none), and the whole evaluation's
    estimate (see the module's docstring)."""
    start = next((when for when, what in phases if what.startswith("evaluate graphs")), None)
    end = next((when for when, what in phases if what.startswith("evaluate rc=")), None)
    trained = [when for when, text in log if re.match(r"training .* preset\)", text)]
    exported = [when for when, text in log if ": test MSE " in text]
    if start is None or end is None or not trained or not exported:
        return {}
    written = {path.split("/")[2]: (when, json.loads(data)) for path, (when, data) in runs.items()
               if re.fullmatch(r"eval/runs/[^/]+/metrics\.json", path)}
    variant = "cuda_graphs" if all(m["cuda_graphs"] for _, m in written.values()) else "cuda"
    entries = bench["presets"]["thesis"]
    alone = {name: entries[entries[name].get("timed_as", name)][variant]["epoch_s"]
             for name in written}
    epochs = {name: _epoch_spans(when, m["history"]["seconds"])
              for name, (when, m) in written.items()}
    together, window = _most_together(epochs)
    work = sum(alone[name] * sum(window[0] <= a and b <= window[1] for a, b in spans)
               for name, spans in epochs.items())
    gain = work / (window[1] - window[0])
    errors = [text for _, text in log if text.startswith("flexff: error:")]
    training_s = exported[0] - trained[0]
    extra = sum((entries[name]["epochs"] - m["epochs"]) * entries[name]["members"] * alone[name]
                for name, (_, m) in written.items())
    wall = end - start
    return {"epochs": {name: m["epochs"] for name, (_, m) in written.items()},
            "graphs": variant == "cuda_graphs", "wall_s": round(wall, 1),
            **({"stopped_by": re.sub(WORK, "WORK/", errors[0])} if errors else {}),
            "phases_s": _log_phases(log, start),
            "training_s": round(training_s, 1),
            "gpu_busy_training": _busy(gpu, trained[0], exported[0]),
            "trainings_together": together, "seconds_together": round(window[1] - window[0], 1),
            "gpu_busy_together": _busy(gpu, *window), "sharing_gain": round(gain, 3),
            "epoch_s_alone": alone,
            "epoch_s_in_evaluation": {name: statistics.median(m["history"]["seconds"][1:])
                                      for name, (_, m) in written.items()},
            "test_mse": {name: m["test_mse"] for name, (_, m) in written.items()},
            "whole_training_s": round(training_s + extra / gain, 1),
            "whole_evaluation_s": round(wall + extra / gain, 1),
            "whole_evaluation_s_no_sharing_loss": round(wall + extra, 1)}


def _epoch_spans(written: float, seconds: list[float]) -> list[tuple[float, float]]:
    """Each epoch's start and end but the first (capture, warm-up), placed back from when
    the training wrote its metrics."""
    spans, end = [], written
    for took in reversed(seconds[1:]):
        spans.append((end - took, end))
        end -= took
    return spans[::-1]


def _most_together(epochs: dict[str, list[tuple[float, float]]]
                   ) -> tuple[int, tuple[float, float]]:
    """The most trainings in their epochs at once, and the longest span they were."""
    bounds = {name: (spans[0][0], spans[-1][1]) for name, spans in epochs.items() if spans}
    best: tuple[int, tuple[float, float]] = (0, (0.0, 0.0))
    for names in _subsets(sorted(bounds)):
        since = max(bounds[n][0] for n in names)
        until = min(bounds[n][1] for n in names)
        if until > since and (len(names), until - since) > (best[0], best[1][1] - best[1][0]):
            best = (len(names), (since, until))
    return best


def _subsets(names: list[str]) -> list[list[str]]:
    return [[n for k, n in enumerate(names) if mask >> k & 1]
            for mask in range(1, 2 ** len(names))]


def _log_phases(log: list[tuple[float, str]], start: float) -> dict[str, float]:
    """Seconds from the evaluation's start to each of its steps' first line."""
    steps = {"ilc_labels": r"iterative learning control on the \d+ training",
             "training": r"training .* preset\)", "export": r"\S+: test MSE ",
             "identification": "identifying the rigid-body",
             "ilc_limit": "iterative learning control on the evaluation",
             "cosimulation": "pid: e2 = ", "held_out": "every feedforward on the"}
    out = {}
    for step, marker in steps.items():
        when = next((w for w, text in log if re.match(marker, text)), None)
        if when is not None:
            out[step] = round(when - start, 1)
    return out


def _e2_ratios(files: dict[str, bytes]) -> dict[str, dict[str, float]]:
    """Each feedforward's e2 ratio per axis (PID's e2 over its own) on the evaluation
    reference, from the report (summary.json) or else the co-simulations' metrics
    (cosim/NAME/metrics.json) in `files`."""
    if "summary.json" in files:
        return {name: {axis: figures["e2_ratio"] for axis, figures in axes.items()}
                for name, axes in json.loads(files["summary.json"])["scenarios"].items()
                if name != "pid"}
    e2 = {path.split("/")[1]: json.loads(data) for path, data in files.items()
          if re.fullmatch(r"cosim/[^/]+/metrics\.json", path)}
    if "pid" not in e2:
        return {}
    axes = [axis for axis in ("x", "y") if axis in e2["pid"]]
    return {name: {axis: e2["pid"][axis]["e2"] / metrics[axis]["e2"] for axis in axes}
            for name, metrics in e2.items() if name != "pid"}


if __name__ == "__main__":
    main()
