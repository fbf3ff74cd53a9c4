"""bench_fmu: the Python loop and the C floor run the same steps; the full-length benchmark is
marked slow. (The floor's own checks of its plan and arguments: tests/cosim/test_floor.py.)"""

import time

import pytest

from flexff.fmu_bench import bench_fmu
from tests.fmu_toys import build_toy, discrete_pi, duffing


@pytest.fixture(autouse=True)
def session_cache(tmp_path_factory, monkeypatch):
    """The compiled C floor goes to the session's cache, not the user's."""
    monkeypatch.setenv("FLEXFF_CACHE", str(tmp_path_factory.getbasetemp() / "flexff-cache"))


@pytest.mark.parametrize("make", [duffing, discrete_pi], ids=["duffing", "discrete_pi"])
def test_bench_loops_agree(tmp_path_factory, make):
    fmu = build_toy(make(), tmp_path_factory)
    start = time.perf_counter()
    result = bench_fmu(fmu, steps=200, repeats=2)
    elapsed_us = 1e6 * (time.perf_counter() - start)
    assert result["same_outputs"] and result["isolated_same_outputs"]
    assert result["python_us_per_step"] > 0 and result["c_us_per_step"] > 0
    # a round trip to another process per call cannot be cheaper than the call in-process
    assert result["isolated_us_per_step"] > result["master_us_per_step"] > 0
    # the figures against a clock of the test's own: every loop ran `repeats` times in the
    # call, each at least as long as its best, one after the other
    loops = ("python_us_per_step", "python_bare_us_per_step", "python_us_per_do_step",
             "c_us_per_step")
    assert 2 * 200 * sum(result[name] for name in loops) < elapsed_us
    # Python's call overhead cannot make the same calls faster than C (measured: 10x for duffing,
    # 57x for discrete_pi)
    assert result["ratio"] > 1.0


@pytest.mark.slow
def test_bench_full(tmp_path_factory):
    result = bench_fmu(build_toy(duffing(), tmp_path_factory), steps=20000, repeats=5)
    assert result["same_outputs"]
    assert result["ratio"] > 1.0  # Python's call overhead cannot make it faster than C
