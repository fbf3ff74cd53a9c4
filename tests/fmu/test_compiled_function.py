"""CasADi Functions compiled into the build cache: the same results bit for bit, compiled once
per machine, and interpreted (with a warning) where no compiler runs."""

import subprocess

import casadi as ca
import numpy as np
import pytest

from flexff.controllers.ilc_model import model_inverse_dynamics
from flexff.fmu import compiled_function
from flexff.fmu.compiled_function import compiled
from flexff.learning import samples
from flexff.learning.samples import COMPILED_FROM, evaluate_samples
from flexff.plant.parameters import HARDWARE


@pytest.fixture(scope="module")
def inverse_dynamics():
    """The hardware plant's inverse dynamics with motor friction: the learning filter's model."""
    return model_inverse_dynamics(HARDWARE)


def motion(n: int, seed: int = 0) -> list[np.ndarray]:
    rng = np.random.default_rng(seed)
    return [scale * rng.standard_normal((n, 2)) for scale in (0.01, 0.02, 0.5)]


def test_a_compiled_function_gives_the_interpreted_results_bit_for_bit(inverse_dynamics):
    function = compiled(inverse_dynamics)
    assert function.class_name() == "External" and function.name() == inverse_dynamics.name()
    for sample in zip(*motion(50)):
        assert np.array_equal(np.asarray(function(*sample)),
                              np.asarray(inverse_dynamics(*sample)))


def test_a_function_runs_compiled_once_it_has_seen_enough_samples(monkeypatch):
    function = model_inverse_dynamics(HARDWARE)  # a new Function: no samples counted yet
    made = []
    monkeypatch.setattr(samples, "compiled", lambda f: made.append(f.name()) or compiled(f))
    columns = motion(COMPILED_FROM, seed=1)
    interpreted = np.asarray(function.map(COMPILED_FROM)(*(c.T for c in columns))).T
    first = evaluate_samples(function, *(c[:100] for c in columns))
    assert made == [] and np.array_equal(first, interpreted[:100])
    assert np.array_equal(evaluate_samples(function, *columns), interpreted)
    assert made == [function.name()]


def test_a_function_is_compiled_once(inverse_dynamics, monkeypatch):
    compiled(inverse_dynamics)
    monkeypatch.setattr(compiled_function, "_compile", lambda *_: pytest.fail("compiled again"))
    assert compiled(inverse_dynamics).class_name() == "External"


def test_without_a_compiler_it_runs_interpreted_and_says_so(monkeypatch, tmp_path):
    monkeypatch.setenv("FLEXFF_CACHE", str(tmp_path))  # nothing compiled there yet
    monkeypatch.setenv("CC", str(tmp_path / "no-such-cc"))
    compiled_function._warn_interpreted.cache_clear()
    x = ca.SX.sym("x")
    square = ca.Function("square", [x], [x * x])
    with pytest.warns(RuntimeWarning, match="CasADi function square runs interpreted.*set \\$CC"):
        assert compiled(square) is square


def test_a_failed_compilation_runs_interpreted(monkeypatch, tmp_path):
    def failing(*_):
        raise subprocess.CalledProcessError(1, "gcc", stderr="error: no space left\n")

    monkeypatch.setenv("FLEXFF_CACHE", str(tmp_path))
    monkeypatch.setattr(compiled_function, "_compile", failing)
    compiled_function._warn_interpreted.cache_clear()
    x = ca.SX.sym("x")
    cube = ca.Function("cube", [x], [x * x * x])
    with pytest.warns(RuntimeWarning, match=r"could not be compiled \(error: no space left\)"):
        assert compiled(cube) is cube
