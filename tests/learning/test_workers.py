"""Models trained side by side (learning.workers) are the models trained one after the other,
and a failed one is reported, not lost."""

import pytest
import torch

import flexff.learning.workers
from flexff.learning.synthetic import synthetic_dataset
from flexff.learning.train import train
from flexff.learning.workers import TrainJob, train_parallel, worker_count

TINY = {"pgnn": {"channels": 8, "levels": 3, "epochs": 2},
        "tcn": {"channels": 8, "levels": 3, "epochs": 2}}


@pytest.fixture(scope="module")
def data(tmp_path_factory):
    return synthetic_dataset(tmp_path_factory.mktemp("tiny") / "data", n_train=4, n_test=1,
                             duration=6.0, rate_hz=100.0, seed=5)


def test_parallel_training_equals_training_one_after_the_other(data, tmp_path):
    jobs = [TrainJob(kind, "fast", data, tmp_path / "parallel" / kind, sizes, cost=k)
            for k, (kind, sizes) in enumerate(TINY.items())]
    parallel = train_parallel(jobs, workers=2, progress=False)
    assert set(parallel) == set(TINY)
    for kind, sizes in TINY.items():
        alone = train(kind, "fast", data, tmp_path / "alone" / kind, progress=False,
                      threads=parallel[kind]["threads"], **sizes)
        assert parallel[kind]["test_mse"] == alone["test_mse"]
        assert parallel[kind]["history"]["val"] == alone["history"]["val"]
        weights = [torch.load(tmp_path / folder / kind / "model.pt", weights_only=True)
                   for folder in ("parallel", "alone")]
        assert all(torch.equal(weights[0][name], weights[1][name]) for name in weights[0])


def test_a_failed_training_run_is_raised_with_its_message(data, tmp_path):
    jobs = [TrainJob("tcn", "fast", data, tmp_path / "bad", {"levels": 0}),
            TrainJob("pgnn", "fast", data, tmp_path / "good", TINY["pgnn"])]
    with pytest.raises(ValueError, match="levels must be at least 1"):
        train_parallel(jobs, workers=2, progress=False)


def test_training_on_a_dask_cluster_equals_training_here(data, tmp_path):
    """A local cluster of two worker processes stands in for a remote one: the same jobs on
    one thread each give the same weights and losses as the local pool."""
    from dask.distributed import LocalCluster

    def jobs(folder):
        return [TrainJob(kind, "fast", data, tmp_path / folder / kind, sizes, cost=k)
                for k, (kind, sizes) in enumerate(TINY.items())]

    here = train_parallel(jobs("here"), workers=2, progress=False, threads=1)
    with LocalCluster(n_workers=2, threads_per_worker=1, processes=True,
                      dashboard_address=None) as cluster:
        there = train_parallel(jobs("there"), progress=False,
                               scheduler=cluster.scheduler_address)
    assert set(there) == set(TINY)
    for kind in TINY:
        assert there[kind]["threads"] == here[kind]["threads"] == 1
        assert there[kind]["test_mse"] == here[kind]["test_mse"]
        assert there[kind]["history"]["val"] == here[kind]["history"]["val"]
        weights = [torch.load(tmp_path / folder / kind / "model.pt", weights_only=True)
                   for folder in ("here", "there")]
        assert all(torch.equal(weights[0][name], weights[1][name]) for name in weights[0])


def test_on_cuda_the_trainings_share_each_gpu(monkeypatch):
    monkeypatch.setattr(flexff.learning.workers, "granted_cores", lambda: 16)
    monkeypatch.setattr(flexff.learning.workers, "TRAININGS_PER_GPU", 3)
    assert worker_count(jobs=8, requested=None, gpus=0) == 8  # the CPU: one per core
    assert worker_count(jobs=30, requested=None, gpus=0) == 16
    assert worker_count(jobs=8, requested=None, gpus=1) == 3  # one GPU: three processes
    assert worker_count(jobs=8, requested=None, gpus=2) == 6
    assert worker_count(jobs=8, requested=1, gpus=1) == 1  # as asked
    assert worker_count(jobs=2, requested=None, gpus=2) == 2  # at most one per job
