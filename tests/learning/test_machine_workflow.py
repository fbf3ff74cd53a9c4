"""Any machine, end to end in the fast suite: the 1-axis drive example through the command line
and a 3-axis machine (three drives under one PID of three named axes) through the Python API:
collect, identify, train, export, build, evaluate."""

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from flexff.cosim.config import parse_config
from flexff.cosim.machine import parse_machine
from flexff.learning.excitation import excitation_set, write_table
from flexff.learning.machine_evaluate import evaluate_machine

EXAMPLE = Path(__file__).parents[2] / "flexff" / "machines" / "examples" / "drive.toml"
AXES = ("x", "y", "z")


def three_axes(folder: Path):
    """Three drives of other masses under one PID, axes named x, y, z."""
    machine = {"name": "gantry", "axis": [
        {"name": a, "measured": f"d{a}.x", "true": f"d{a}.x_true", "feedforward": f"pid.{a}_ff",
         "effort": f"pid.{a}_effort", "range": [-0.04, 0.04], "velocity": 0.2,
         "acceleration": 2.0} for a in AXES],
        "prior": {"terms": ["inertia", "viscous", "coulomb_asymmetric"]}}
    table = {"run": {"step": 0.001, "stop": 4.0},
             "fmu": {"pid": {"builtin": "pid", "axes": [
                 {"name": a, "mass": 2.0, "crossover_hz": 20.0} for a in AXES]},
                 **{f"d{a}": {"builtin": "drive", "parameters": {"m_motor": 1.6 + k,
                                                                 "cogging": 0.0}}
                    for k, a in enumerate(AXES)}},
             "connection": [c for a in AXES for c in (
                 {"from": f"pid.{a}_effort", "to": f"d{a}.F"},
                 {"from": f"d{a}.x", "to": f"pid.{a}"})],
             "source": [{"kind": "csv", "path": "reference.csv"},
                        {"kind": "constant", "values": {f"{a}_ff": 0.0 for a in AXES}}],
             "machine": machine}
    reference = excitation_set(parse_machine(machine, "m"), 1, 0, 4.0, 1000.0, seed=5)[0]
    write_table(reference, folder / "reference.csv")
    return parse_config(table, name="gantry", base=folder, origin=str(folder / "gantry.toml"))


def test_a_3_axis_machine_runs_the_whole_workflow(tmp_path):
    loop = three_axes(tmp_path)
    summary = evaluate_machine(loop, tmp_path / "out", models=("tcn", "pgnn"), n_train=3,
                               n_test=1, duration=4.0, ilc_iterations=2, progress=False,
                               epochs=1)
    assert summary["axes"] == list(AXES)
    assert set(summary["scenarios"]) == {"pid", "identified", "tcn", "pgnn", "ilc"}
    assert summary["ilc"]["trials"] == 3 and "diverged" not in summary["ilc"]
    identified = summary["identified"]
    for k, axis in enumerate(AXES):
        inertia = identified[axis]["parameters"][0]
        assert inertia == pytest.approx(2.0 + k, rel=0.05)  # each drive's own mass
        assert summary["scenarios"]["identified"][axis]["e2_ratio"] > 5
        assert summary["scenarios"]["ilc"][axis]["e2_ratio"] > 5
    assert (tmp_path / "out" / "table.md").read_text().startswith("| axis | pid |")
    assert (tmp_path / "out" / "errors.png").stat().st_size > 10_000  # a panel per axis


@pytest.mark.parametrize("overrides, message", [
    ({"epochs": 0}, "epochs, batch_size and window must be at least 1"),
    ({"hiden": 8}, "hiden"),
    ({"n_test": 0}, "TEST\\): 0: the evaluation compares the models on the test trajectories"),
])
def test_a_bad_setting_is_refused_before_any_work(tmp_path, overrides, message):
    loop = three_axes(tmp_path)
    with pytest.raises(ValueError, match=message):
        evaluate_machine(loop, tmp_path / "out", progress=False, **overrides)
    assert not (tmp_path / "out").exists()


def test_the_drive_example_through_the_command_line(tmp_path):
    out = tmp_path / "eval"
    done = subprocess.run([sys.executable, "-m", "flexff", "evaluate", "--config",
                           str(EXAMPLE), "-o", str(out), "--models", "tcn",
                           "--trajectories", "2", "1", "--duration", "6", "--epochs", "1"],
                          capture_output=True, text=True, timeout=600)
    assert done.returncode == 0, done.stderr[-2000:]
    assert "| x |" in done.stdout
    summary = json.loads((out / "summary.json").read_text())
    assert summary["scenarios"]["identified"]["x"]["e2_ratio"] > 10
    parameters = summary["identified"]["x"]["parameters"]
    np.testing.assert_allclose(parameters[:2], [2.0, 20.0], rtol=0.1)  # mass, viscous
