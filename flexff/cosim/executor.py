"""Jobs in parallel, in local processes or on a Dask cluster: the one executor of runs
(cosim.batch), data collection (learning.collect) and a machine's trainings.

`execute(function, jobs, workers, scheduler, fresh)` is a context manager that yields each
job's Finished (its index, result or error, or cancelled) as the jobs end, in the order they
end; `cancel()` drops the jobs not started yet. Local workers are forks of the caller (they
have what it loaded and registered, a script's own built-ins too), or with `fresh` children of
the fork server (fmu.forkserver), for CUDA, which a fork of a process that has looked for a
GPU cannot use safely. They die with the caller (even when it is killed) and take Ctrl-C as the
user means it: the run in progress stops, an idle worker stays quiet, and no further job
starts. A Dask scheduler that cannot be reached is a ConnectionError naming it, after
SCHEDULER_TIMEOUT.
"""

from __future__ import annotations

import multiprocessing
import os
import signal
from collections.abc import Callable, Iterator, Sequence
from concurrent.futures import Future, ProcessPoolExecutor, as_completed
from contextlib import contextmanager
from dataclasses import dataclass
from typing import Any, Generic, TypeVar

from tqdm import tqdm

from flexff.fmu.errors import InputError, MissingPackage
from flexff.fmu.forkserver import Caller, context

Job = TypeVar("Job")
Result = TypeVar("Result")

SCHEDULER_TIMEOUT = "10s"  # how long to try to reach a Dask scheduler


def granted_cores() -> int:
    """The cores this process may run on (its CPU affinity), at least one."""
    cores = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count()
    return max(1, cores or 1)


def check_workers(workers: int | None) -> None:
    """An InputError for a count of local processes below 1 (None: one per core granted)."""
    if workers is not None and workers < 1:
        raise InputError(f"workers must be at least 1, got {workers} (leave it out for one "
                         f"process per CPU)")


@dataclass(frozen=True)
class Finished(Generic[Result]):
    """How one job ended: its result, the error it raised, or cancelled before it started."""

    index: int  # the job's position in the list given to execute
    result: Result | None = None
    error: BaseException | None = None
    cancelled: bool = False


class Execution(Generic[Result]):
    """The jobs under way: iterate for each Finished as it comes; cancel() the rest."""

    def __init__(self, futures: dict[Any, int], finished: Iterator[Any],
                 cancel: Callable[[], object]) -> None:
        self._futures, self._finished, self._cancel = futures, finished, cancel

    def __iter__(self) -> Iterator[Finished[Result]]:
        for future in self._finished:
            index = self._futures[future]
            if future.cancelled():
                yield Finished(index, cancelled=True)
                continue
            try:
                yield Finished(index, result=future.result())
            except Exception as error:
                yield Finished(index, error=error)

    def cancel(self) -> None:
        """Drop the jobs that have not started."""
        self._cancel()


@contextmanager
def execute(function: Callable[[Job], Result], jobs: Sequence[Job], workers: int | None = None,
            scheduler: str | None = None, fresh: bool = False) -> Iterator[Execution[Result]]:
    """Run `function(job)` for every job: in up to `workers` local processes (default: one
    per core granted; `fresh`: not forks of this one, module doc), or on the Dask scheduler
    at `scheduler` (dask.distributed, imported only then)."""
    check_workers(workers)
    if scheduler is not None:
        with _on_dask(function, jobs, scheduler) as execution:
            yield execution
        return
    if not fresh:
        _stop_bar_monitor()
    pool = ProcessPoolExecutor(max_workers=max(1, min(workers or granted_cores(), len(jobs) or 1)),
                               mp_context=context(function.__module__) if fresh
                               else multiprocessing.get_context("fork"),
                               initializer=_start_worker, initargs=(Caller.now(),))
    try:
        futures: dict[Future[Result], int] = {pool.submit(_guarded, function, job): k
                                              for k, job in enumerate(jobs)}
        yield Execution(futures, as_completed(futures),
                        lambda: [f.cancel() for f in futures])
    finally:  # on Ctrl-C too: the jobs not started are dropped, those in progress stop
        pool.shutdown(cancel_futures=True)


def _stop_bar_monitor() -> None:
    """Stop the thread an open tqdm bar keeps to refresh itself, before the pool forks: a fork
    of a process running a second thread may deadlock in the child (a lock that thread held
    stays held; Python 3.12 warns of it). The bars go on without it; a later bar starts it."""
    monitor = tqdm.monitor
    if monitor is not None:
        monitor.exit()  # type: ignore[no-untyped-call]  # the stubs leave it untyped
        tqdm.monitor = None


@contextmanager
def _on_dask(function: Callable[[Job], Result], jobs: Sequence[Job], scheduler: str
             ) -> Iterator[Execution[Result]]:
    try:
        from dask.distributed import Client
        from dask.distributed import as_completed as dask_completed
    except ImportError:
        raise MissingPackage("running on a Dask cluster needs dask.distributed: "
                             "pip install 'flexff[cluster]'") from None
    try:
        client = Client(scheduler, timeout=SCHEDULER_TIMEOUT)
    except OSError as error:  # refused, timed out, unknown host
        raise ConnectionError(f"cannot reach the Dask scheduler at {scheduler}: {error}") \
            from None
    with client:
        futures = client.map(function, list(jobs), pure=False)
        yield Execution(dict(zip(futures, range(len(futures)))), dask_completed(futures),
                        lambda: client.cancel([f for f in futures if not f.done()]))


_worker = {"running": False, "interrupted": False}  # a pool process's state, for Ctrl-C


def _start_worker(caller: Caller) -> None:
    caller.adopt()
    signal.signal(signal.SIGINT, _on_interrupt)


def _on_interrupt(signum: int, frame: object) -> None:
    """Ctrl-C in a pool process: it starts no further job, and stops the one in progress
    (an idle one stays quiet: a KeyboardInterrupt there would print a traceback)."""
    _worker["interrupted"] = True
    if _worker["running"]:
        raise KeyboardInterrupt


def _guarded(function: Callable[[Job], Result], job: Job) -> Result:
    """`function(job)` in a pool process, unless Ctrl-C was pressed (the pool queues ahead)."""
    if _worker["interrupted"]:
        raise KeyboardInterrupt
    _worker["running"] = True
    try:
        return function(job)
    finally:
        _worker["running"] = False
