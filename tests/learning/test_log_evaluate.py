"""`flexff evaluate --data LOGS` on a machine's logs alone: the identified model and each
network compared by their force prediction on the test logs."""

import json

import pytest

from flexff.learning.log_evaluate import evaluate_logs
from flexff.learning.machine_dataset import write_machine_dataset
from tests.learning.test_description_data import machine, trajectory


def test_each_model_predicts_the_test_logs(tmp_path, capsys):
    one = machine(("x",))
    logs = [trajectory(("x",), k, "train") for k in range(4)] + [trajectory(("x",), 9, "test")]
    write_machine_dataset(tmp_path / "data", one, {t.name: t.signals for t in logs}, 1000.0,
                          {t.name: t.split for t in logs}, "logs")
    summary = evaluate_logs(tmp_path / "data", tmp_path / "eval", ("tcn", "pgnn"),
                            progress=False, epochs=1)
    errors = summary["relative_error"]
    assert list(errors) == ["identified", "tcn", "pgnn"] and summary["test"] == ["test-9"]
    # noise-free logs of a mass with viscous and Coulomb friction, its efforts sampled, not
    # held: the linear model is exact but for the half sample it takes them to lead; the
    # physics-guided model adds only its residual, which starts at zero
    assert errors["identified"]["x"] < 0.005
    assert errors["pgnn"]["x"] < 0.05
    assert 0 < errors["tcn"]["x"] < 1.0  # one epoch: a network's error, not the model's
    assert json.loads((tmp_path / "eval" / "summary.json").read_text()) == summary
    # how the errors are scored, and each model's efforts on the test logs per sample
    assert summary["preprocessing"]["derived"] == ["cutoff_hz", "lead_s", "model_rate_hz"]
    assert summary["preprocessing"]["error"].startswith("relative 2-norm per axis")
    assert "model rate" in capsys.readouterr().out  # the derived settings, printed
    assert (tmp_path / "eval" / "predictions.csv").read_text().startswith(
        "trajectory,split,time,scored,x_effort,x_effort_filtered,identified.x_effort,"
        "tcn.x_effort,pgnn.x_effort")
    table = (tmp_path / "eval" / "table.md").read_text()
    assert table.startswith("| axis | identified | tcn | pgnn |")
    assert f"{100 * errors['identified']['x']:.2f} %" in table


def test_a_bad_setting_is_refused_before_the_data_loads(tmp_path):
    with pytest.raises(ValueError, match="epochs, batch_size and window must be at least 1"):
        evaluate_logs(tmp_path / "missing", tmp_path / "eval", epochs=0)


def test_the_command_line_takes_a_logs_dataset(tmp_path, capsys):
    from flexff.cli import main

    one = machine(("q",))
    logs = [trajectory(("q",), k, "train") for k in range(3)] + [trajectory(("q",), 7, "test")]
    write_machine_dataset(tmp_path / "data", one, {t.name: t.signals for t in logs}, 1000.0,
                          {t.name: t.split for t in logs}, "logs")
    assert main(["evaluate", "--data", str(tmp_path / "data"), "-o", str(tmp_path / "eval"),
                 "--models", "lstm", "--epochs", "1"]) == 0
    out = capsys.readouterr().out
    assert "| axis | identified | lstm |" in out and "relative 2-norm" in out
    assert (tmp_path / "eval" / "runs" / "lstm" / "run.json").is_file()
    assert main(["evaluate", "--data", str(tmp_path / "data")]) == 2  # no output folder
