"""Shared fixtures: plant models are built once per test session."""

import numpy as np
import pytest

from plant.model import PlantModel


@pytest.fixture(scope="session")
def nominal() -> PlantModel:
    return PlantModel("nominal")


@pytest.fixture(scope="session")
def hardware() -> PlantModel:
    return PlantModel("hardware")


@pytest.fixture
def rng() -> np.random.Generator:
    return np.random.default_rng(20261121)
