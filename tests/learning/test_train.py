"""Training on a tiny synthetic set: it learns, keeps the best epoch, is reproducible, and
bad requests fail with a message that says what to do."""

import copy
import json
from dataclasses import replace

import numpy as np
import pytest
import torch

import flexff.learning.manipulator_data as manipulator_data
import flexff.learning.train as training
from flexff.controllers.features import FORCE_INPUTS, feature_names
from flexff.learning import synthetic
from flexff.learning.batches import PAD, TRAIN, VALIDATION, window_roles
from flexff.learning.dataset import DatasetError, load_dataset
from flexff.learning.deploy import predict
from flexff.learning.features import FeatureConfig, prepare_trajectory
from flexff.learning.identify import identify_samples
from flexff.learning.manipulator_data import prior_labels
from flexff.learning.manipulator_settings import manipulator_settings
from flexff.learning.presets import edge_samples, make_config
from flexff.learning.rigid import rigid_forces
from flexff.learning.run_folder import load_run
from flexff.learning.signal_processing import decimation
from flexff.learning.synthetic import motion_trajectory, skew_sine_circle, synthetic_dataset
from flexff.learning.threads import cpu_threads, torch_threads
from flexff.learning.train import learning_rate, train
from flexff.plant.parameters import HARDWARE, MOTOR_FRICTION

TINY = {"lstm": {"hidden": 16, "layers": 2, "linear_skip": False},
        "pgnn": {"channels": 8, "levels": 3}, "tcn": {"channels": 8}}


def test_tiny_training_reduces_the_loss_and_writes_the_run_folder(data, tmp_path):
    metrics = train("lstm", "fast", data, tmp_path / "run", progress=False, epochs=6,
                    **TINY["lstm"])
    history = metrics["history"]
    assert history["train"][-1] < 0.5 * history["train"][0]
    assert min(history["val"]) < history["val"][0]
    for name in ("run.json", "model.pt", "loss.png", "metrics.json"):
        assert (tmp_path / "run" / name).is_file()
    saved = json.loads((tmp_path / "run" / "metrics.json").read_text())
    for key in ("train_mse", "val_mse", "test_mse", "parameters", "seconds_per_epoch", "epochs",
                "best_epoch"):
        assert key in saved
    assert saved["epochs"] == 6 and saved["model_rate_hz"] == 100.0
    assert saved["parameters"] == 4 * 16 * (63 + 16 + 2) + 4 * 16 * (16 + 16 + 2) + 16 * 2 + 2


def test_the_epoch_with_the_lowest_validation_loss_is_kept(data, tmp_path, monkeypatch):
    scripted, snapshots = [5.0, 3.0, 1.0, 2.0, 4.0], []
    real = training.role_mse

    def scripted_role_mse(network, data_set, role, **kwargs):
        if role == VALIDATION and scripted and not kwargs:
            snapshots.append(copy.deepcopy(network.state_dict()))
            return scripted.pop(0)
        return real(network, data_set, role, **kwargs)

    monkeypatch.setattr(training, "role_mse", scripted_role_mse)
    metrics = train("tcn", "fast", data, tmp_path / "run", progress=False, epochs=5,
                    **TINY["tcn"])
    assert metrics["best_epoch"] == 3 and metrics["history"]["val"] == [5.0, 3.0, 1.0, 2.0, 4.0]
    kept = load_run(tmp_path / "run").network.state_dict()
    for name, value in snapshots[2].items():
        torch.testing.assert_close(kept[name], value.cpu(), rtol=0, atol=0)
    assert not all(torch.equal(kept[n], v.cpu()) for n, v in snapshots[4].items())


def test_training_is_reproducible(data, tmp_path):
    runs = [train("pgnn", "fast", data, tmp_path / f"run{k}", progress=False, epochs=2,
                  **TINY["pgnn"]) for k in range(2)]
    assert runs[0]["history"]["train"] == runs[1]["history"]["train"]
    a, b = (load_run(tmp_path / f"run{k}").network.state_dict() for k in range(2))
    assert all(torch.equal(a[n], b[n]) for n in a)


