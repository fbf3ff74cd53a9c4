"""Fixtures of the FMU builder's tests: the toy Systems of tests/fmu_toys.py as FMUs."""

import pytest

from tests.fmu_toys import build_toy, discrete_pi, duffing


@pytest.fixture(scope="session")
def duffing_fmu(tmp_path_factory):
    """The nonlinear continuous toy System as an FMU."""
    return build_toy(duffing(), tmp_path_factory)


@pytest.fixture(scope="session")
def pi_fmu(tmp_path_factory):
    """The discrete PI toy System as an FMU."""
    return build_toy(discrete_pi(), tmp_path_factory)
