"""Fixtures of the learning tests."""

import pytest

from flexff.learning.threads import torch_threads


@pytest.fixture(scope="module")
def few_threads():
    """Small tensors: spare threads only wait for busy cores (see learning.threads). A module
    asks for it with `pytestmark = pytest.mark.usefixtures("few_threads")`."""
    with torch_threads():
        yield
