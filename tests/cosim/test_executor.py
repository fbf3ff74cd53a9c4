"""cosim.executor, the one executor of runs and data collection: results by job, errors as
values, cancellation of the jobs not started, the same on a local Dask cluster; no thread of
a progress bar running when the workers fork."""

import os
import threading
import time

import pytest
from tqdm import tqdm

from flexff.cosim.executor import execute
from flexff.fmu.errors import InputError


def square_or_fail(k: int) -> int:
    if k == 3:
        raise ValueError("three")
    if k >= 10:
        time.sleep(0.2)
    return k * k


def outcomes(running):
    return {f.index: (f.result, None if f.error is None else str(f.error), f.cancelled)
            for f in running}


def test_local_processes_give_each_job_its_result_or_error():
    with execute(square_or_fail, [0, 1, 2, 3, 4], workers=2) as running:
        got = outcomes(running)
    assert got == {0: (0, None, False), 1: (1, None, False), 2: (4, None, False),
                   3: (None, "three", False), 4: (16, None, False)}


def test_no_worker_is_an_error_not_every_core():
    with pytest.raises(InputError, match="workers must be at least 1, got 0"), \
            execute(square_or_fail, [0, 1], workers=0):
        pass


def test_cancel_drops_the_jobs_not_started():
    jobs = [10] * 12  # 0.2 s each, one worker: most are queued when the first ends
    with execute(square_or_fail, jobs, workers=1) as running:
        seen = []
        for finished in running:
            seen.append(finished)
            if len(seen) == 1:
                running.cancel()
    assert seen[0].result == 100 and len(seen) == len(jobs)
    # the first, the one then running, and the two the pool had handed its worker queue ran
    assert sum(f.cancelled for f in seen) >= len(jobs) - 4


def test_workers_fork_without_the_thread_of_an_open_progress_bar(monkeypatch):
    """tqdm's monitor thread, which a bar starts, is stopped before the pool forks: a fork of a
    process with a second thread may deadlock (Python 3.12+ warns of it)."""
    threads_at_fork = []

    def counting_fork():
        threads_at_fork.append(sorted(t.name for t in threading.enumerate()))
        return real_fork()

    real_fork = os.fork
    before = sorted(t.name for t in threading.enumerate())
    with tqdm(total=5, disable=False, file=open(os.devnull, "w")) as bar:
        assert "tqdm_monitor" in {t.name for t in threading.enumerate()}  # the bar started it
        monkeypatch.setattr(os, "fork", counting_fork)
        with execute(square_or_fail, [0, 1, 2], workers=2) as running:
            for _ in running:
                bar.update()
    assert threads_at_fork == [before, before]  # two workers forked, without the monitor


def test_a_local_dask_cluster_gives_the_same():
    distributed = pytest.importorskip("dask.distributed")
    with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=False,
                                  dashboard_address=None) as cluster, \
            execute(square_or_fail, [0, 1, 2, 3, 4], scheduler=cluster.scheduler_address) \
            as running:
        got = outcomes(running)
    assert got == {0: (0, None, False), 1: (1, None, False), 2: (4, None, False),
                   3: (None, "three", False), 4: (16, None, False)}
