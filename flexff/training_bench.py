"""`flexff bench --training DATA`: how fast the networks train here, on each device.

Each training `flexff evaluate --env ENV` runs by default (learning.evaluate.trained_scenarios,
those on ILC labels too) trains a few epochs of each preset in a process of its own, with the
evaluation's settings, on CUDA (where there is one) and on the CPU with every core; one that
differs from a training timed before only in its data's values takes that one's figures. Per
run: the seconds from the process's start to its first epoch, the median seconds per epoch
after the first, and on CUDA the GPU's busy share and peak memory. On CUDA the thesis preset
runs eagerly, replaying CUDA graphs (learning.training_step), under bf16 autocast (the
mixed-precision candidate), and as several trainings sharing the GPU
(learning.workers.TRAININGS_PER_GPU), eagerly and replaying graphs. The estimate of a whole
evaluation's training multiplies each training's epochs and members by its seconds per epoch,
and divides by the speed-up of the trainings sharing the GPU. A run that fails is a figure
too (its error); when every one fails the bench stops with the first one's error.
"""

from __future__ import annotations

import json
import statistics
import subprocess
import sys
import tempfile
import threading
import time
from collections.abc import Callable
from contextlib import nullcontext
from pathlib import Path
from typing import TYPE_CHECKING, Any

from tqdm import tqdm

from flexff.cosim.executor import granted_cores
from flexff.fmu.errors import InputError, RunError

if TYPE_CHECKING:
    from flexff.learning.evaluate import TrainedScenario

# epochs per run on CUDA (the first is a warm-up, left out) and on the CPU (no warm-up to
# speak of; an epoch of the thesis preset took 12 to 76 s on 2 cores)
EPOCHS = {"cuda": {"fast": 4, "thesis": 3}, "cpu": {"fast": 2, "thesis": 1}}
SHARING_EPOCHS = 4  # epochs of each run when several share the GPU
# the CUDA variants timed with several trainings sharing the GPU: figures key -> settings
SHARED = {"sharing_graphs": {"cuda_graphs": True}, "sharing": {"cuda_graphs": False}}
UTILISATION_S = 0.05  # how often the GPU's busy share is read during a run
# FeatureConfig settings that change the data's values but not how much of it there is, nor
# the network's size: trainings that differ in these alone (a scenario on ILC labels and its
# kind on the collected set) do the same work per epoch
VALUE_SETTINGS = ("encoders", "quantize_encoders", "cutoff_hz", "filter_order",
                  "filter_forces", "position_noise_m", "force_noise_n", "current_noise_a",
                  "filtered_prior")


def training_benchmark(data: Path, presets: tuple[str, ...] = ("fast", "thesis"),
                       models: tuple[str, ...] | None = None, bf16: bool = True,
                       sharing: tuple[int, ...] = (1, 4),
                       save: Callable[[dict[str, Any]], object] | None = None
                       ) -> dict[str, Any]:
    """Time the trainings of `presets` x `models` (default: all) on the dataset folder
    `data` with the settings of the evaluation of its set (sim or hardware), on CUDA and the
    CPU; on CUDA eagerly and, for the thesis preset (the one meant for a GPU), replaying CUDA
    graphs and with bf16 autocast too, and its runs by `sharing` processes side by side, eager
    and replaying graphs; JSON-ready figures, also given to `save` as
    they grow (nothing measured is lost when the bench is stopped)."""
    import torch

    from flexff.learning.dataset import load_dataset
    from flexff.learning.evaluate import ENVIRONMENTS, trained_scenarios
    from flexff.learning.models import NETWORKS

    env = load_dataset(data).set
    if env not in ENVIRONMENTS:
        raise InputError(f"{data}: a {env!r} set; the training bench takes a set of "
                         f"{' or '.join(ENVIRONMENTS)} (flexff data collect --set)")
    environment = ENVIRONMENTS[env]
    cuda = torch.cuda.is_available()
    devices = ["cuda", "cpu"] if cuda else ["cpu"]
    kinds = models or tuple(NETWORKS)
    scenarios = {preset: trained_scenarios(environment, preset, kinds,
                                           ilc_labels=environment.ilc_labelled(kinds))
                 for preset in presets}
    timed_as = {preset: _timed_as(preset, listed) for preset, listed in scenarios.items()}
    runs = [(preset, scenario, device, variant) for preset, listed in scenarios.items()
            for scenario in listed if timed_as[preset][scenario.name] == scenario.name
            for device in devices
            for variant in (("", "graphs", *(("bf16",) if bf16 else ()))
                            if device == "cuda" and preset == "thesis" else ("",))]
    figures: dict[str, Any] = {"data": str(data), "env": env, "cores": granted_cores(),
                               "gpu": torch.cuda.get_device_name() if cuda else None,
                               "torch": torch.__version__, "presets": {
                                   preset: {s.name: _entry(s, preset, timed_as[preset])
                                            for s in listed}
                                   for preset, listed in scenarios.items()}}
    with tempfile.TemporaryDirectory(prefix="flexff-bench-") as scratch:
        for preset, scenario, device, variant in tqdm(runs, desc="training bench",
                                                      unit="run"):
            name = f"{device}_{variant}" if variant else device
            run = _timed_run(scenario.kind, preset, data,
                             Path(scratch) / f"{preset}-{scenario.name}-{name}", device,
                             "bf16" if variant == "bf16" else "float32", EPOCHS[device][preset],
                             {**scenario.overrides,
                              **({"cuda_graphs": variant == "graphs"} if device == "cuda"
                                 else {})})
            for listed, entry in figures["presets"][preset].items():
                if entry.get("timed_as", listed) == scenario.name:
                    entry[name] = run
            if save is not None:
                save(figures)
        failed = [entry[device].get("error") for entries in figures["presets"].values()
                  for entry in entries.values() for device in devices]
        if all(failed):
            raise InputError(f"{data}: no training ran here: {failed[0]}")
        if cuda and len(sharing) > 1 and "thesis" in presets:
            for key, settings in SHARED.items():
                figures[key] = _sharing(data, scenarios["thesis"], sharing,
                                        Path(scratch) / key, settings)
                if save is not None:
                    save(figures)
    for preset, entries in figures["presets"].items():
        for entry in entries.values():
            entry.update(_ratios(entry))
        figures.setdefault("estimate_s", {})[preset] = _estimate(
            entries, {"cuda": figures.get("sharing"), "cuda_graphs": figures.get("sharing_graphs")}
            if preset == "thesis" else {})
    return figures


