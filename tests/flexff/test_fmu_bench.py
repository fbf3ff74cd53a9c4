"""bench_fmu: both step loops run the same steps; the full-length benchmark is marked slow."""

import subprocess
import time

import pytest

from flexff.fmu.compile import cached_program
from flexff.fmu_bench import BENCH_SOURCE, bench_fmu
from tests.fmu_toys import build_toy, discrete_pi, duffing


@pytest.fixture(autouse=True)
def session_cache(tmp_path_factory, monkeypatch):
    """The compiled C bench program goes to the session's cache, not the user's."""
    monkeypatch.setenv("FLEXFF_CACHE", str(tmp_path_factory.getbasetemp() / "flexff-cache"))


@pytest.mark.parametrize("make", [duffing, discrete_pi], ids=["duffing", "discrete_pi"])
def test_bench_loops_agree(tmp_path_factory, make):
    fmu = build_toy(make(), tmp_path_factory)
    start = time.perf_counter()
    result = bench_fmu(fmu, steps=200, repeats=2)
    elapsed_us = 1e6 * (time.perf_counter() - start)
    assert result["same_outputs"]
    assert result["python_us_per_step"] > 0 and result["c_us_per_step"] > 0
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


@pytest.mark.parametrize("counts, message", [
    (["2", "7", "1.0", "0"], "fewer arguments than N_IN asks for: 2"),
    (["1", "7", "1.0", "2", "8"], "N_OUT does not match the arguments: 2"),
    (["1", "7", "x", "0"], "bad input value: x"),
    (["1", "-7", "1.0", "0"], "bad value reference: -7"),
], ids=["inputs", "outputs", "value", "value reference"])
def test_bad_bench_arguments_are_refused(counts, message):
    """Every count is checked against the arguments given before anything is read by it."""
    program = cached_program("bench", [BENCH_SOURCE])
    result = subprocess.run([str(program), "/nonexistent.so", "guid", "10", "0.001", "2",
                             *counts], capture_output=True, text=True)
    assert result.returncode == 2 and message in result.stderr, result.stderr


@pytest.mark.parametrize("steps, repeats", [("0", "2"), ("10", "0"), ("ten", "2")])
def test_bad_bench_loop_sizes_are_refused(steps, repeats):
    program = cached_program("bench", [BENCH_SOURCE])
    result = subprocess.run([str(program), "/nonexistent.so", "guid", steps, "0.001", repeats,
                             "0", "0"], capture_output=True, text=True)
    assert result.returncode == 2 and "must be a whole number of at least 1" in result.stderr
