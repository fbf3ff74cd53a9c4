"""Training several models side by side, one process per core (on CUDA, TRAININGS_PER_GPU
per GPU), with a progress bar each.

The models of an evaluation are independent, so they train in parallel processes, one thread
each, the most expensive first. Workers report each epoch through a queue, die with this
process, and leave run folders that resume from their last checkpoint. On a Dask cluster the
runs go through cosim.executor to workers that see the same file system.

Docs: "Learning", section Training side by side (docs/explanation/learning.md), and "Use a
GPU" (docs/how-to/gpu.md).
"""

from __future__ import annotations

import queue
from collections.abc import Mapping, Sequence
from concurrent.futures import FIRST_EXCEPTION, Future, ProcessPoolExecutor, wait
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import torch
from tqdm import tqdm

from flexff.cosim.executor import execute, granted_cores
from flexff.fmu.forkserver import Caller, context
from flexff.learning.devices import pick_device, training_gpus

POLL_S = 0.2  # how often the bars are redrawn while the workers run
# trainings sharing one GPU, each in its own process: one keeps an H200 busy 10 to 30 % of
# the time (learning.devices); the demo's four side by side trained in 71 s on one
TRAININGS_PER_GPU = 4


@dataclass(frozen=True)
class TrainJob:
    """One training run of learning.train.train: model kind, preset, data and run folders,
    setting overrides, its expected cost (any unit; the largest starts first) and the name
    its bar and result go by (default: the model kind)."""

    model: str
    preset: str
    data: Path
    run: Path
    overrides: Mapping[str, Any] = field(default_factory=dict)
    cost: float = 1.0
    label: str = ""

    @property
    def name(self) -> str:
        return self.label or self.model


