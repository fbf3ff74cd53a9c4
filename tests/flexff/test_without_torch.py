"""flexff without the extra "learn" (pyproject.toml): co-simulation, FMU building, validation
and SSP export run where PyTorch is not installed, and the learning commands say in one line
what to install. Every process of a command (FMU validation's child too) finds no PyTorch: a
sitecustomize on PYTHONPATH refuses torch and onnxscript as a missing package would."""

import os
import subprocess
import sys

import pytest

from tests.helpers import REPOSITORY

REFUSE = '''import importlib.abc, sys


class Refuse(importlib.abc.MetaPathFinder):
    def find_spec(self, name, path=None, target=None):
        if name.partition(".")[0] in ("torch", "onnxscript"):
            raise ModuleNotFoundError(f"No module named {name!r}", name=name)
        return None


sys.meta_path.insert(0, Refuse())
'''


@pytest.fixture
def python(tmp_path):
    """python(*args) -> the finished `python ARGS` in tmp_path, without PyTorch."""
    (tmp_path / "refuse").mkdir()
    (tmp_path / "refuse" / "sitecustomize.py").write_text(REFUSE)
    path = os.pathsep.join(filter(None, (str(tmp_path / "refuse"), str(REPOSITORY),
                                         os.environ.get("PYTHONPATH"))))
    environment = {**os.environ, "PYTHONPATH": path}

    def run(*args: str) -> subprocess.CompletedProcess[str]:
        return subprocess.run([sys.executable, *args], cwd=tmp_path, env=environment,
                              capture_output=True, text=True)

    return run


def test_pytorch_is_refused_as_a_missing_package(python):
    done = python("-c", "import torch.nn")
    assert done.returncode == 1 and "ModuleNotFoundError: No module named 'torch'" in done.stderr


def test_co_simulation_fmu_building_validation_and_ssp_run_without_pytorch(python, tmp_path):
    for name, example in (("fmus.toml", "third-party-fmus"), ("loop.toml", "spline-rigid-body-ff")):
        config = python("-m", "flexff", "config", "example", example)
        assert config.returncode == 0, config.stderr
        (tmp_path / name).write_text(config.stdout)
    for args in (["run", "fmus.toml", "-o", "out"], ["fmu", "build", "plant", "-o", "plant.fmu"],
                 ["fmu", "validate", "plant.fmu"], ["ssp", "export", "-o", "run.ssp", "loop.toml"]):
        done = python("-m", "flexff", *args)
        assert done.returncode == 0, (args, done.stderr)
    assert (tmp_path / "out" / "signals.parquet").stat().st_size > 0
    assert (tmp_path / "run.ssp").stat().st_size > 0


@pytest.mark.parametrize("args", [["train", "--model", "lstm", "--data", "data", "-o", "runs"],
                                  ["export", "-o", "model.onnx", "runs"],
                                  ["demo", "-o", "demo"]])
def test_a_learning_command_says_in_one_line_what_to_install(python, args):
    done = python("-m", "flexff", *args)
    assert done.returncode == 1
    assert done.stderr == (f"flexff: error: flexff {args[0]} needs PyTorch: "
                           "pip install 'flexff[learn]'\n")
