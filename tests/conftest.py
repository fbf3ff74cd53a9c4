"""Fixtures of every package's tests: plant models are built once per test session. Each
package's own fixtures are in its folder's conftest.py."""

import numpy as np
import pytest

from flexff.plant.model import PlantModel


@pytest.fixture(scope="session")
def nominal() -> PlantModel:
    return PlantModel("nominal")


@pytest.fixture(scope="session")
def hardware() -> PlantModel:
    return PlantModel("hardware")


@pytest.fixture
def rng() -> np.random.Generator:
    return np.random.default_rng(20261121)