def test_an_ensembles_members_share_one_identification_of_the_prior(data, tmp_path):
    """Seeds differ, the prior does not: a process identifies it once per data set and
    preprocessing, and a run of other preprocessing identifies its own."""
    manipulator_data._identified_prior.cache_clear()
    runs = [train("pgnn", "fast", data, tmp_path / f"seed{seed}", progress=False, epochs=1,
                  seed=seed, **TINY["pgnn"]) for seed in (0, 1)]
    assert runs[0]["prior_parameters"] == runs[1]["prior_parameters"]
    assert manipulator_data._identified_prior.cache_info()[:2] == (1, 1)  # hits, misses
    train("pgnn", "fast", data, tmp_path / "other", progress=False, epochs=1, cutoff_hz=5.0,
          **TINY["pgnn"])
    assert manipulator_data._identified_prior.cache_info()[:2] == (1, 2)


@pytest.mark.parametrize("kind", ["lstm", "pgnn"])
def test_reported_test_mse_is_that_of_the_si_model(data, tmp_path, kind):
    """The metric's units, end to end: min-max-scaled labels, from the deployed forces (the
    pgnn's with its prior through the labels' filter, as its labels were made), the filter's
    edges left out."""
    metrics = train(kind, "fast", data, tmp_path / "run", progress=False, epochs=2, **TINY[kind])
    run = load_run(tmp_path / "run")
    dataset = load_dataset(data)
    features, forces = prepare_trajectory(dataset.split("test")[0], dataset.sample_rate_hz,
                                          run.config.features)
    predicted = predict(run, features)
    if kind == "pgnn":
        prior = run.prior_parameters
        predicted += (prior_labels(features, prior, run.config.features, run.model_rate_hz)
                      - rigid_forces(features, run.config.features.feature_set, prior))
    edge = run.config.edge_samples(run.config.features.cutoff_hz, run.model_rate_hz)
    assert edge > 0
    scaled = ((predicted - forces) / run.label_scaler.span)[edge:-edge]
    assert np.mean(scaled**2) == pytest.approx(metrics["test_mse"], rel=1e-4)


def test_the_prior_and_force_inputs_are_the_model_identified_on_the_training_set(tmp_path,
                                                                                 monkeypatch):
    """Labels from a plant unlike the nominal one (heavier lower arms and wrist inertia, stiffer
    and softer wrist flexures, twice the hardware variant's friction): the pgnn's prior holds
    exactly the parameters learning.identify finds on the same (noise-free) training samples,
    and explains the test forces far better than the nominal model; a TCN with force inputs
    takes that model's force as its last two inputs, and after one epoch, its linear skip
    about all it has learned, explains the test forces nearly as well."""
    true = HARDWARE.scaled(tau_coulomb=2.0, b_viscous=2.0, m_low=(1.1, 0.9, 1.2), j_ee=3.0,
                           k_w=(1.2, 0.8, 1.1))
    monkeypatch.setattr(synthetic, "HARDWARE", true)
    monkeypatch.setattr(synthetic, "MOTOR_FRICTION", (*MOTOR_FRICTION, "m_low", "j_ee", "k_w"))
    synthetic._label_function.cache_clear()
    try:
        data = synthetic_dataset(tmp_path / "data", n_train=4, n_test=1, duration=4.0,
                                 rate_hz=200.0, seed=7)
    finally:
        synthetic._label_function.cache_clear()  # labels of the patched plant: forget them
    metrics = train("pgnn", "fast", data, tmp_path / "run", progress=False, epochs=1,
                    **TINY["pgnn"])
    run = load_run(tmp_path / "run")
    features = run.config.features
    dataset = load_dataset(data)
    rate = dataset.sample_rate_hz
    model_rate = rate / decimation(rate, features.model_rate_hz)
    pairs = [prepare_trajectory(t, rate, features) for t in dataset.split("train")]
    expected = identify_samples([x for x, _ in pairs], [f for _, f in pairs], features,
                                model_rate,
                                run.config.edge_samples(features.cutoff_hz, model_rate))
    assert run.prior_parameters == pytest.approx(expected.parameters(), rel=1e-9)
    assert metrics["prior_parameters"] == run.prior_parameters
    assert run.prior_parameters["tau_coulomb1"] == pytest.approx(2 * 7e-3, rel=0.2)
    assert metrics["prior_test_mse"] < 0.1 * metrics["rigid_body_test_mse"]
    tcn = train("tcn", "fast", data, tmp_path / "tcn", progress=False, epochs=1,
                force_input=True, **TINY["tcn"])
    forced = load_run(tmp_path / "tcn")
    assert forced.force_input == run.prior_parameters
    assert forced.feature_names == feature_names(features.feature_set, force_input=True)
    assert forced.feature_names[-2:] == list(FORCE_INPUTS)
    # measured: 1.9e-5, the prior 7.5e-6, the nominal model 8.4e-4
    assert tcn["test_mse"] < min(0.05 * tcn["rigid_body_test_mse"], 5 * metrics["prior_test_mse"])


