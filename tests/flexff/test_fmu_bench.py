"""bench_fmu: both step loops run the same steps; the full-length benchmark is marked slow."""

import pytest

from flexff.fmu_bench import bench_fmu
from tests.fmu_toys import build_toy, discrete_pi, duffing


@pytest.fixture(autouse=True)
def session_cache(tmp_path_factory, monkeypatch):
    """The compiled C bench program goes to the session's cache, not the user's."""
    monkeypatch.setenv("FLEXFF_CACHE", str(tmp_path_factory.getbasetemp() / "flexff-cache"))


@pytest.mark.parametrize("make", [duffing, discrete_pi], ids=["duffing", "discrete_pi"])
def test_bench_loops_agree(tmp_path_factory, make):
    result = bench_fmu(build_toy(make(), tmp_path_factory), steps=200, repeats=2)
    assert result["same_outputs"]
    assert result["python_us_per_step"] > 0 and result["c_us_per_step"] > 0
    assert result["ratio"] == pytest.approx(result["python_us_per_step"] / result["c_us_per_step"])


@pytest.mark.slow
def test_bench_full(tmp_path_factory):
    result = bench_fmu(build_toy(duffing(), tmp_path_factory), steps=20000, repeats=5)
    print(result)
    assert result["same_outputs"]
    assert result["ratio"] > 1.0  # Python's call overhead cannot make it faster than C
