"""Fixtures of the learning tests."""

import pytest

from flexff.learning.synthetic import synthetic_dataset


@pytest.fixture(scope="module")
def few_threads():
    """Small tensors: spare threads only wait for busy cores (see learning.threads). A module
    asks for it with `pytestmark = pytest.mark.usefixtures("few_threads")`."""
    from flexff.learning.threads import torch_threads  # here: without PyTorch, a skip

    with torch_threads():
        yield


@pytest.fixture(scope="module")
def data(tmp_path_factory):
    """A tiny synthetic dataset folder, one per module: the trainings' tests run on it (a
    module may define its own `data` instead)."""
    return synthetic_dataset(tmp_path_factory.mktemp("tiny") / "data", n_train=4, n_test=1,
                             duration=4.0, rate_hz=200.0, seed=7)