def test_the_residual_labels_filter_the_prior_as_the_labels_are_filtered():
    """A slow circle (motor reversals every few seconds) whose force is exactly the prior's,
    friction included: the labels hold its friction steps low-passed, so the prior through
    the same filter leaves no residual, the prior as it is a wiggle at every reversal (what
    the pgnn learned and deployed on the hardware stand-in,
    learning.manipulator_data.prior_labels)."""
    rate = 100.0
    t = np.arange(2000) / rate
    motion = skew_sine_circle(t, duration=20.0, radius=0.03, turns=3.0, start_angle=0.0)
    trajectory = motion_trajectory("circle", "train", 0, t, motion, {}, force_noise=0.0)
    config = FeatureConfig(feature_set="compact", quantize_encoders=False, position_noise_m=0.0,
                           force_noise_n=0.0)
    features, forces = prepare_trajectory(trajectory, rate, config)
    friction = {k: float(v) for k, v in HARDWARE.flat_values(*MOTOR_FRICTION).items()}
    edge = edge_samples(2.0, config.cutoff_hz, rate)

    def residual(filtered: bool) -> float:
        prior = prior_labels(features, friction, replace(config, filtered_prior=filtered), rate)
        return float(np.sqrt(np.mean((forces - prior)[edge:-edge] ** 2)))

    assert residual(filtered=False) > 1e-3  # N: the friction steps, 7 mNm per motor
    assert residual(filtered=True) < 1e-3 * residual(filtered=False)


def test_validation_windows_are_a_seeded_shuffle():
    roles = window_roles([250, 300], 100, 0.25, np.random.default_rng(0))
    assert [len(r) for r in roles] == [250, 300]
    windows = [r[s] for r in roles for s in range(0, len(r), 100)]
    assert windows.count(VALIDATION) == 2 and windows.count(TRAIN) == 4
    again = window_roles([250, 300], 100, 0.25, np.random.default_rng(0))
    assert all(np.array_equal(a, b) for a, b in zip(roles, again))
    with pytest.raises(ValueError, match="too few"):
        window_roles([100], 100, 0.125, np.random.default_rng(0))


def test_the_filter_edges_enter_no_loss():
    """The first and last `edge` samples are PAD; the windows between keep their roles."""
    plain = window_roles([250, 300], 100, 0.25, np.random.default_rng(0))
    edged = window_roles([250, 300], 100, 0.25, np.random.default_rng(0), edge=20)
    for a, b in zip(plain, edged):
        assert np.all(b[:20] == PAD) and np.all(b[-20:] == PAD)
        assert np.array_equal(a[20:-20], b[20:-20])
    assert edge_samples(2.0, 5.0, 100.0) == 40
    assert make_config("tcn", "fast").edge_samples(5.0, 100.0) == 40
    assert make_config("tcn", "thesis").edge_samples(5.0, 100.0) == 0  # the thesis keeps them


