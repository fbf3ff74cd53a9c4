"""Any machine's loop on a table of references, its feedforward from a table, its record read
as a dataset's columns."""

import shutil
from pathlib import Path

import numpy as np
import pytest

from flexff.cosim.config import load_config, parse_config
from flexff.cosim.config_error import ConfigError
from flexff.cosim.run import simulate_config
from flexff.learning.machine_loop import loop_machine, on_references, record_signals

EXAMPLES = Path(__file__).parents[2] / "flexff" / "cosim" / "examples"
LOOP = """
[run]
step = 0.01
stop = 1.0

[fmu.ft]
path = "Feedthrough.fmu"
unconnected = "start"

[[source]]
kind = "constant"
values = { x_ref = 0.0, other = 2.0 }

[[connection]]
from = "x_ref"
to = "ft.Float64_continuous_input"

[[connection]]
from = "other"
to = "ft.Float64_discrete_input"

[machine]
[[machine.axis]]
name = "x"
measured = "2 * ft.Float64_continuous_output"
feedforward = "ft.Float64_discrete_input"
effort = "ft.Float64_discrete_output"
range = [-1.0, 1.0]
velocity = 1.0
acceleration = 10.0
"""


def table(path: Path, time: np.ndarray, columns: dict) -> Path:
    np.savetxt(path, np.column_stack([time, *columns.values()]), delimiter=",",
               header=",".join(["time", *columns]), comments="")
    return path


@pytest.fixture
def loop(tmp_path: Path):
    shutil.copy(EXAMPLES / "reference-fmus" / "fmi2" / "Feedthrough.fmu", tmp_path)
    (tmp_path / "loop.toml").write_text(LOOP)
    return load_config(tmp_path / "loop.toml")


def test_the_loop_runs_on_the_table_and_its_record_is_read_as_a_dataset(loop, tmp_path):
    time = np.arange(0.0, 3.0005, 0.01)
    references = table(tmp_path / "ref.csv", time, {
        "x_ref": np.sin(time), "vx_ref": np.cos(time), "ax_ref": -np.sin(time),
        "jx_ref": -np.cos(time)})
    forces = table(tmp_path / "ff.csv", time, {"x_ff": 3 * time})
    run = on_references(loop, references, 3.0, "sine", forces)
    assert (run.stop, run.name) == (3.0, "sine")
    columns = record_signals(simulate_config(run), loop_machine(run))
    assert set(columns) == {"x_ref", "vx_ref", "ax_ref", "jx_ref", "x_measured", "x_effort"}
    np.testing.assert_allclose(columns["x_ref"], np.sin(time), atol=1e-12)
    np.testing.assert_allclose(columns["x_measured"], 2 * np.sin(time), atol=1e-12)
    np.testing.assert_allclose(columns["x_effort"], 3 * time, atol=1e-12)  # the table, not 2.0
    pid_alone = record_signals(simulate_config(on_references(loop, references, 1.0, "z")),
                               loop_machine(loop))
    assert not pid_alone["x_effort"].any()


def test_a_table_that_mixes_references_with_other_signals_is_refused(loop, tmp_path):
    time = np.arange(0.0, 1.0005, 0.01)
    mixed = table(tmp_path / "mixed.csv", time, {"x_ref": time, "other": time})
    run = on_references(loop, mixed, 1.0, "mixed")  # the loop's own sources are constants
    with pytest.raises(ConfigError, match=r"source\[1\]\.path: .*gives x_ref beside other"):
        on_references(run, mixed, 1.0, "again")


def test_a_loop_without_a_description_is_refused():
    bare = parse_config({"run": {"stop": 1.0}, "fmu": {"ft": {
        "path": str(EXAMPLES / "reference-fmus" / "fmi2" / "Feedthrough.fmu"),
        "unconnected": "start"}}})
    with pytest.raises(ConfigError, match=r"machine: the loop has no machine description"):
        loop_machine(bare)
