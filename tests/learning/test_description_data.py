"""Training on a [machine] description's data: a 1-axis and a 3-axis machine's trajectories to a
run folder."""

import json

import casadi as ca
import numpy as np
import pytest

from flexff.controllers.learned_feedforward import learned_feedforward_system
from flexff.controllers.machine_feedforward import ahead
from flexff.cosim.machine import parse_machine
from flexff.fmu.build import build_fmu
from flexff.fmu.errors import InputError
from flexff.fmu.validation import validate_fmu
from flexff.learning.dataset_files import Trajectory as MachineTrajectory
from flexff.learning.description_data import DescriptionData, resting
from flexff.learning.export import export, run_steps, session
from flexff.learning.feature_spec import feature_function
from flexff.learning.machine_features import MachineFeatures
from flexff.learning.model_card import read_card
from flexff.learning.presets import make_config
from flexff.learning.run_folder import load_run
from flexff.learning.samples import evaluate_samples
from flexff.learning.train import fit
from tests.runners import run_fmu

RATE = 1000.0
MASS, DAMPING, COULOMB = 2.0, 20.0, 1.5


def machine(names):
    return parse_machine({"name": "synthetic", "axis": [
        {"name": n, "measured": f"p.{n}", "feedforward": f"c.{n}_ff", "effort": f"c.{n}_u",
         "range": [-0.1, 0.1], "velocity": 0.5, "acceleration": 5.0} for n in names]}, "m")


def trajectory(names, seed, split, seconds=8.0):
    """Random multi-sines per axis; the effort of a mass with viscous and Coulomb friction."""
    rng = np.random.default_rng(seed)
    t = np.arange(0.0, seconds, 1 / RATE)
    signals = {"time": t}
    for name in names:
        f = rng.uniform(0.2, 1.5, 3)
        a = rng.uniform(0.005, 0.02, 3) * (f[0] / f)
        w = 2 * np.pi * f[:, None]
        x, v = (a[:, None] * np.sin(w * t)).sum(0), (a[:, None] * w * np.cos(w * t)).sum(0)
        acc = -(a[:, None] * w**2 * np.sin(w * t)).sum(0)
        jerk = -(a[:, None] * w**3 * np.cos(w * t)).sum(0)
        signals |= {f"{name}_ref": x, f"v{name}_ref": v, f"a{name}_ref": acc,
                    f"j{name}_ref": jerk, f"{name}_measured": x,
                    f"{name}_effort": MASS * acc + DAMPING * v + COULOMB * np.tanh(v / 1e-3)}
    return MachineTrajectory(f"{split}-{seed}", split, signals)


@pytest.mark.parametrize("names", [("x",), ("q1", "q2", "z")])
def test_a_machine_trains_into_a_run_folder(names, tmp_path):
    data = [trajectory(names, k, "train") for k in range(6)] + [
        trajectory(names, 10 + k, "test") for k in range(2)]
    config = make_config("tcn", "fast", epochs=2)
    metrics = fit(config, DescriptionData.of(config, machine(names), RATE, data, "digest",
                                             MachineFeatures()), tmp_path / "run", progress=False)
    run = load_run(tmp_path / "run")
    info = json.loads((tmp_path / "run" / "run.json").read_text())
    assert info["label_names"] == [f"{n}_effort" for n in names]
    assert [a["name"] for a in info["machine"]["axis"]] == list(names)
    # the settings that apply: no manipulator's encoders, 1.8 Hz corner or training noise
    assert info["config"]["features"] == {"edge_periods": 2.0}
    assert info["machine_features"]["cutoff_hz"] == pytest.approx(metrics["cutoff_hz"])
    first = names[0]
    assert run.feature_names[:4] == [first, f"v{first}", f"a{first}", f"dir_{first}_0.003"]
    assert 5.0 < metrics["cutoff_hz"] < 7.0  # four times the 1.5 Hz band's edge
    assert RATE / metrics["model_rate_hz"] == pytest.approx(round(RATE / metrics["model_rate_hz"]))
    # the linear skip's least squares hold inertia, damping and the friction's direction
    assert metrics["test_mse"] < 1e-3
    assert (tmp_path / "run" / "loss.png").is_file()


def test_the_physics_guided_model_asks_for_its_prior():
    with pytest.raises(InputError, match=r"pgnn.* and only it learns over an identified prior"):
        DescriptionData.of(make_config("pgnn", "fast", epochs=1), machine(("x",)), RATE,
                           [trajectory(("x",), 0, "train")], "d")


