"""Fixtures of every package's tests: plant models are built once per test session. Each
package's own fixtures are in its folder's conftest.py."""

import numpy as np
import pytest

from flexff.fmu.build import build_fmu
from flexff.plant.model import PlantModel
from tests.loops import loop_systems

pytest_plugins = ["tests.without_learn"]  # tests that need PyTorch skip where it is missing


@pytest.fixture(scope="session")
def nominal() -> PlantModel:
    return PlantModel("nominal")


@pytest.fixture(scope="session")
def hardware() -> PlantModel:
    return PlantModel("hardware")


@pytest.fixture
def rng() -> np.random.Generator:
    return np.random.default_rng(20261121)


@pytest.fixture(scope="session")
def loop_fmus(tmp_path_factory):
    """loop_fmus(plant) -> the FMUs of tests.loops.loop_systems(plant), built once per session."""
    built: dict[str, dict] = {}

    def fmus(plant: str = "nominal") -> dict:
        if plant not in built:
            folder = tmp_path_factory.mktemp(f"loop_{plant}")
            built[plant] = {name: build_fmu(system, folder / f"{name}.fmu")
                            for name, system in loop_systems(plant).items()}
        return built[plant]

    return fmus
