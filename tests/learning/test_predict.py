"""`flexff predict RUN --data LOGS`: each model's effort per sample beside the measured one,
raw and filtered, with the preprocessing that made the labels (each setting of
`[machine.learning]`, derived where not given) and the error's definition."""

import csv
import json

import numpy as np
import pytest

from flexff.cosim.config_error import ConfigError
from flexff.cosim.machine import machine_table, parse_machine
from flexff.fmu.errors import InputError
from flexff.learning.description_data import DescriptionData
from flexff.learning.linear_model import write_linear_model
from flexff.learning.machine_dataset import load_machine_dataset, write_machine_dataset
from flexff.learning.machine_features import ERROR, MachineFeatures, lagged
from flexff.learning.machine_identify import dataset_features, identify_dataset
from flexff.learning.predict import predict_logs, write_predictions
from flexff.learning.presets import make_config
from flexff.learning.signal_processing import lowpass
from flexff.learning.train import fit
from tests.learning.test_description_data import RATE, machine, trajectory


def _dataset(folder, names=("x",), learning=None):
    one = machine(names)
    if learning is not None:
        one = parse_machine({**machine_table(one), "learning": learning}, "m")
    logs = [trajectory(names, k, "train") for k in range(3)] + [trajectory(names, 9, "test")]
    write_machine_dataset(folder, one, {t.name: t.signals for t in logs}, RATE,
                          {t.name: t.split for t in logs}, "logs")
    return load_machine_dataset(folder)


def _identified(tmp_path, data):
    features, _ = dataset_features(data)
    write_linear_model(identify_dataset(data, features), tmp_path / "eval" / "identified.json")
    return tmp_path / "eval"


def test_the_identified_model_predicts_each_sample_beside_the_filtered_label(tmp_path):
    data = _dataset(tmp_path / "data")
    predictions = predict_logs(_identified(tmp_path, data), tmp_path / "data")
    record = predictions.preprocessing
    assert record["error"] == ERROR and record["derived"] == ["cutoff_hz", "lead_s",
                                                               "model_rate_hz"]
    assert record["lead_samples"] == pytest.approx(0.5)  # the zero-order hold's half sample
    assert [t.trajectory for t in predictions.trajectories] == ["train-0", "train-1", "train-2",
                                                                "test-9"]
    test = predictions.trajectories[-1]
    decimation = round(RATE / record["model_rate_hz"])
    effort = data.trajectories[-1].signals["x_effort"]
    # raw: the effort as logged at the model's samples; filtered: half a sample earlier,
    # through the labels' zero-phase low-pass, decimated
    np.testing.assert_array_equal(test.measured[:, 0], effort[::decimation])
    label = lowpass(lagged(effort, RATE, 0.5 / RATE), RATE, record["cutoff_hz"],
                    record["filter_order"])[::decimation]
    np.testing.assert_allclose(test.filtered[:, 0], label, rtol=1e-12, atol=1e-12)
    # the model of the prior is exact on these logs but for the half sample
    assert predictions.relative_error["identified"]["x"] < 0.005
    edge = int(np.argmax(test.scored))
    assert edge > 0 and not test.scored[-1] and test.scored[edge:len(test.scored) - edge].all()


def test_the_description_sets_every_preprocessing_choice(tmp_path):
    data = _dataset(tmp_path / "data", learning={"cutoff_hz": 25.0, "lead_s": 0.0,
                                                 "filter_order": 2, "model_rate_hz": 250.0})
    features, line = dataset_features(data)
    assert (features.cutoff_hz, features.lead_s, features.filter_order,
            features.model_rate_hz) == (25.0, 0.0, 2, 250.0)
    assert "derived" not in line and "25 Hz" in line and "order 2" in line
    predictions = predict_logs(_identified(tmp_path, data), tmp_path / "data", "test")
    assert predictions.preprocessing["derived"] == []
    assert predictions.preprocessing["model_rate_hz"] == 250.0
    # these efforts are sampled with the motion, not held: without the default half-sample
    # lead the model of the prior is exact
    assert predictions.relative_error["identified"]["x"] < 1e-4


@pytest.mark.parametrize("learning, key", [({"cutoff_hz": -1.0}, "cutoff_hz"),
                                           ({"filter_order": 1.5}, "filter_order"),
                                           ({"lead_s": -0.001}, "lead_s"),
                                           ({"corner": 3.0}, "corner")])
def test_a_bad_learning_setting_names_its_key(learning, key):
    with pytest.raises(ConfigError, match=rf"machine\.learning\.{key}"):
        parse_machine({**machine_table(machine(("x",))), "learning": learning}, "m")


def test_a_network_run_predicts_and_writes_csv_json_and_png(tmp_path):
    data = _dataset(tmp_path / "data", ("a", "b"))
    config = make_config("tcn", "fast", epochs=1)
    metrics = fit(config, DescriptionData.of(config, data.description, RATE, data.trajectories,
                                             data.digest, MachineFeatures()),
                  tmp_path / "run", progress=False)
    assert metrics["preprocessing"]["error"] == ERROR  # metrics.json holds the scoring
    assert json.loads((tmp_path / "run" / "metrics.json").read_text())["preprocessing"][
        "cutoff_hz"] == metrics["cutoff_hz"]
    predictions = predict_logs(tmp_path / "run", tmp_path / "data", "test")
    assert list(predictions.relative_error) == ["tcn"]
    written = write_predictions(predictions, tmp_path / "out" / "p.csv")
    assert [p.name for p in written] == ["p.csv", "p.json", "p.png"]
    with (tmp_path / "out" / "p.csv").open() as file:
        rows = list(csv.DictReader(file))
    assert list(rows[0]) == ["trajectory", "split", "time", "scored", "a_effort",
                             "a_effort_filtered", "tcn.a_effort", "b_effort",
                             "b_effort_filtered", "tcn.b_effort"]
    assert len(rows) == len(predictions.trajectories[0].time)
    # the error recomputed from the CSV as its definition says
    scored = [r for r in rows if r["scored"] == "1"]
    f = np.array([float(r["b_effort_filtered"]) for r in scored])
    p = np.array([float(r["tcn.b_effort"]) for r in scored])
    assert np.linalg.norm(f - p) / np.linalg.norm(f) == pytest.approx(
        predictions.relative_error["tcn"]["b"], rel=1e-6)
    saved = json.loads((tmp_path / "out" / "p.json").read_text())
    assert saved["relative_error"] == predictions.relative_error
    assert saved["preprocessing"]["derived"] == ["cutoff_hz", "lead_s", "model_rate_hz"]


def test_the_command_line_predicts_and_refuses_a_folder_without_models(tmp_path, capsys):
    from flexff.cli import main

    data = _dataset(tmp_path / "data")
    run = _identified(tmp_path, data)
    assert main(["predict", str(run), "--data", str(tmp_path / "data"), "-o",
                 str(tmp_path / "p.csv"), "--split", "test"]) == 0
    out = capsys.readouterr().out
    assert "(derived; set [machine.learning] cutoff_hz)" in out and "identified: x " in out
    assert (tmp_path / "p.png").is_file() and (tmp_path / "p.json").is_file()
    (tmp_path / "empty").mkdir()
    assert main(["predict", str(tmp_path / "empty"), "--data", str(tmp_path / "data"), "-o",
                 str(tmp_path / "q.csv")]) == 2
    assert "holds no trained model" in capsys.readouterr().err
    with pytest.raises(InputError, match="split"):
        predict_logs(run, tmp_path / "data", "validation")
