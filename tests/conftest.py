"""Shared fixtures: plant models are built once per test session."""

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


@pytest.fixture(scope="session")
def plant_fmus(tmp_path_factory) -> dict:
    """The plant FMU of each variant, built once per test session."""
    from flexff.fmu.build import build_fmu
    from flexff.plant.system import plant_system

    folder = tmp_path_factory.mktemp("plant_fmus")
    return {v: build_fmu(plant_system(v), folder / f"plant_{v}.fmu")
            for v in ("nominal", "hardware")}


@pytest.fixture(scope="session")
def duffing_fmu(tmp_path_factory):
    """The nonlinear continuous toy System of tests/fmu_toys.py as an FMU."""
    from tests.fmu_toys import build_toy, duffing

    return build_toy(duffing(), tmp_path_factory)


@pytest.fixture(scope="session")
def pi_fmu(tmp_path_factory):
    """The discrete PI toy System of tests/fmu_toys.py as an FMU."""
    from tests.fmu_toys import build_toy, discrete_pi

    return build_toy(discrete_pi(), tmp_path_factory)


@pytest.fixture(scope="module")
def few_threads():
    """Small tensors: spare threads only wait for busy cores (see learning.threads). A module
    asks for it with `pytestmark = pytest.mark.usefixtures("few_threads")`."""
    from flexff.learning.threads import torch_threads  # torch only for the modules that use it

    with torch_threads():
        yield