def train_parallel(jobs: Sequence[TrainJob], workers: int | None = None,
                   progress: bool = True, scheduler: str | None = None,
                   threads: int | None = None, device: str = "auto"
                   ) -> dict[str, dict[str, Any]]:
    """Train every job on `device` ('auto', 'cpu', 'cuda'), `workers` at a time (default: one
    per core granted, on CUDA TRAININGS_PER_GPU per GPU; at most one per job), each on
    `threads` threads (default: cores // workers), or on the Dask cluster at `scheduler`
    (one thread each unless told; its workers resolve 'auto' themselves); return the metrics
    per job name. The first failure is raised once the runs under way have finished (an
    evaluation run again reuses them); the jobs not started are cancelled."""
    if not jobs:
        return {}
    ordered = sorted(jobs, key=lambda job: -job.cost)
    if scheduler is not None:
        return _train_on_cluster(ordered, scheduler, threads or 1, progress, device)
    picked = pick_device(device)
    gpus = training_gpus(picked)
    workers = worker_count(len(jobs), workers, len(gpus))
    threads = threads or max(1, granted_cores() // workers)
    run_on = "cuda" if gpus else str(picked)  # a worker's own GPU is its current one
    fork_server = context("flexff.learning.train")
    with fork_server.Manager() as manager:
        free_gpus = manager.Queue()
        for k in range(workers if gpus else 0):  # the GPUs dealt out in turn
            free_gpus.put(gpus[k % len(gpus)])
        with ProcessPoolExecutor(max_workers=workers, mp_context=fork_server,
                                 initializer=_start_worker,
                                 initargs=(Caller.now(), free_gpus if gpus else None)) as pool:
            epochs = manager.Queue()
            futures = {pool.submit(_train_one, job, threads, run_on, epochs): job
                       for job in ordered}
            return _run(futures, ordered, epochs, progress)


def worker_count(jobs: int, requested: int | None, gpus: int) -> int:
    """Training processes side by side: `requested`, at most one per job; by default one per
    core granted, and on CUDA (`gpus` > 0) TRAININGS_PER_GPU per GPU."""
    default = gpus * TRAININGS_PER_GPU if gpus else granted_cores()
    return max(1, min(requested or default, jobs))


def _start_worker(caller: Caller, free_gpus: Any) -> None:
    """Pool initializer: die with the caller and take its environment and folder; on CUDA take
    a GPU of the queue `free_gpus` (one entry per worker) and make it this process's current
    device."""
    caller.adopt()
    if free_gpus is not None:
        torch.cuda.set_device(free_gpus.get_nowait())


def _run(futures: dict[Future[dict[str, Any]], TrainJob], ordered: Sequence[TrainJob],
         epochs: Any, progress: bool) -> dict[str, dict[str, Any]]:
    """Follow the submitted runs with a bar each; their metrics per job name."""
    bars = {job.name: tqdm(desc=job.name, position=k, unit="epoch", leave=True,
                           disable=not progress, dynamic_ncols=True)
            for k, job in enumerate(ordered)}
    try:
        _follow(futures, epochs, bars)
    finally:
        for bar in bars.values():
            bar.close()
    return {futures[f].name: f.result() for f in futures}


def _train_on_cluster(ordered: Sequence[TrainJob], scheduler: str, threads: int,
                      progress: bool, device: str) -> dict[str, dict[str, Any]]:
    """The jobs on a Dask cluster, one bar counting the runs finished (a worker's epochs do
    not reach this process)."""
    results: dict[str, dict[str, Any]] = {}
    tasks = [(job, threads, device) for job in ordered]
    bar = tqdm(total=len(ordered), desc=f"training on {scheduler}", unit="run",
               disable=not progress, dynamic_ncols=True)
    with execute(_train_alone, tasks, scheduler=scheduler) as running, bar:
        for finished in running:
            if finished.error is not None:
                running.cancel()
                raise finished.error
            if finished.result is None:  # cancelled after a failure
                continue
            job = ordered[finished.index]
            results[job.name] = finished.result
            bar.set_postfix_str(job.name, refresh=False)
            bar.update()
    return {job.name: results[job.name] for job in ordered}


def _follow(futures: dict[Future[dict[str, Any]], TrainJob], epochs: Any,
            bars: dict[str, tqdm[Any]]) -> None:
    """Update the bars from the workers' epoch reports until every job is done; stop at the
    first failure (the jobs not started are cancelled)."""
    pending = set(futures)
    while pending:
        done, pending = wait(pending, timeout=POLL_S, return_when=FIRST_EXCEPTION)
        _drain(epochs, bars)
        failed = [error for f in done if (error := f.exception()) is not None]
        if failed:
            for f in pending:
                f.cancel()
            raise failed[0]
    _drain(epochs, bars)


def _drain(epochs: Any, bars: dict[str, tqdm[Any]]) -> None:
    while True:
        try:
            model, report = epochs.get_nowait()
        except queue.Empty:
            return
        bar = bars[model]
        if bar.total is None:  # its first epoch: the rate counts from now, not from the queue
            bar.reset(total=report["epochs"])
        bar.set_postfix(train=f"{report['train']:.3g}", val=f"{report['val']:.3g}",
                        best=report["best_epoch"], refresh=False)
        bar.update(report["epoch"] - bar.n)


def _train_one(job: TrainJob, threads: int, device: str, epochs: Any) -> dict[str, Any]:
    """Worker: one training run on `device`, each epoch reported on the queue `epochs`."""
    from flexff.learning.train import train

    return train(job.model, job.preset, job.data, job.run, progress=False,
                 on_epoch=lambda report: epochs.put((job.name, report)),
                 **{**job.overrides, "threads": threads, "device": device})


def _train_alone(task: tuple[TrainJob, int, str]) -> dict[str, Any]:
    """Cluster worker: one training run on the given number of threads and device."""
    from flexff.learning.train import train

    job, threads, device = task
    return train(job.model, job.preset, job.data, job.run, progress=False,
                 **{**job.overrides, "threads": threads, "device": device})