def _ratios(entry: dict[str, Any]) -> dict[str, float]:
    """A training's ratios of seconds per epoch, where both were measured: the CPU's over
    CUDA's (`speedup`), eager CUDA's over replayed graphs' (`graph_speedup`), and the CPU's
    over the seconds the GPU was busy in an eager epoch (`speedup_bound`): what CUDA would
    gain with no host time at all, its kernels as they are."""
    cpu, cuda, graphs = (entry.get(k, {}) for k in ("cpu", "cuda", "cuda_graphs"))
    ratios = {}
    if "epoch_s" in cuda and "epoch_s" in cpu:
        ratios["speedup"] = cpu["epoch_s"] / cuda["epoch_s"]
        if cuda.get("gpu_busy"):
            ratios["speedup_bound"] = cpu["epoch_s"] / (cuda["epoch_s"] * cuda["gpu_busy"])
    if "epoch_s" in cuda and "epoch_s" in graphs:
        ratios["graph_speedup"] = cuda["epoch_s"] / graphs["epoch_s"]
    return ratios


def _timed_as(preset: str, scenarios: list[TrainedScenario]) -> dict[str, str]:
    """Each scenario's name -> the name of the first scenario whose training does the same
    work per epoch (itself where none before does)."""
    first: dict[str, str] = {}
    return {s.name: first.setdefault(_work(s, preset), s.name) for s in scenarios}


def _work(scenario: TrainedScenario, preset: str) -> str:
    """What sets the work of an epoch of `scenario`'s training: its settings but for the
    data's values (VALUE_SETTINGS), its seed and its epochs."""
    from flexff.learning.manipulator_settings import config_record, manipulator_settings

    settings = config_record(*manipulator_settings(scenario.kind, preset, **scenario.overrides),
                             learned=True)
    settings["features"] = {key: value for key, value in settings["features"].items()
                            if key not in VALUE_SETTINGS}
    return json.dumps({k: v for k, v in settings.items() if k not in ("seed", "epochs")},
                      sort_keys=True)


def _entry(scenario: TrainedScenario, preset: str, timed_as: dict[str, str]) -> dict[str, Any]:
    """A scenario's figures before its runs: its epochs and networks, and the scenario it
    takes its figures from where that is another."""
    from flexff.learning.manipulator_settings import manipulator_settings

    config, _ = manipulator_settings(scenario.kind, preset, **scenario.overrides)
    entry = {"kind": scenario.kind, "epochs": config.epochs,
             "members": scenario.members}
    if timed_as[scenario.name] != scenario.name:
        entry["timed_as"] = timed_as[scenario.name]
    return entry


def _estimate(entries: dict[str, Any], sharing: dict[str, dict[str, Any] | None]
              ) -> dict[str, float]:
    """Seconds of a whole evaluation's training: on the CPU, each run on its own cores; on
    each CUDA variant (eager 'cuda', 'cuda_graphs'), one after another, and shared as that
    variant's figures in `sharing` measured."""
    def total(device: str) -> float:
        return float(sum(e["members"] * (e[device]["start_s"] + e["epochs"] * e[device]["epoch_s"])
                         for e in entries.values()))

    if not all("epoch_s" in e["cpu"] for e in entries.values()):
        return {}
    estimate = {"cpu_one_after_another": total("cpu")}
    for variant in ("cuda", "cuda_graphs"):
        if all("epoch_s" in e.get(variant, {}) for e in entries.values()):
            estimate[f"{variant}_one_after_another"] = total(variant)
            if shared := sharing.get(variant):
                best = max(shared["speedup"].values())
                estimate[f"{variant}_shared"] = total(variant) / best
    return estimate


