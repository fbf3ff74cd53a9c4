"""Identification for any machine: known parameters back from noise-free data, standard
deviations that hold, refusals naming the term, and the same model in NumPy and CasADi."""

import numpy as np
import pytest

from flexff.cosim.machine import parse_machine
from flexff.learning.linear_model import (
    IdentificationError,
    identify_linear,
    read_linear_model,
    write_linear_model,
)

PITCH = 0.016


def machine(names=("x",), terms=None, extra=None, width=1e-3):
    prior = {"coulomb_width": width, **({"terms": terms} if terms else {}),
             **({"extra": extra} if extra else {})}
    return parse_machine({"name": "drive", "axis": [
        {"name": n, "measured": f"p.{n}", "feedforward": f"c.{n}_ff", "effort": f"c.{n}_u",
         "range": [-0.1, 0.1], "velocity": 0.5, "acceleration": 5.0} for n in names],
        "prior": prior}, "m")


def motion(names, seconds=20.0, rate=1000.0, seed=0):
    rng = np.random.default_rng(seed)
    t = np.arange(0.0, seconds, 1 / rate)
    out = {}
    for name in names:
        f = rng.uniform(0.1, 1.0, 4)
        amplitude = rng.uniform(0.005, 0.02, 4) * f[0] / f
        w = 2 * np.pi * f[:, None]
        phase = rng.uniform(0, 2 * np.pi, 4)[:, None]
        out[name] = (amplitude[:, None] * np.sin(w * t + phase)).sum(0)
        out[f"v{name}"] = (amplitude[:, None] * w * np.cos(w * t + phase)).sum(0)
        out[f"a{name}"] = -(amplitude[:, None] * w**2 * np.sin(w * t + phase)).sum(0)
    return out


def drive_effort(m):
    v = m["vx"]
    tanh = np.tanh(v / 1e-3)
    return (2.0 * m["ax"] + 20.0 * v + 0.5 * 1.5 * (tanh + tanh**2)
            + 0.5 * 1.2 * (tanh - tanh**2) + 0.5 * np.sin(2 * np.pi * m["x"] / PITCH))


def test_a_drive_is_recovered_to_1e_6_from_noise_free_data():
    drive = machine(terms=["inertia", "viscous", "coulomb_asymmetric"],
                    extra={"x": {"cogging": f"sin(2 * pi * x / {PITCH})"}})
    m = motion(("x",))
    model = identify_linear(drive, m, {"x": drive_effort(m)})
    fit = model.axes["x"]
    assert fit.terms == ["inertia", "viscous", "coulomb_positive", "coulomb_negative", "cogging"]
    np.testing.assert_allclose(fit.parameters, [2.0, 20.0, 1.5, 1.2, 0.5], rtol=1e-6)
    assert fit.relative_error < 1e-9 and fit.condition < 1e3


def test_three_axes_with_a_coupling_term():
    names = ("q1", "q2", "z")
    three = machine(names, terms=["inertia", "viscous", "offset"],
                    extra={"q1": {"coupling": "aq2 * cos(q2)"}})
    m = motion(names, seed=1)
    efforts = {"q1": 0.3 * m["aq1"] + 0.1 * m["vq1"] - 0.2 + 0.05 * m["aq2"] * np.cos(m["q2"]),
               "q2": 0.1 * m["aq2"] + 0.02 * m["vq2"] + 0.4,
               "z": 5.0 * m["az"] + 9.0 * m["vz"] + 49.05}
    model = identify_linear(three, m, efforts)
    np.testing.assert_allclose(model.axes["q1"].parameters, [0.3, 0.1, -0.2, 0.05], rtol=1e-6)
    np.testing.assert_allclose(model.axes["z"].parameters, [5.0, 9.0, 49.05], rtol=1e-6)
    for name, predicted in model.predict(m).items():
        np.testing.assert_allclose(predicted, efforts[name], atol=1e-9)


def test_standard_deviations_hold_on_noisy_labels():
    drive = machine()
    m = motion(("x",), seed=2)
    truth = 2.0 * m["ax"] + 20.0 * m["vx"] + 1.3 * np.tanh(m["vx"] / 1e-3) + 0.15
    deviations = []
    for seed in range(20):
        noisy = truth + np.random.default_rng(seed).normal(0.0, 0.2, truth.size)
        fit = identify_linear(drive, m, {"x": noisy}).axes["x"]
        deviations.append((np.array(fit.parameters) - [2.0, 20.0, 1.3, 0.15]) / fit.std)
    # each parameter's error in its standard deviations: about unit spread over 20 draws
    spread = np.std(deviations, axis=0)
    assert np.all((spread > 0.5) & (spread < 1.6)), spread


def test_the_condition_number_is_that_of_the_scaled_regressor():
    drive = machine(terms=["inertia", "viscous"])
    m = motion(("x",), seed=3)
    fit = identify_linear(drive, m, {"x": m["ax"]}).axes["x"]
    w = np.column_stack([m["ax"], m["vx"]])
    assert fit.condition == pytest.approx(np.linalg.cond(w / np.linalg.norm(w, axis=0)))


def test_a_term_the_data_cannot_tell_apart_is_named():
    drive = machine(terms=["inertia", "viscous"], extra={"x": {"damping_again": "2 * vx"}})
    m = motion(("x",))
    with pytest.raises(IdentificationError, match=r"axis x: the data cannot tell "
                                                  r"(viscous|damping_again) from the other"):
        identify_linear(drive, m, {"x": m["ax"]})
    still = {k: v * 0 if k == "ax" else v for k, v in m.items()}
    with pytest.raises(IdentificationError, match=r"the term inertia is zero on every sample"):
        identify_linear(machine(terms=["inertia", "viscous"]), still, {"x": m["vx"]})


def test_the_width_is_chosen_from_the_candidates_without_a_prior_width():
    drive = machine(width=None, terms=["inertia", "viscous", "coulomb"])
    m = motion(("x",), seed=4)
    effort = 2.0 * m["ax"] + 20.0 * m["vx"] + 1.3 * np.tanh(m["vx"] / (0.003 * 0.5))
    fit = identify_linear(drive, m, {"x": effort}).axes["x"]
    assert fit.width == pytest.approx(0.003 * 0.5)
    np.testing.assert_allclose(fit.parameters, [2.0, 20.0, 1.3], rtol=1e-6)


def test_json_and_casadi_give_the_same_efforts(tmp_path):
    drive = machine(terms=["inertia", "viscous", "coulomb_asymmetric"],
                    extra={"x": {"cogging": f"sin(2 * pi * x / {PITCH})"}})
    m = motion(("x",))
    model = identify_linear(drive, m, {"x": drive_effort(m)})
    again = read_linear_model(write_linear_model(model, tmp_path / "model.json"))
    np.testing.assert_array_equal(again.predict(m)["x"], model.predict(m)["x"])
    function = model.casadi_function()
    by_casadi = np.array([float(function(m["x"][k], m["vx"][k], m["ax"][k]))
                          for k in range(0, m["x"].size, 997)])
    np.testing.assert_allclose(by_casadi, model.predict(m)["x"][::997], rtol=1e-12)
    assert "coulomb_negative" in model.summary()
