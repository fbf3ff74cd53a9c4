"""Models trained side by side (learning.workers) are the models trained one after the other,
and a failed one is reported, not lost."""

import pytest
import torch

from flexff.learning.synthetic import synthetic_dataset
from flexff.learning.train import train
from flexff.learning.workers import TrainJob, train_parallel

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
    with pytest.raises(ValueError, match="levels >= 1"):
        train_parallel(jobs, workers=2, progress=False)
