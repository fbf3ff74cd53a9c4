"""Errors that tell the truth: bad input of any floor is an InputError, exit 2 and its message;
a run that failed (RunError) is exit 1 and its message; anything else is a bug, exit 1 with its
type and the hint to rerun with --debug, which prints the traceback."""

import pytest

import flexff.cli
from flexff.cli import main
from flexff.cosim.config_error import ConfigError
from flexff.fmu.errors import InputError, MissingPackage, RunError
from flexff.fmu.importer import FmuError
from flexff.learning.collect import CollectionError
from flexff.learning.dataset import DatasetError
from tests.cosim.test_batch import SHORT  # a 1 s run of the manipulator
from tests.flexff.test_cli_errors import fails

HINT = " (rerun with flexff --debug for the traceback)"


@pytest.fixture
def caught(monkeypatch) -> list[BaseException]:
    """The errors that reached the command line's handler, in order."""
    errors: list[BaseException] = []
    failure = flexff.cli._failure

    def spy(error, *args):
        errors.append(error)
        return failure(error, *args)

    monkeypatch.setattr(flexff.cli, "_failure", spy)
    return errors


def test_the_error_classes():
    assert issubclass(InputError, ValueError)  # pytest.raises(ValueError) still catches them
    assert issubclass(ConfigError, InputError) and issubclass(FmuError, InputError)
    assert issubclass(DatasetError, InputError) and not issubclass(RunError, ValueError)
    assert issubclass(CollectionError, RunError) and issubclass(MissingPackage, ImportError)


@pytest.mark.parametrize("args, files, message", [
    (["run", "{tmp}/bad.toml", "-o", "{tmp}/out"],
     {"bad.toml": SHORT.replace("stop = 1.0", "stop = 1.0\nbogus = 1")}, "run.bogus"),
    (["run", "{tmp}/bad.toml", "-o", "{tmp}/out"],
     {"bad.toml": '[run]\nstop = 1.0\nstep = 0.01\n[fmu.a]\npath = "junk.fmu"\n',
      "junk.fmu": "not a zip archive"}, "junk.fmu: not an FMU"),
    (["fmu", "build", "learned-feedforward", "--model", "{tmp}/junk.onnx", "-o", "{tmp}/ff.fmu"],
     {"junk.onnx": "not a graph"}, "is not a readable ONNX model"),
    (["fmu", "build", "onnx", "{tmp}/junk.onnx", "-o", "{tmp}/n.fmu"],
     {"junk.onnx": "not a graph"}, "is not a readable ONNX model"),
    pytest.param(["train", "--model", "lstm", "--data", "{tmp}/data", "-o", "{tmp}/run"],
                 {"data/readme.txt": "not a dataset"},
                 "is not a flexff dataset: manifest.json is missing", marks=pytest.mark.learn),
    (["run", "{tmp}/short.toml", "-o", "{tmp}/out", "--sweep", "controller.encoders=[2"],
     {"short.toml": SHORT}, "--sweep values must be TOML values"),
    (["run", "{tmp}/short.toml", "-o", "{tmp}/out", "--sweep", "encoders=2,3"],
     {"short.toml": SHORT}, "a sweep key is table.key"),
    (["run", "{tmp}/short.toml", "-o", "{tmp}/out", "--realtime", "--rt-factor", "-1"],
     {"short.toml": SHORT}, "real-time factor must be positive"),
    (["run", "{tmp}/short.toml", "-o", "{tmp}/out", "--workers", "0"],
     {"short.toml": SHORT}, "workers must be at least 1, got 0"),
    pytest.param(["train", "--model", "lstm", "--data", "{tmp}/data", "-o", "{tmp}/run",
                  "--epochs", "0"], {"data/readme.txt": "not a dataset"},
                 "epochs, batch_size and window must be at least 1", marks=pytest.mark.learn),
], ids=["config-key", "fmu-file", "feedforward-model", "onnx-graph", "dataset-folder",
        "sweep-value", "sweep-key", "rt-factor", "workers", "epochs"])
def test_bad_input_of_every_floor(capsys, caught, tmp_path, args, files, message):
    for name, text in files.items():
        (tmp_path / name).parent.mkdir(parents=True, exist_ok=True)
        (tmp_path / name).write_text(text)
    code, line = fails(capsys, args, tmp=tmp_path)
    assert code == 2 and line.startswith("flexff: error: ") and message in line, line
    assert not line.endswith(HINT)
    assert len(caught) == 1 and isinstance(caught[0], InputError), caught


@pytest.mark.parametrize("error, line", [
    (ValueError("boom"), "flexff: error: ValueError: boom" + HINT),
    (ZeroDivisionError("division by zero"),
     "flexff: error: ZeroDivisionError: division by zero" + HINT),
    (RuntimeError("an invariant broke"), "flexff: error: RuntimeError: an invariant broke" + HINT),
    (RunError("training diverged"), "flexff: error: training diverged"),
    (MissingPackage("needs dask.distributed: pip install 'flexff[cluster]'"),
     "flexff: error: needs dask.distributed: pip install 'flexff[cluster]'"),
], ids=["value-error", "zero-division", "runtime-error", "run-error", "missing-package"])
def test_an_internal_error_is_a_bug(capsys, monkeypatch, tmp_path, error, line):
    """A plain ValueError is no longer the user's fault: exit 1, and the hint for a bug."""
    def run_config(*args, **kwargs):
        raise error

    config = tmp_path / "short.toml"
    config.write_text(SHORT)
    monkeypatch.setattr("flexff.cosim.run.run_config", run_config)
    code, err = fails(capsys, ["run", config, "-o", tmp_path / "out"])
    assert (code, err) == (1, line)


def test_debug_prints_the_traceback_of_a_bug(capsys, monkeypatch, tmp_path):
    def run_config(*args, **kwargs):
        raise ValueError("boom")

    config = tmp_path / "short.toml"
    config.write_text(SHORT)
    monkeypatch.setattr("flexff.cosim.run.run_config", run_config)
    monkeypatch.setenv("FLEXFF_DEBUG", "0")  # restored after the test: --debug sets it
    assert main(["--debug", "run", str(config), "-o", str(tmp_path / "out")]) == 1
    err = capsys.readouterr().err
    assert "Traceback (most recent call last)" in err and 'raise ValueError("boom")' in err
    assert err.splitlines()[-1] == "flexff: error: ValueError: boom"
