"""The physics-guided model on a synthetic machine whose residual over its prior is known: a
mass with viscous and Coulomb friction (the prior, exact) on a spring, linear and cubic (the
residual, a function of the position alone). Moves between rests: at rest the spring still
pulls, and the model, prior plus residual, must hold it there as while moving."""

import numpy as np
import pytest
import torch

from flexff.controllers.learned_feedforward import learned_feedforward_system
from flexff.cosim.machine import parse_machine
from flexff.fmu.build import build_fmu
from flexff.learning.dataset_files import Trajectory
from flexff.learning.deploy import SIModel
from flexff.learning.description_data import DescriptionData, features_from_dict
from flexff.learning.export import export
from flexff.learning.linear_prior import AxisFit, LinearModel
from flexff.learning.machine_features import MachineFeatures, prepare
from flexff.learning.presets import make_config
from flexff.learning.run_folder import load_run
from flexff.learning.train import fit
from tests.helpers import rest_to_rest_moves
from tests.runners import run_fmu

RATE = 1000.0
MASS, DAMPING, COULOMB, WIDTH = 2.0, 20.0, 1.5, 1e-3
SPRING, CUBIC = 40.0, 2e4  # N/m, N/m^3: 2 N and 2.5 N at the range's ends
MACHINE = parse_machine({"name": "sprung", "axis": [
    {"name": "x", "measured": "p.x", "feedforward": "c.x_ff", "effort": "c.x_u",
     "range": [-0.05, 0.05], "velocity": 0.25, "acceleration": 2.5}]}, "m")


def spring(x):
    return SPRING * x + CUBIC * x**3


def prior() -> LinearModel:
    """The prior's terms (inertia, viscous, Coulomb, offset) at their true values."""
    return LinearModel(MACHINE, {"x": AxisFit(list(MACHINE.prior.terms),
                                              [MASS, DAMPING, COULOMB, 0.0], [0.0] * 4,
                                              WIDTH, 1.0, 0.0, 0.0)})


def moves(seed: int, split: str, seconds: float = 10.0) -> Trajectory:
    """Minimum-jerk moves between random positions, each followed by a rest of 0.2 to 0.6 s;
    the effort of the sprung mass (at rest: the spring's pull)."""
    t, x, v, a = rest_to_rest_moves(seed, seconds, RATE)
    signals = {"time": t, "x_ref": x, "vx_ref": v, "ax_ref": a,
               "jx_ref": np.gradient(a, 1 / RATE), "x_measured": x,
               "x_effort": MASS * a + DAMPING * v + COULOMB * np.tanh(v / WIDTH) + spring(x)}
    return Trajectory(f"{split}-{seed}", split, signals)


@pytest.fixture(scope="module")
def trained(tmp_path_factory):
    """A pgnn (fast preset) trained over the exact prior on six trajectories, its metrics
    and its folder."""
    folder = tmp_path_factory.mktemp("pgnn")
    data = [moves(k, "train") for k in range(6)] + [moves(10 + k, "test") for k in range(2)]
    config = make_config("pgnn", "fast", epochs=40)
    metrics = fit(config, DescriptionData.of(config, MACHINE, RATE, data, "digest",
                                             MachineFeatures(), prior()),
                  folder / "run", progress=False)
    return metrics, folder


def test_the_residual_beats_its_prior_at_rest_too(trained):
    """On the test trajectories the model is closer to the efforts than its prior alone, and
    so it is where the reference rests: there the residual holds the spring's pull (trained
    to zero, it left that to the loop, and each start and stop a step)."""
    metrics, folder = trained
    assert metrics["test_mse"] < 0.3 * metrics["prior_test_mse"]
    run = load_run(folder / "run")
    test = moves(10, "test")
    features, _ = prepare(test.signals, RATE, MACHINE,
                          features_from_dict(run.info["machine_features"]))
    model = SIModel(run, prior=False)  # the residual alone, as exported
    with torch.no_grad():
        residual = model(torch.as_tensor(features.copy()), *model.initial_state())[0].numpy()[:, 0]
    step = round(RATE / run.model_rate_hz)
    x, v = test.signals["x_ref"][::step], test.signals["vx_ref"][::step]
    edge = len(x) // 10
    rest = (v == 0.0) & (np.abs(spring(x)) > 1.0)
    rest[:edge] = rest[-edge:] = False
    assert rest.sum() > 50
    missed = np.abs(residual[rest] - spring(x[rest]))
    assert np.median(missed) < 0.25 * np.median(np.abs(spring(x[rest])))


def test_its_feedforward_adds_the_residual_at_rest(trained, tmp_path):
    """The feedforward FMU gives prior plus residual where the reference rests as where it
    moves: held at a stretched spring, it pushes back by about the spring's pull, where the
    prior alone (offset zero, at rest) gives nothing."""
    _, folder = trained
    model = export(folder / "run", tmp_path / "pgnn.onnx")
    fmu = build_fmu(learned_feedforward_system(model, 1e-3), tmp_path / "pgnn.fmu")
    at = 0.04
    held = run_fmu(fmu, 300, 1e-3, {"x_ref": np.full(300, at), "vx_ref": np.zeros(300),
                                    "ax_ref": np.zeros(300), "jx_ref": np.zeros(300)},
                   record=["x_ff"])["x_ff"]
    assert held[-1] == pytest.approx(spring(at), rel=0.3)
