"""Fixtures of the learning tests."""

import pytest


@pytest.fixture(scope="module")
def few_threads():
    """Small tensors: spare threads only wait for busy cores (see learning.threads). A module
    asks for it with `pytestmark = pytest.mark.usefixtures("few_threads")`."""
    from flexff.learning.threads import torch_threads  # here: without PyTorch, a skip

    with torch_threads():
        yield
