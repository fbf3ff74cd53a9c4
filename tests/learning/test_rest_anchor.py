"""Learned models of a machine whose prior is exact and holds no effort at rest: a mass with
viscous and asymmetric Coulomb friction, moves between rests, its measured positions noisy as
an encoder's. The one-sided friction feature is 1 while moving, as a constant is, and the
rests' noisy features cannot tell them apart: a free constant came out at a few mN, which the
feedforward gave at rest (where the reference's features are exactly zero) and which crept a
machine with steep friction off its position. Resting at the origin, each model must give what
its prior gives there: nothing."""

import numpy as np
import pytest
import torch

from flexff.controllers.learned_feedforward import learned_feedforward_system
from flexff.cosim.machine import parse_machine
from flexff.fmu.build import build_fmu
from flexff.learning.dataset_files import Trajectory
from flexff.learning.description_data import DescriptionData
from flexff.learning.export import export
from flexff.learning.linear_prior import AxisFit, LinearModel
from flexff.learning.machine_features import MachineFeatures
from flexff.learning.presets import make_config
from flexff.learning.rest_anchor import RestAnchor, fit_through, rest_anchor
from flexff.learning.train import fit
from tests.helpers import rest_to_rest_moves
from tests.runners import run_fmu

RATE = 1000.0
MASS, DAMPING, PLUS, MINUS, WIDTH = 2.0, 20.0, 1.5, 1.0, 1e-3  # Coulomb moving + and -
NOISE = 1e-5  # the measured positions' noise in training [m]
MACHINE = parse_machine({
    "name": "slide", "prior": {"terms": ["inertia", "viscous", "coulomb_asymmetric"]},
    "axis": [{"name": "x", "measured": "p.x", "feedforward": "c.x_ff", "effort": "c.x_u",
              "range": [-0.05, 0.05], "velocity": 0.25, "acceleration": 2.5}]}, "m")


def prior() -> LinearModel:
    """The prior at its true values."""
    return LinearModel(MACHINE, {"x": AxisFit(
        ["inertia", "viscous", "coulomb_positive", "coulomb_negative"],
        [MASS, DAMPING, PLUS, MINUS], [0.0] * 4, WIDTH, 1.0, 0.0, 0.0)})


def moves(seed: int, split: str, seconds: float = 10.0) -> Trajectory:
    """Minimum-jerk moves between random positions, each followed by a rest of 0.2 to 0.6 s,
    and the slide's effort along them."""
    t, x, v, a = rest_to_rest_moves(seed, seconds, RATE)
    direction = np.tanh(v / WIDTH)
    friction = 0.5 * (PLUS + MINUS) * direction + 0.5 * (PLUS - MINUS) * direction**2
    signals = {"time": t, "x_ref": x, "vx_ref": v, "ax_ref": a,
               "jx_ref": np.gradient(a, 1 / RATE), "x_measured": x,
               "x_effort": MASS * a + DAMPING * v + friction}
    return Trajectory(f"{split}-{seed}", split, signals)


@pytest.fixture(scope="module")
def trained(tmp_path_factory):
    """A physics-guided model (its residual kept: it helps on the noisy motion) and an LSTM
    (a few epochs: the constant comes from the linear skip's fit), each one's metrics and
    feedforward FMU."""
    folder = tmp_path_factory.mktemp("rest")
    data = [moves(k, "train") for k in range(6)] + [moves(10 + k, "test") for k in range(2)]
    features = MachineFeatures(position_noise={"x": NOISE})
    out = {}
    for kind, epochs, given in (("pgnn", 20, prior()), ("lstm", 3, None)):
        config = make_config(kind, "fast", epochs=epochs)
        metrics = fit(config, DescriptionData.of(config, MACHINE, RATE, data, "digest",
                                                 features, given),
                      folder / kind, progress=False)
        model = export(folder / kind, folder / f"{kind}.onnx")
        out[kind] = metrics, build_fmu(learned_feedforward_system(model, 1e-3),
                                       folder / f"{kind}.fmu")
    return out


@pytest.mark.parametrize("kind", ["pgnn", "lstm"])
def test_at_rest_at_the_origin_it_gives_what_its_prior_gives(trained, kind):
    """Held at rest at the origin, the feedforward FMU gives no effort where its prior gives
    none (before: -2.5 mN from the physics-guided model, 30 mN from the LSTM)."""
    _, fmu = trained[kind]
    held = run_fmu(fmu, 100, 1e-3, {"x_ref": np.zeros(100), "vx_ref": np.zeros(100),
                                    "ax_ref": np.zeros(100), "jx_ref": np.zeros(100)},
                   record=["x_ff"])["x_ff"]
    assert np.max(np.abs(held)) < 1e-5


def test_the_residual_still_helps(trained):
    """Pinned at rest, the physics-guided model's residual still lowers the test error below
    its prior's: it was kept, and the pin cost it little."""
    metrics, _ = trained["pgnn"]
    assert metrics["prior_alone"] == []
    assert metrics["test_mse"] < 0.8 * metrics["prior_test_mse"]


def test_a_pinned_output_is_fitted_through_its_anchor():
    """fit_through: a pinned output's fit passes through the anchor's zero exactly, and matches
    the data as well as that allows; an output not pinned is the plain least-squares fit."""
    rng = np.random.default_rng(0)
    x = torch.as_tensor(rng.normal(size=(400, 3)))
    y = x @ torch.as_tensor([[1.0, 2.0], [0.5, -1.0], [0.0, 3.0]], dtype=x.dtype) + 0.2 \
        + 0.01 * torch.as_tensor(rng.normal(size=(400, 2)))
    anchor = RestAnchor(np.array([0.1, -0.2, 0.3]), np.zeros(3), np.array([0.0, 5.0]), (1,), ())
    solution = fit_through(x, y, anchor)
    plain = fit_through(x, y, None)
    assert torch.allclose(solution[:, 0], plain[:, 0])
    at_anchor = torch.as_tensor(anchor.zero) @ solution[:-1, 1] + solution[-1, 1]
    assert float(at_anchor) == pytest.approx(5.0, abs=1e-12)
    assert not torch.allclose(solution[:, 1], plain[:, 1])


def test_which_axes_are_held():
    """Without an offset in the prior every axis is held to no constant, and those without
    extra terms to no effort at rest at the origin; with an offset none is held."""
    axes = [{"name": n, "measured": f"p.{n}", "feedforward": f"c.{n}_ff", "effort": f"c.{n}_u",
             "range": [-0.05, 0.05], "velocity": 0.25, "acceleration": 2.5} for n in "xy"]
    cogged = parse_machine({"name": "cogged", "axis": axes, "prior": {
        "terms": ["inertia", "viscous", "coulomb"],
        "extra": {"y": {"cogging": "cos(y / 0.01)"}}}}, "m")
    anchor = rest_anchor(cogged, MachineFeatures().inputs)
    assert anchor is not None
    assert anchor.pinned == (0, 1) and anchor.still == (0,)
    assert np.all(anchor.zero == 0) and anchor.resting[-1] == 1.0  # cos(0): the extra at rest
    offset = parse_machine({"name": "offset", "axis": axes}, "m")  # the default terms
    assert rest_anchor(offset, MachineFeatures().inputs) is None
