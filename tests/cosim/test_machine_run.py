"""A [machine] in a run: its signals checked against the loop, its axes in metrics.json."""

import json
import shutil
from pathlib import Path

import numpy as np
import pytest

from flexff.cosim.config import checked, expanded, load_config, parse_config
from flexff.cosim.config_error import ConfigError
from flexff.cosim.metrics import error_norms
from flexff.cosim.recording import load_recording
from flexff.cosim.run import run_config

EXAMPLES = Path(__file__).parents[2] / "flexff" / "cosim" / "examples"

CONFIG = """
[run]
step = 0.01
stop = 2.0

[fmu.ft]
path = "Feedthrough.fmu"
unconnected = "start"

[[source]]
kind = "csv"
path = "reference.csv"

[[connection]]
from = "x_ref"
to = "ft.Float64_continuous_input"
gain = 0.5

[machine]
name = "feedthrough"
[[machine.axis]]
name = "x"
measured = "ft.Float64_continuous_output"
feedforward = "ft.Float64_discrete_input"
effort = "ft.Float64_discrete_output"
range = [-1.0, 1.0]
velocity = 1.0
acceleration = 10.0
"""


@pytest.fixture
def folder(tmp_path: Path) -> Path:
    shutil.copy(EXAMPLES / "reference-fmus" / "fmi2" / "Feedthrough.fmu", tmp_path)
    time = np.arange(0.0, 2.005, 0.01)
    np.savetxt(tmp_path / "reference.csv", np.column_stack([time, np.sin(time)]),
               delimiter=",", header="time,x_ref", comments="")
    return tmp_path


def test_the_metrics_are_the_machine_axes(folder: Path):
    (folder / "run.toml").write_text(CONFIG)
    config = load_config(folder / "run.toml")
    assert [a.name for a in config.machine.axes] == ["x"]
    assert checked(parse_config(expanded(config))).machine == config.machine
    metrics = run_config(config, folder / "out")
    record = load_recording(folder / "out")
    error = record["x_ref"] - record["ft.Float64_continuous_output"]
    assert metrics["x"] == pytest.approx(error_norms(error, 0.01), rel=1e-12)
    assert json.loads((folder / "out" / "metrics.json").read_text())["x"]["e2"] > 0


def test_a_description_naming_a_signal_the_loop_lacks_is_refused(folder: Path):
    (folder / "run.toml").write_text(CONFIG.replace('effort = "ft.Float64_discrete_output"',
                                                    'effort = "ft.Float64_output"'))
    with pytest.raises(ConfigError, match=r"run\.toml: machine\.axis\[0\]\.effort: "
                                          r"'ft\.Float64_output' is not an output"):
        run_config(folder / "run.toml", folder / "out")
