"""ONNX export: onnxruntime reproduces PyTorch in both forms, on test trajectories, for every
model kind; the metadata tells a runner what it needs; the graph is in SI units."""

import json
import shutil

import numpy as np
import onnx
import pytest
import torch

from flexff.controllers.features import reference_features
from flexff.learning.dataset import REFERENCE_SIGNALS, load_dataset
from flexff.learning.deploy import TRUST_FADE, SIModel, predict, trust
from flexff.learning.export import TOLERANCE, export, run_sequence, run_steps, session
from flexff.learning.features import prepare_trajectory
from flexff.learning.model_card import ModelCard, read_card
from flexff.learning.rigid import rigid_forces
from flexff.learning.run_folder import load_run
from flexff.learning.synthetic import synthetic_dataset
from flexff.learning.train import train

TINY = {
    "lstm": {"hidden": 12},
    "cnn-lstm": {"hidden": 12, "conv_channels": [8, 6, 4]},
    "tcn": {"channels": 8, "levels": 4},
    "pgnn": {"channels": 8, "levels": 3},
}


pytestmark = pytest.mark.usefixtures("few_threads")


@pytest.fixture(scope="module")
def data(tmp_path_factory):
    return synthetic_dataset(tmp_path_factory.mktemp("export") / "data", n_train=3, n_test=1,
                             duration=3.0, rate_hz=100.0, seed=11)


@pytest.fixture(scope="module")
def runs(data, tmp_path_factory):
    folder = tmp_path_factory.mktemp("runs")
    for kind, sizes in TINY.items():
        train(kind, "fast", data, folder / kind, progress=False, epochs=1, val_fraction=0.2,
              **sizes)
    return folder


def _test_inputs(data, run):
    dataset = load_dataset(data)
    traj = dataset.split("test")[0]
    features, _ = prepare_trajectory(traj, dataset.sample_rate_hz, run.config.features)
    return features, traj


def _relative(a, b):
    return float(np.abs(a - b).max() / np.abs(b).max())


def _graph_forces(run, features):
    """What the graph returns: the model's forces, less the rigid-body prior for the pgnn
    (its graph is the residual; the feedforward FMU adds the prior)."""
    forces = predict(run, features)
    if run.config.model == "pgnn":
        forces = forces - rigid_forces(features, run.config.features.feature_set,
                                       run.prior_parameters)
    return forces


@pytest.mark.parametrize("kind", list(TINY))
def test_onnxruntime_matches_pytorch_in_both_forms(data, runs, tmp_path, kind):
    path = export(runs / kind, tmp_path / f"{kind}.onnx")
    run = load_run(runs / kind)
    features, _ = _test_inputs(data, run)
    expected = _graph_forces(run, features)
    card = read_card(path)
    assert card.prior == ("rigid-body" if kind == "pgnn" else "none")
    assert card.prior_parameters == run.prior_parameters
    assert bool(run.prior_parameters) == (kind == "pgnn")
    if kind in ("tcn", "pgnn"):  # one buffer per level (learning.models.StreamingTCN)
        assert [s["input"] for s in card.state] == [
            f"level{i}_buffer" for i in range(TINY[kind]["levels"])]
    runtime = session(path)
    whole = run_sequence(runtime, features)
    steps = run_steps(runtime, features)
    assert whole.shape == expected.shape == (len(features), 2) and whole.dtype == np.float64
    assert _relative(whole, expected) < TOLERANCE
    assert _relative(steps, expected) < TOLERANCE
    assert _relative(steps, whole) < TOLERANCE