def _sharing(data: Path, scenarios: list[TrainedScenario], counts: tuple[int, ...], scratch: Path,
             settings: dict[str, Any]) -> dict[str, Any]:
    """The thesis preset's trainings of `scenarios` with `settings`, SHARING_EPOCHS each, by
    each of `counts` processes side by side on the one GPU: the wall time of each count, its
    speedup over the first, and the GPU's busy share meanwhile."""
    from flexff.learning.workers import TrainJob, train_parallel

    walls, busy = {}, {}
    for count in counts:
        jobs = [TrainJob(s.kind, "thesis", data, scratch / f"share{count}" / s.name,
                         {**s.overrides, **settings, "epochs": SHARING_EPOCHS})
                for s in scenarios]
        start = time.perf_counter()
        with _BusyShare() as share:
            train_parallel(jobs, workers=count, progress=False, device="cuda")
        walls[str(count)] = time.perf_counter() - start
        busy[str(count)] = share.mean()
    first = walls[str(counts[0])]
    return {"runs": len(scenarios), "epochs": SHARING_EPOCHS, "wall_s": walls,
            "speedup": {count: first / wall for count, wall in walls.items()},
            "gpu_busy": busy}


class _BusyShare:
    """The GPU's busy share (torch.cuda.utilization, from NVML), read every UTILISATION_S
    by a thread while the block runs: each reading's time and share [0, 1]."""

    def __init__(self) -> None:
        self.readings: list[tuple[float, float]] = []
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._sample, daemon=True)

    def __enter__(self) -> _BusyShare:
        self._thread.start()
        return self

    def __exit__(self, *_: object) -> None:
        self._stop.set()
        self._thread.join()

    def _sample(self) -> None:
        import torch

        while not self._stop.wait(UTILISATION_S):
            try:
                self.readings.append((time.time(), torch.cuda.utilization() / 100))
            except Exception:  # no NVML here (nvidia-ml-py): no busy share
                return

    def mean(self, since: float = 0.0, until: float = float("inf")) -> float | None:
        """The mean share of the readings from `since` to `until` (None where there are
        none)."""
        during = [share for when, share in self.readings if since <= when <= until]
        return statistics.mean(during) if during else None


def _timed_run(kind: str, preset: str, data: Path, out: Path, device: str, precision: str,
               epochs: int, overrides: dict[str, Any]) -> dict[str, Any]:
    """One training in a fresh process; its start-up, seconds per epoch, GPU figures."""
    request = {"kind": kind, "preset": preset, "data": str(data), "out": str(out),
               "device": device, "precision": precision,
               "overrides": {**overrides, "epochs": epochs,
                             **({"threads": granted_cores()} if device == "cpu" else {})}}
    spawned = time.time()
    done = subprocess.run([sys.executable, "-m", "flexff.training_bench", json.dumps(request)],
                          capture_output=True, text=True, check=False)
    if done.returncode:  # kept as a figure: the other runs go on
        return {"error": done.stderr.strip().splitlines()[-1] if done.stderr.strip() else
                f"exit code {done.returncode}"}
    child = json.loads(done.stdout.strip().splitlines()[-1])
    if "error" in child:
        return {"error": child["error"]}
    seconds = child["seconds"]
    timed = seconds[1:] or seconds
    return {"start_s": child["first_epoch_start"] - spawned,
            "epoch_s": statistics.median(timed), "epochs_timed": len(seconds),
            **{k: child[k] for k in ("gpu_busy", "gpu_memory_gb", "val", "device",
                                     "cuda_graphs")}}


def _child(request: dict[str, Any]) -> dict[str, Any]:
    """In the bench's child process: train as asked; the epochs' timing and what it used."""
    import torch

    from flexff.learning.train import train

    ends: list[float] = []
    share = _BusyShare() if request["device"] == "cuda" else None
    autocast = torch.autocast("cuda", dtype=torch.bfloat16) \
        if request["precision"] == "bf16" else nullcontext()
    with autocast, share or nullcontext():
        metrics = train(request["kind"], request["preset"], request["data"], request["out"],
                        progress=False, on_epoch=lambda _: ends.append(time.time()),
                        device=request["device"], **request["overrides"])
    seconds = metrics["history"]["seconds"]
    first_start = ends[0] - seconds[0]
    return {"first_epoch_start": first_start, "seconds": seconds,
            "val": metrics["history"]["val"][-1], "device": metrics["device"],
            "cuda_graphs": metrics["cuda_graphs"],
            "gpu_busy": share.mean(first_start, ends[-1]) if share is not None else None,
            "gpu_memory_gb": torch.cuda.max_memory_allocated() / 1e9 if share is not None
            else None}


if __name__ == "__main__":
    try:
        outcome = _child(json.loads(sys.argv[1]))
    except (InputError, RunError) as error:  # what the run says is wrong, in its words
        outcome = {"error": str(error)}
    print(json.dumps(outcome), flush=True)