def test_a_machine_model_exports_and_runs_as_its_feedforward_fmu(tmp_path):
    """Export the run, build the FMU: at each of the model's calls the FMU gives what
    onnxruntime gives on the features of the reference half a sample ahead (the labels'
    lead), from the state at rest on the first ones, plus the linear skip the card holds."""
    names = ("x",)
    data = [trajectory(names, k, "train") for k in range(4)] + [trajectory(names, 9, "test")]
    config = make_config("lstm", "fast", epochs=1)
    fit(config, DescriptionData.of(config, machine(names), RATE, data, "d"), tmp_path / "run",
        progress=False)
    model = export(tmp_path / "run", tmp_path / "model.onnx")
    card = read_card(model)
    assert (card.labels, card.output_signals, card.output_units) == ("efforts", ["x_ff"], ["N"])
    fmu = build_fmu(learned_feedforward_system(model, 1e-3), tmp_path / "ff.fmu")
    assert validate_fmu(fmu) == []
    reference = trajectory(names, 20, "test", seconds=1.0).signals
    inputs = ["x_ref", "vx_ref", "ax_ref", "jx_ref"]
    result = run_fmu(fmu, 900, 1e-3, {n: reference[n][:900] for n in inputs}, record=["x_ff"])
    period = round(RATE / card.sample_rate_hz)
    calls = np.arange(0, 900, period)
    u = ca.SX.sym("u", 4)
    features_ahead = ca.Function("f", [u], [feature_function(machine(names), load_run(
        tmp_path / "run").feature_inputs)(ahead(u, 0.5 / RATE))])
    features = evaluate_samples(features_ahead, np.column_stack([reference[n] for n in inputs]))
    assert card.linear_inputs is not None  # the fast LSTM's skip, outside the graph
    skip = features[calls] @ np.asarray(card.linear_inputs["weights"]).T \
        + np.asarray(card.linear_inputs["bias"])
    expected = run_steps(session(model), features[calls], primed=True)[:, 0] + skip[:, 0]
    np.testing.assert_allclose(result["x_ff"][calls], expected,
                               rtol=1e-5, atol=1e-5 * np.abs(expected).max())
    # at rest on the first reference since ever: a constant output, no start-up transient
    rest = run_fmu(fmu, 200, 1e-3, {n: np.full(200, reference[n][0]) for n in inputs},
                   record=["x_ff"])["x_ff"]
    np.testing.assert_allclose(rest, rest[0], rtol=1e-6, atol=1e-9)
    task = build_fmu(learned_feedforward_system(model, 1e-3, task=True),
                     tmp_path / "task.fmu")  # primed too: its first result, a period late
    late = run_fmu(task, 200, 1e-3, {n: np.full(200, reference[n][0]) for n in inputs},
                   record=["x_ff"])["x_ff"]
    np.testing.assert_allclose(late[2 * period:], rest[0], rtol=1e-6, atol=1e-9)
    assert not np.allclose(run_steps(session(model), np.repeat(features[:1], 40, axis=0)),
                           rest[0] - skip[0, 0], rtol=1e-4)  # from zero it would not be


def test_the_rest_is_no_label_where_every_reference_rests():
    """The physics-guided model's residual learns no label where every axis's reference
    rests (the loop settling its last move there), but where one still moves, and on logs
    without references."""
    two = machine(("x", "y"))
    still = trajectory(("x", "y"), 0, "train", seconds=3.0)
    signals = dict(still.signals)
    signals["vx_ref"] = np.where(np.arange(3000) < 2000, 0.0, signals["vx_ref"])
    signals["vy_ref"] = np.where(np.arange(3000) < 1000, 0.0, signals["vy_ref"])
    features = MachineFeatures(cutoff_hz=5.0).resolved(RATE, [], two)
    step = features.decimation(RATE)
    rests = resting(MachineTrajectory("t", "train", signals), RATE, two, features)
    assert rests.shape == (len(range(0, 3000, step)),)
    np.testing.assert_array_equal(rests, np.arange(0, 3000, step) < 1000)
    logs = {k: v for k, v in signals.items() if not k.startswith("v")}
    assert not resting(MachineTrajectory("t", "train", logs), RATE, two, features).any()
