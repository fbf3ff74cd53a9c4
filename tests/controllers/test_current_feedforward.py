"""Current-level feedforward: the controller's i1_ff..i3_ff inputs added after the control
allocation (zero: today's controller bit for bit), a current-level learned model as an FMU
against onnxruntime, the wiring of the short form and of the evaluation's loop, and the labels
of such a model."""

import dataclasses
import json
import tempfile

import numpy as np
import pytest

from flexff.cli import main
from flexff.controllers.feedback import HOME_ANGLES, INPUTS, controller_system
from flexff.controllers.learned_feedforward import learned_feedforward_system
from flexff.cosim.config import parse_config
from flexff.cosim.run import simulate_config
from flexff.cosim.scenario import resolve
from flexff.fmu.build import build_fmu
from flexff.fmu.errors import InputError
from flexff.learning.dataset import (
    CURRENT_SIGNALS,
    REFERENCE_SIGNALS,
    Trajectory,
    load_dataset,
    write_dataset,
)
from flexff.learning.export import export
from flexff.learning.features import FeatureConfig, prepare_trajectory
from flexff.learning.loop import default_loop, with_feedforward
from flexff.learning.model_card import ModelCard, read_card
from flexff.learning.synthetic import synthetic_dataset
from flexff.learning.threads import torch_threads
from flexff.learning.train import train
from flexff.plant.references import thesis_evaluation
from flexff.plant.signals import CURRENT_FEEDFORWARD, names
from tests.controllers.test_learned_feedforward import STEPS, independent_forces
from tests.helpers import NETWORK_RTOL
from tests.runners import run_fmu

I_FF = names(CURRENT_FEEDFORWARD)
REFERENCE = 'reference = { kind = "thesis-eval" }\nrun = { stop = 0.5 }\n'


@pytest.fixture(scope="module")
def data(tmp_path_factory):
    return synthetic_dataset(tmp_path_factory.mktemp("data") / "sim", n_train=3, n_test=1,
                             duration=3.0, rate_hz=100.0, seed=5)


@pytest.fixture(scope="module")
def models(data, tmp_path_factory):
    """A tiny LSTM and a tiny physics-guided network trained on the currents, exported."""
    folder = tmp_path_factory.mktemp("currents")
    sizes = {"lstm": {"hidden": 12}, "pgnn": {"channels": 8, "levels": 3}}
    with torch_threads():
        for kind, size in sizes.items():
            train(kind, "fast", data, folder / kind, progress=False, epochs=1,
                  val_fraction=0.2, labels="currents", **size)
            export(folder / kind, folder / f"{kind}-currents.onnx")
    return {kind: folder / f"{kind}-currents.onnx" for kind in sizes}


@pytest.fixture(scope="module")
def model(models):
    return models["lstm"]


def sampled(system, inputs):
    """The output and state update of a controller System at random states, for `inputs`."""
    rng = np.random.default_rng(3)
    x = 1e-4 * rng.standard_normal((system.dynamics.size1_in(0), 1))
    p = np.array([[s.start] for s in system.parameters])
    w = np.zeros((0, 1))
    return (np.asarray(system.output(x, inputs, p, w)), np.asarray(system.dynamics(x, inputs, p)))


@pytest.mark.parametrize("variant", ["nominal", "hardware"])
def test_zero_current_feedforward_is_todays_controller(variant):
    today, with_ff = controller_system(variant), controller_system(variant,
                                                                   current_feedforward=True)
    assert today.inputs == INPUTS and [v.name for v in with_ff.inputs[len(INPUTS):]] == list(I_FF)
    rng = np.random.default_rng(0)
    for _ in range(20):
        u = rng.standard_normal((len(INPUTS), 1)) * 0.01
        u[2:5, 0] += HOME_ANGLES  # near the centre
        zero = sampled(with_ff, np.vstack([u, np.zeros((3, 1))]))
        assert np.isfinite(zero[0]).all()
        assert all(np.array_equal(a, b) for a, b in zip(sampled(today, u), zero))
        i_ff = rng.standard_normal((3, 1))
        out, update = sampled(with_ff, np.vstack([u, i_ff]))
        base, base_update = sampled(today, u)
        assert np.allclose(out[:3] - base[:3], i_ff, rtol=0, atol=1e-12)  # after the allocation
        assert np.array_equal(out[3:], base[3:]) and np.array_equal(update, base_update)


def test_a_closed_loop_with_zero_current_feedforward_is_bit_for_bit_todays():
    today = parse_config(REFERENCE, name="today")
    general = with_feedforward(today)
    controller = general.builtin("controller")
    zeros = dataclasses.replace(general, fmus=tuple(
        dataclasses.replace(f, options={**f.options, "current_feedforward": True})
        if f is controller else f for f in general.fmus))
    zeros = with_feedforward(zeros)  # the controller's i1_ff..i3_ff get zero
    assert any(set(I_FF) <= set(s.values) for s in zeros.sources)
    a, b = simulate_config(today), simulate_config(zeros)
    for name in ("i1", "i2", "i3", "x", "y", "Fx_fb", "Fy_fb"):
        assert np.array_equal(a[name], b[name]), name


