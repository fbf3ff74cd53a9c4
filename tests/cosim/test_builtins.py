"""The registry of built-in FMUs: a user's own built-in, registered through the public API, is
named, checked and run like the manipulator's (that cosim imports no machine:
tests/flexff/test_import_contract.py)."""

from dataclasses import replace

import numpy as np
import pytest

from flexff.cosim.batch import run_batch
from flexff.cosim.builtins import Option, register_builtin, registered
from flexff.cosim.config import parse_config
from flexff.cosim.config_error import ConfigError
from flexff.cosim.plugins import short_forms
from flexff.cosim.recording import load_recording
from flexff.cosim.references import reference_kinds
from flexff.cosim.run import run_config


def test_the_manipulator_registers_like_any_machine():
    assert {"plant", "controller", "rigid-body-feedforward", "learned-feedforward"} <= set(
        registered())
    assert {"thesis-eval", "thesis-hardware-eval"} <= set(reference_kinds())
    assert [f.tables for f in short_forms() if f.default] == [
        ("plant", "controller", "feedforward")]


def gain_system(options, step):
    """y = k u, a discrete System sampled at `step` (one state, unused)."""
    import casadi as ca

    from flexff.fmu.system import System, Variable

    x, u, p, w = ca.SX.sym("x"), ca.SX.sym("u"), ca.SX.sym("p", 0), ca.SX.sym("w", 0)
    return System(
        name="gain", description="a gain", kind="discrete",
        states=(Variable("held", "1"),), inputs=(Variable("u", "1"),),
        outputs=(Variable("y", "1"),), parameters=(),
        initial_state=ca.Function("initial_state", [p], [ca.SX(1, 1)]),
        dynamics=ca.Function("dynamics", [x, u, p], [x]),
        output=ca.Function("output", [x, u, p, w], [options["k"] * u]),
        sample_time=step)


@pytest.fixture(autouse=True)
def _test_gain_unregistered():
    """The test built-in leaves the registry as it found it: later tests (the docs' reference
    page) compare the registry with what the entry points register."""
    yield
    from flexff.cosim import builtins

    builtins._REGISTRY.pop("test-gain", None)


def register_gain():
    register_builtin("test-gain", (Option("k", "number", 1.0),
                                   Option("mode", "choice", "plain", choices=("plain",))),
                     gain_system, "a gain, for the tests")


GAIN = """
[run]
step = 0.01
stop = 0.1

[[source]]
kind = "constant"
values = {u = 2.0}

[fmu.g]
builtin = "test-gain"
"""


def test_a_user_builtin_is_checked():
    register_gain()
    assert parse_config(GAIN + "k = 3\n").fmus[0].options == {"k": 3.0, "mode": "plain"}
    for extra, key, message in (("kk = 3", "fmu.g.kk", "unknown key"),
                                ('k = "3"', "fmu.g.k", "expected a number"),
                                ('mode = "fancy"', "fmu.g.mode", "unknown mode 'fancy'")):
        with pytest.raises(ConfigError) as info:
            parse_config(f"{GAIN}{extra}\n", origin="gain.toml")
        assert f"gain.toml: {key}: {message}" in str(info.value)


def test_a_user_builtin_runs(tmp_path):
    register_gain()
    run_config(parse_config(GAIN + "k = 1.5\n"), tmp_path)
    record = load_recording(tmp_path)
    np.testing.assert_allclose(record["g.y"], 3.0)


def test_a_user_builtin_runs_in_parallel_workers(tmp_path):
    """Local workers are forks (cosim.executor): a script's own built-in is theirs too."""
    register_gain()
    configs = [replace(parse_config(GAIN + f"k = {k}\n"), name=f"k{k}") for k in (1, 2)]
    results = run_batch(configs, tmp_path, workers=2)
    assert [r.error for r in results] == [None, None]
    for k, result in zip((1, 2), results):
        np.testing.assert_allclose(load_recording(result.output_dir)["g.y"], 2.0 * k)


def test_a_name_is_registered_once():
    register_gain()
    register_gain()  # the same built-in again: nothing changes
    with pytest.raises(ValueError, match="'test-gain' is already registered"):
        register_builtin("test-gain", ("k",), gain_system)