def test_learning_rate_schedules():
    one = make_config("tcn", "fast", learning_rate=1.0, schedule="onecycle")
    assert learning_rate(one, 0.0) == pytest.approx(1 / 25)
    assert learning_rate(one, 0.3) == pytest.approx(1.0)
    assert learning_rate(one, 1.0) == pytest.approx(1 / 25 / 1e4)
    cos = make_config("tcn", "fast", learning_rate=1.0, schedule="cosine")
    assert learning_rate(cos, 0.5) == pytest.approx(0.5)
    assert learning_rate(make_config("lstm", "thesis"), 0.7) == 2e-5


def test_a_size_list_may_be_a_tuple():
    assert make_config("cnn-lstm", "fast", conv_kernels=(6, 3, 2)).architecture[
        "conv_kernels"] == (6, 3, 2)


def test_thesis_preset_follows_the_seed():
    lstm, tcn = make_config("lstm", "thesis"), make_config("tcn", "thesis")
    assert (lstm.epochs, lstm.learning_rate, lstm.window, lstm.val_fraction) == (1000, 2e-5, 100,
                                                                                 0.125)
    assert lstm.architecture == {"hidden": 100, "layers": 2, "dropout": 0.05}
    assert (tcn.epochs, tcn.learning_rate, tcn.architecture["channels"]) == (1500, 2e-4, 200)
    features = manipulator_settings("lstm", "thesis")[1]
    assert features.model_rate_hz is None and features.cutoff_hz == 1.8


@pytest.mark.parametrize("args,overrides,message", [
    (("gru", "fast"), {}, "unknown model 'gru'"),
    (("lstm", "slow"), {}, "unknown preset 'slow'"),
    (("lstm", "fast"), {"epoch": 3}, "unknown setting 'epoch'.*'epochs'"),
    (("lstm", "fast"), {"feature_set": "big"}, "unknown feature set 'big'"),
    (("tcn", "fast"), {"schedule": "step"}, "unknown schedule"),
    (("pgnn", "fast"), {"force_input": True}, "force_input is for the black-box networks"),
    (("lstm", "fast"), {"seed": -1}, r"seed must be a whole number from 0 to 2\*\*63 - 1, got -1"),
    (("lstm", "fast"), {"hidden": 0}, r"hidden must be at least 1 \(whole numbers\), got 0"),
    (("cnn-lstm", "fast"), {"conv_kernels": [10, 0, 2]}, "conv_kernels must be at least 1"),
    (("tcn", "fast"), {"channels": 2.5}, "channels must be at least 1"),
    (("tcn", "fast"), {"dropout": 1.0}, "dropout must lie from 0 up to 1, got 1.0"),
])
def test_bad_requests_are_refused(data, tmp_path, args, overrides, message):
    with pytest.raises(ValueError, match=message):
        train(*args, data, tmp_path / "run", progress=False, **overrides)


def test_empty_split_and_bad_data_are_refused(data, tmp_path):
    manifest = json.loads((data / "manifest.json").read_text())
    copy_dir = tmp_path / "data"
    copy_dir.mkdir()
    for entry in manifest["trajectories"]:
        (copy_dir / entry["file"]).write_bytes((data / entry["file"]).read_bytes())
        entry["split"] = "train"
    (copy_dir / "manifest.json").write_text(json.dumps(manifest))
    with pytest.raises(DatasetError, match=r"'test' split is empty.*manifest.json"):
        train("lstm", "fast", copy_dir, tmp_path / "run", progress=False)
    manifest["version"] = 0
    (copy_dir / "manifest.json").write_text(json.dumps(manifest))
    with pytest.raises(DatasetError, match="collect the data again"):
        train("lstm", "fast", copy_dir, tmp_path / "run", progress=False)
    assert not (tmp_path / "run").exists()


def test_run_folder_must_exist(tmp_path):
    with pytest.raises(ValueError, match=r"not a finished training run.*run.json is missing"):
        load_run(tmp_path)


def test_thread_policy_and_restoration():
    before = torch.get_num_threads()
    assert cpu_threads(3) == 3 and cpu_threads(0) >= 1
    with torch_threads(1) as inside:
        assert inside == 1 == torch.get_num_threads()
    assert torch.get_num_threads() == before