@pytest.mark.parametrize("kind", ["lstm", "pgnn"])
def test_a_current_level_model_as_an_fmu_equals_onnxruntime(models, kind, tmp_path):
    """The pgnn's prior (the rigid-body force allocated at the reference position, in
    generated C) is added by the independent runner with learning.rigid."""
    model = models[kind]
    card = read_card(model)
    assert card.prior == ("rigid-body" if kind == "pgnn" else "none")
    assert card.labels == "currents" and card.output_signals == list(I_FF)
    assert card.output_units == ["A"] * 3
    fmu = build_fmu(learned_feedforward_system(model, 1e-3), tmp_path / "ff.fmu")
    signals = thesis_evaluation().signals()
    reference = {n: signals[n][5000:5000 + STEPS + 1] for n in REFERENCE_SIGNALS}
    expected = independent_forces(model, reference)[:STEPS]  # the documented scheme, 3 columns
    out = run_fmu(fmu, STEPS, 1e-3, {n: reference[n][:STEPS] for n in REFERENCE_SIGNALS})
    got = np.column_stack([out[n] for n in I_FF])[:STEPS]
    assert expected.shape == got.shape == (STEPS, 3) and np.abs(expected).max() > 0.01
    assert np.abs(got - expected).max() <= NETWORK_RTOL * np.abs(expected).max()


def test_the_short_form_wires_a_current_level_model(model):
    config = parse_config(f'{REFERENCE}[feedforward]\nkind = "learned"\nmodel = "{model}"\n',
                          name="currents")
    controller = config.builtin("controller")
    assert controller.options["current_feedforward"] is True
    assert [s.values for s in config.sources] == [{"Fx_ff": 0.0, "Fy_ff": 0.0}]
    with tempfile.TemporaryDirectory() as folder:
        links = {(k.consumer, k.input): k.from_name for k in resolve(config, folder).links}
    assert all(links["controller", n] == f"feedforward.{n}" for n in I_FF)
    assert links["controller", "Fx_ff"] == "Fx_ff"  # the zero source
    # the evaluation's loop: the same wiring
    loop = with_feedforward(default_loop("nominal"), "learned-feedforward",
                            {"model": model, "mode": "step"})
    assert loop.builtin("controller").options["current_feedforward"] is True
    assert [s.values for s in loop.sources] == [{"Fx_ff": 0.0, "Fy_ff": 0.0}]
    # a force-level feedforward, or none, adds nothing to today's loop
    for plain in (with_feedforward(default_loop("nominal")),
                  with_feedforward(default_loop("nominal"), "rigid-body-feedforward")):
        assert "current_feedforward" not in plain.builtin("controller").options
        assert not any(set(s.values) & set(I_FF) for s in plain.sources)
    # taken out again, the current feedforward inputs of a controller that has them get zero
    assert [s.values for s in with_feedforward(loop).sources] == [
        dict.fromkeys(("Fx_ff", "Fy_ff", *I_FF), 0.0)]
    text = f'{REFERENCE}[fmu.controller]\nbuiltin = "controller"\ncurrent_feedforward = 1\n'
    with pytest.raises(InputError, match=r"fmu\.controller\.current_feedforward: expected true"):
        parse_config(text, name="bad")


def test_current_labels_are_the_currents(data):
    trajectory = load_dataset(data).trajectories[0]
    config = FeatureConfig(labels="currents", filter_forces=False)
    _, labels = prepare_trajectory(trajectory, 100.0, config)
    assert np.array_equal(labels, np.column_stack([trajectory.signals[n]
                                                   for n in CURRENT_SIGNALS]))


def test_what_has_no_current_level_is_refused(data, tmp_path):
    with pytest.raises(InputError, match="unknown labels 'torques'"):
        FeatureConfig(labels="torques")
    odd = ModelCard("full", "features", [], 100.0, output_signals=["i1_ff"])
    with pytest.raises(InputError, match=r"output signals .* are neither the forces"):
        ModelCard.from_metadata(odd.metadata(), "m.onnx")
    folder = tmp_path / "no-currents"
    folder.mkdir()
    ds = load_dataset(data)
    plain = [Trajectory(t.name, t.split, {k: v for k, v in t.signals.items()
                                           if k not in CURRENT_SIGNALS}) for t in ds.trajectories]
    write_dataset(folder, "sim", 100.0, {}, plain)
    with pytest.raises(InputError, match="has no i1: current-level labels need"):
        train("tcn", "fast", folder, tmp_path / "run", progress=False, epochs=1,
              labels="currents")


def test_flexff_train_labels_currents(tmp_path, capsys):
    data = synthetic_dataset(tmp_path / "data", n_train=4, n_test=1, duration=6.0,
                             rate_hz=100.0, seed=2)
    assert main(["train", "--model", "tcn", "--data", str(data), "-o", str(tmp_path / "run"),
                 "--labels", "currents", "--epochs", "1"]) == 0
    info = json.loads((tmp_path / "run" / "run.json").read_text())
    assert info["label_names"] == list(CURRENT_SIGNALS)
    assert info["config"]["features"]["labels"] == "currents"
    assert np.isfinite(json.loads(capsys.readouterr().out)["rigid_body_test_mse"])
