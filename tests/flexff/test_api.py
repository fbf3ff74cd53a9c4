"""flexff.api: the README's "Python" snippet run word for word in an empty folder, and each
function against the command line's own results."""

import dataclasses

import numpy as np
import pytest

from flexff import api
from flexff.cli import main
from flexff.cosim.config_error import ConfigError
from tests.helpers import run_readme_snippet


def test_readme_python_snippet_runs_as_written(tmp_path):
    lines = run_readme_snippet(tmp_path, "python-api").splitlines()
    assert lines[0].startswith("x0 at 20.0 s: ") and len(lines) == 3
    assert [line.split(" peak")[0] for line in lines[1:]] == [
        "run-fmu.vdp.parameters.mu=0.5", "run-fmu.vdp.parameters.mu=1.5"]


def test_api_runs_as_the_command_line(tmp_path, capsys):
    assert main(["config", "example", "third-party-fmus"]) == 0
    path = tmp_path / "run.toml"
    path.write_text(capsys.readouterr().out)
    assert main(["run", str(path), "-o", str(tmp_path / "cli")]) == 0
    config = api.load(path)
    metrics = api.run(config, tmp_path / "api", progress=False)
    cli, ours = api.read(tmp_path / "cli"), api.read(tmp_path / "api")
    assert ours.configuration == cli.configuration and ours.metrics == metrics
    memory = api.simulate(config)
    for name, values in cli.recording.signals.items():
        assert np.array_equal(ours.recording[name], values), name
        assert np.array_equal(memory[name], values), name
    assert api.check(config) == config
    with pytest.raises(ConfigError, match=r"run\.stop"):
        api.check(dataclasses.replace(config, stop=0.005))  # not a whole number of steps