def test_the_physics_guided_residual_fades_out_beyond_its_training_range(data, runs, tmp_path):
    """Inside the training range the pgnn's graph gives its network's residual; where a
    feature lies TRUST_FADE spans beyond, none: the model is its prior alone there."""
    path = export(runs / "pgnn", tmp_path / "pgnn.onnx")
    run = load_run(runs / "pgnn")
    features, _ = _test_inputs(data, run)
    low, span = run.feature_scaler.low, run.feature_scaler.span
    inside = np.clip(features, low, low + span)
    runtime = session(path)
    assert np.abs(run_sequence(runtime, inside)).min() > 0
    beyond = inside.copy()
    beyond[len(beyond) // 2:, 0] = low[0] - TRUST_FADE * span[0]
    residual = run_sequence(runtime, beyond)
    assert np.array_equal(residual[:len(beyond) // 2], run_sequence(runtime, inside)[
        :len(beyond) // 2]) and not residual[len(beyond) // 2:].any()


def test_trust_is_one_inside_the_range_and_falls_with_the_farthest_feature():
    scaled = torch.tensor([[0.0, 1.0], [0.5, 1.0 + TRUST_FADE / 2], [-TRUST_FADE / 4, 1.2],
                           [0.5, -2 * TRUST_FADE]], dtype=torch.float64)
    expected = [1.0, 0.5, 1.0 - 0.2 / TRUST_FADE, 0.0]
    assert trust(scaled)[:, 0].tolist() == pytest.approx(expected, abs=1e-12)


@pytest.mark.parametrize("kind", ["lstm", "pgnn"])
def test_reference_inputs_compute_the_features_in_the_graph(data, runs, tmp_path, kind):
    path = export(runs / kind, tmp_path / f"{kind}_ref.onnx", inputs="reference")
    run = load_run(runs / kind)
    _, traj = _test_inputs(data, run)
    reference = np.column_stack([traj.signals[s] for s in REFERENCE_SIGNALS])
    expected = _graph_forces(run, reference_features(traj.signals,
                                                     run.config.features.feature_set))
    assert _relative(run_sequence(session(path), reference), expected) < TOLERANCE
    assert read_card(path).input_signals == list(REFERENCE_SIGNALS)


def test_metadata_names_everything_a_runner_needs(runs, tmp_path):
    path = export(runs / "cnn-lstm", tmp_path / "model.onnx")
    meta = {p.key: p.value for p in onnx.load(str(path)).metadata_props}  # as any reader sees it
    assert read_card(path) == ModelCard.from_metadata(meta, path)
    run = load_run(runs / "cnn-lstm")
    assert meta["format"] == "flexff-feedforward" and meta["model_kind"] == "cnn-lstm"
    assert json.loads(meta["input_signals"]) == run.feature_names
    assert len(json.loads(meta["input_units"])) == 63
    assert json.loads(meta["feature_range"]) == {"signals": run.feature_names,
                                                 "low": run.feature_scaler.low.tolist(),
                                                 "high": run.feature_scaler.high.tolist()}
    assert json.loads(meta["output_signals"]) == ["Fx_ff", "Fy_ff"]
    assert float(meta["sample_rate_hz"]) == 100.0 and meta["feature_set"] == "full"
    assert meta["flexff_version"] and "extrapolate" in meta["usage"]
    state = json.loads(meta["state"])
    assert [s["input"] for s in state] == ["input_buffer", "h", "c"]
    assert state[0]["shape"] == [1, 63, 13] and state[1]["shape"] == [1, 1, 12]  # 1 layer
    runtime = session(path)
    inputs = {i.name: i.shape for i in runtime.get_inputs()}
    assert inputs["inputs"][1] == 63 and isinstance(inputs["inputs"][0], str)  # dynamic time
    assert {o.name for o in runtime.get_outputs()} == {"forces", "input_buffer_out", "h_out",
                                                       "c_out"}


def test_scaling_lives_inside_the_graph(runs):
    """SI in, newtons out: the SI model equals unscale(network(scale(features)))."""
    run = load_run(runs / "tcn")
    x = np.random.default_rng(0).uniform(run.feature_scaler.low, run.feature_scaler.high, (20, 63))
    scaled = torch.as_tensor(run.feature_scaler.transform(x), dtype=torch.float32)[None]
    with torch.no_grad():
        network_out = run.network(scaled)[0][0].double().numpy()
    np.testing.assert_allclose(predict(run, x), run.label_scaler.inverse(network_out), rtol=1e-6)
    with pytest.raises(ValueError, match="inputs must be one of"):
        SIModel(run, "currents")


def test_export_of_a_missing_run_says_what_to_do(tmp_path):
    with pytest.raises(ValueError, match=r"not a finished training run.*train one"):
        export(tmp_path / "nothing", tmp_path / "x.onnx")


def _truncate(path):
    path.write_bytes(path.read_bytes()[:path.stat().st_size // 2])


def _unlisted_truncated(run):
    """A run written before run.json held the weights' sha256, its model.pt then truncated."""
    info = json.loads((run / "run.json").read_text())
    del info["weights_sha256"]
    (run / "run.json").write_text(json.dumps(info))
    _truncate(run / "model.pt")


def _other_weights(run):
    shutil.copy(run.parent / "tcn" / "model.pt", run / "model.pt")


def _unlisted_other_weights(run):
    _other_weights(run)
    info = json.loads((run / "run.json").read_text())
    del info["weights_sha256"]
    (run / "run.json").write_text(json.dumps(info))


def _no_scalers(run):
    info = json.loads((run / "run.json").read_text())
    del info["scalers"]
    (run / "run.json").write_text(json.dumps(info))


@pytest.mark.parametrize("damage, message", [
    (lambda run: _truncate(run / "model.pt"), "model.pt is not the file run.json was written with"),
    (_unlisted_truncated, "model.pt is damaged or does not hold the weights"),
    (_other_weights, "model.pt is not the file run.json was written with"),
    (_unlisted_other_weights, "model.pt is damaged or does not hold the weights"),
    (lambda run: (run / "run.json").write_bytes(b"\x00\xff garbage"),
     "run.json is not valid JSON"),
    (lambda run: (run / "run.json").write_text("[1, 2]"), "run.json: format and version None"),
    (_no_scalers, "run.json is damaged \\(KeyError: 'scalers'\\)"),
    (lambda run: (run / "model.pt").unlink(), "not a finished training run \\(model.pt is missing"),
    (lambda run: (run / "run.json").unlink(), "not a finished training run \\(run.json is missing"),
], ids=["truncated", "truncated-unlisted", "swapped", "swapped-unlisted", "garbage-json",
        "not-a-run", "no-scalers", "no-weights", "no-run-json"])
def test_export_of_a_damaged_run_names_the_file(runs, tmp_path, damage, message):
    """One line naming the file and what to do, from `flexff export` too (no torch traceback)."""
    run = tmp_path / "runs" / "lstm"
    shutil.copytree(runs / "lstm", run)
    shutil.copytree(runs / "tcn", tmp_path / "runs" / "tcn")
    damage(run)
    with pytest.raises(ValueError, match=message) as info:
        export(run, tmp_path / "x.onnx")
    assert "\n" not in str(info.value) and str(run) in str(info.value)
    assert "flexff train" in str(info.value)
    assert not (tmp_path / "x.onnx").exists()


def test_flexff_export_of_a_damaged_run_prints_one_line(runs, tmp_path, capsys):
    from flexff.cli import main

    run = tmp_path / "lstm"
    shutil.copytree(runs / "lstm", run)
    _truncate(run / "model.pt")
    assert main(["export", str(run), "-o", str(tmp_path / "x.onnx")]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and f"{run / 'model.pt'} is not the file" in err


@pytest.mark.parametrize("failure", ["accuracy", "onnx checker"])
def test_a_failed_export_leaves_the_file_as_it_was(runs, tmp_path, monkeypatch, failure):
    """The graph goes to a temporary file that is renamed once every check passed: a failed
    check leaves no file, and keeps an existing one as it was."""
    out = tmp_path / "pgnn.onnx"
    good = export(runs / "pgnn", out).read_bytes()
    if failure == "accuracy":
        monkeypatch.setattr("flexff.learning.export.TOLERANCE", -1.0)
        expected, match = RuntimeError, f"^{out}: onnxruntime deviates from PyTorch"
    else:
        def broken(graph):
            raise onnx.checker.ValidationError("bad graph")

        monkeypatch.setattr("onnx.checker.check_model", broken)
        expected, match = onnx.checker.ValidationError, "bad graph"
    for target in (out, tmp_path / "new.onnx"):
        with pytest.raises(expected, match=match.replace(str(out), str(target))):
            export(runs / "pgnn", target)
    assert out.read_bytes() == good and sorted(p.name for p in tmp_path.iterdir()) == [
        "pgnn.onnx"]


def test_an_ensemble_graph_gives_its_members_mean_force(data, runs, tmp_path):
    second = tmp_path / "pgnn-seed1"
    train("pgnn", "fast", data, second, progress=False, epochs=1, val_fraction=0.2, seed=1,
          **TINY["pgnn"])
    members = [load_run(runs / "pgnn"), load_run(second)]
    features, _ = _test_inputs(data, members[0])
    alone = [_graph_forces(run, features) for run in members]
    assert _relative(alone[0], alone[1]) > 1e-3  # the seeds do make other networks
    path = export([runs / "pgnn", second], tmp_path / "ensemble.onnx")
    runtime = session(path)
    mean = (alone[0] + alone[1]) / 2
    assert _relative(run_sequence(runtime, features), mean) < TOLERANCE
    assert _relative(run_steps(runtime, features), mean) < TOLERANCE
    card = read_card(path)
    assert card.ensemble_members == 2
    assert [s["input"] for s in card.state] == [
        f"member{m}_level{i}_buffer" for m in range(2) for i in range(TINY["pgnn"]["levels"])]
    with pytest.raises(ValueError, match="share model kind"):
        export([runs / "pgnn", runs / "tcn"], tmp_path / "mixed.onnx")
    assert not (tmp_path / "mixed.onnx").exists()
