"""Fixtures of the plant's tests."""

import pytest

from flexff.fmu.build import build_fmu
from flexff.plant.system import plant_system


@pytest.fixture(scope="session")
def plant_fmus(tmp_path_factory) -> dict:
    """The plant FMU of each variant, built once per test session."""
    folder = tmp_path_factory.mktemp("plant_fmus")
    return {v: build_fmu(plant_system(v), folder / f"plant_{v}.fmu")
            for v in ("nominal", "hardware")}
