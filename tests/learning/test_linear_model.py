"""Identification for any machine: known parameters back from noise-free data, from a
quantized encoder and noisy efforts through the filters with standard deviations that hold,
refusals naming the term, and the same model in NumPy, CasADi and JSON."""

import numpy as np
import pytest

from flexff.cosim.machine import parse_machine
from flexff.fmu.errors import InputError
from flexff.learning.linear_model import (
    IdentificationError,
    identify_linear,
    parallel_filter,
    read_linear_model,
    reference_motion,
    regressor,
    write_linear_model,
)
from flexff.learning.linear_prior import term_names
from flexff.learning.machine_features import MachineFeatures, motion, named_motion

PITCH = 0.016  # the drive's cogging period [m]
WIDTH = 2e-3  # its Coulomb tanh width [m/s]
RATE = 1000.0


def machine(names=("x",), terms=None, extra=None, width=WIDTH):
    prior = {**({"coulomb_width": width} if width else {}), **({"terms": terms} if terms else {}),
             **({"extra": extra} if extra else {})}
    return parse_machine({"name": "drive", "axis": [
        {"name": n, "measured": f"p.{n}", "feedforward": f"c.{n}_ff", "effort": f"c.{n}_u",
         "range": [-0.05, 0.05], "velocity": 0.5, "acceleration": 5.0} for n in names],
        "prior": prior}, "m")


def exact_motion(names, seconds=20.0, seed=0):
    """A multisine per axis within +-0.05 m, 0.1 to 2 Hz, with its exact derivatives."""
    rng = np.random.default_rng(seed)
    t = np.arange(0.0, seconds, 1 / RATE)
    out = {}
    for name in names:
        f = rng.uniform(0.1, 2.0, 4)
        amplitude = rng.uniform(0.004, 0.012, 4) * f.min() / f
        w = 2 * np.pi * f[:, None]
        phase = rng.uniform(0, 2 * np.pi, 4)[:, None]
        out[name] = (amplitude[:, None] * np.sin(w * t + phase)).sum(0)
        out[f"v{name}"] = (amplitude[:, None] * w * np.cos(w * t + phase)).sum(0)
        out[f"a{name}"] = -(amplitude[:, None] * w**2 * np.sin(w * t + phase)).sum(0)
    return out


def drive_effort(m, offset=0.0):
    """2 kg, 20 N s/m, one-sided Coulomb +1.5 / -1.2 N (zero at rest), 0.5 N cogging."""
    v, t = m["vx"], np.tanh(m["vx"] / WIDTH)
    return (2.0 * m["ax"] + 20.0 * v + 0.5 * (1.5 * (t + t**2) + 1.2 * (t - t**2))
            + 0.5 * np.sin(2 * np.pi * m["x"] / PITCH) + offset)


COGGING = {"x": {"cogging": f"sin(2 * pi * x / {PITCH})"}}
ONE_SIDED = (["inertia", "viscous", "coulomb_asymmetric"], [2.0, 20.0, 1.5, 1.2, 0.5])
# with an offset: told from the two levels by the samples near rest alone
OFFSET = (["inertia", "viscous", "coulomb_asymmetric", "offset"],
          [2.0, 20.0, 1.5, 1.2, 0.15, 0.5])


@pytest.mark.parametrize(("terms", "truth"), [ONE_SIDED, OFFSET])
def test_a_drive_is_recovered_to_1e_6_from_noise_free_data(terms, truth):
    drive = machine(terms=terms, extra=COGGING)
    m = exact_motion(("x",))
    offset = truth[4] if "offset" in terms else 0.0
    fit = identify_linear(drive, m, {"x": drive_effort(m, offset)}).axes["x"]
    assert fit.terms == term_names(drive, 0) and fit.terms[-1] == "cogging"
    np.testing.assert_allclose(fit.parameters, truth, rtol=1e-6)
    assert fit.relative_error < 1e-9 and fit.condition < 1e3


def test_three_axes_with_a_coupling_term():
    names = ("q1", "q2", "z")
    three = machine(names, terms=["inertia", "viscous", "offset"],
                    extra={"q1": {"coupling": "aq2 * cos(q2)"}, "z": {"spring": "z"}})
    m = exact_motion(names, seed=1)
    efforts = {"q1": 0.3 * m["aq1"] + 0.1 * m["vq1"] - 0.2 + 0.05 * m["aq2"] * np.cos(m["q2"]),
               "q2": 0.1 * m["aq2"] + 0.02 * m["vq2"] + 0.4,
               "z": 5.0 * m["az"] + 9.0 * m["vz"] + 49.05 + 300.0 * m["z"]}
    model = identify_linear(three, m, efforts)
    np.testing.assert_allclose(model.axes["q1"].parameters, [0.3, 0.1, -0.2, 0.05], rtol=1e-6)
    np.testing.assert_allclose(model.axes["q2"].parameters, [0.1, 0.02, 0.4], rtol=1e-6)
    np.testing.assert_allclose(model.axes["z"].parameters, [5.0, 9.0, 49.05, 300.0], rtol=1e-6)
    for name, predicted in model.predict(m).items():
        np.testing.assert_allclose(predicted, efforts[name], atol=1e-9)


def trajectories(seeds, noise):
    """The drive's recorded signals: a 1 um encoder's count of the position, efforts with
    white noise of `noise` N."""
    out = []
    for seed in seeds:
        m = exact_motion(("x",), seed=seed)
        rng = np.random.default_rng(100 + seed)
        out.append({"x_ref": m["x"], "vx_ref": m["vx"], "ax_ref": m["ax"],
                    "x_measured": 1e-6 * np.floor(m["x"] / 1e-6 + 0.5),
                    "x_effort": drive_effort(m) + noise * rng.standard_normal(m["x"].size)})
    return out


def identified(drive, recorded, source="measured", cutoff_hz=None, **settings):
    """The drive identified on recorded trajectories: the regressor on the measured motion
    (learning.machine_features.motion) or the references, its columns and the efforts through
    parallel_filter at the corner MachineFeatures derives from the references."""
    features = MachineFeatures(cutoff_hz=cutoff_hz).resolved(RATE, recorded, drive)
    moved = [named_motion(motion(r, RATE, drive, features)[0], drive) if source == "measured"
             else reference_motion(drive, r) for r in recorded]
    efforts = [{"x": r["x_effort"]} for r in recorded]
    filtered = parallel_filter(RATE, features.cutoff_hz, **settings)
    return identify_linear(drive, moved, efforts, filtered).axes["x"], features.cutoff_hz


@pytest.mark.parametrize("source", ["measured", "reference"])
def test_a_quantized_encoder_and_noisy_efforts_through_the_filters(source):
    terms, truth = ONE_SIDED
    drive = machine(terms=terms, extra=COGGING)
    fit, cutoff = identified(drive, trajectories((2, 3), noise=0.2), source)
    error = np.array(fit.parameters) - truth
    assert np.all(np.abs(error) < 0.02 * np.abs(truth)), error / truth
    assert np.all(np.abs(error) < 3 * np.array(fit.std)), error / fit.std
    assert 1.0 < cutoff < 50.0


def test_standard_deviations_hold_over_many_draws():
    terms, truth = ONE_SIDED
    drive = machine(terms=terms, extra=COGGING)
    fits = [identified(drive, trajectories((seed,), noise=0.3), cutoff_hz=5.0)[0]
            for seed in range(20)]
    scores = [(np.array(fit.parameters) - truth) / fit.std for fit in fits]
    # each parameter's error in its standard deviations: about unit spread
    spread = np.sqrt(np.mean(np.square(scores), axis=0))
    assert np.all((spread > 0.6) & (spread < 1.5)), spread


def test_condition_and_standard_deviations_against_the_normal_equations():
    drive = machine(terms=["inertia", "viscous", "coulomb", "offset"])
    m = exact_motion(("x",), seed=3)
    labels = drive_effort(m) + np.random.default_rng(0).normal(0.0, 0.1, m["x"].size)
    fit = identify_linear(drive, m, {"x": labels}).axes["x"]
    w = np.column_stack([m["ax"], m["vx"], np.tanh(m["vx"] / WIDTH), np.ones(m["x"].size)])
    np.testing.assert_allclose(w, regressor(drive, m, WIDTH)["x"], rtol=1e-15)
    theta = np.linalg.solve(w.T @ w, w.T @ labels)
    residual = labels - w @ theta
    covariance = residual @ residual / (len(labels) - 4) * np.linalg.inv(w.T @ w)
    np.testing.assert_allclose(fit.parameters, theta, rtol=1e-9)
    np.testing.assert_allclose(fit.std, np.sqrt(np.diag(covariance)), rtol=1e-9)
    assert fit.condition == pytest.approx(np.linalg.cond(w / np.linalg.norm(w, axis=0)))
    assert fit.rms == pytest.approx(np.sqrt(np.mean(residual**2)))
    assert fit.relative_error == pytest.approx(np.linalg.norm(residual) / np.linalg.norm(labels))
    relative = fit.table()["viscous"]["relative_std_percent"]
    assert relative == pytest.approx(100 * np.sqrt(covariance[1, 1]) / theta[1])


@pytest.mark.parametrize("share", [1e-3, 5e-5])  # |R_kk| 6e-5 and 3e-6: both QR paths
def test_nearly_dependent_columns_as_numpy_s_least_squares(share):
    drive = machine(terms=["inertia", "viscous"], extra={"x": {"near": f"vx + {share} * x"}})
    m = exact_motion(("x",), seed=6)
    labels = 2.0 * m["ax"] + 20.0 * m["vx"] + 3.0 * (m["vx"] + share * m["x"]) \
        + np.random.default_rng(0).normal(0.0, 0.01, m["x"].size)
    fit = identify_linear(drive, m, {"x": labels}).axes["x"]
    w = regressor(drive, m, WIDTH)["x"]
    np.testing.assert_allclose(fit.parameters, np.linalg.lstsq(w, labels, rcond=None)[0],
                               rtol=1e-6)
    assert fit.condition == pytest.approx(np.linalg.cond(w / np.linalg.norm(w, axis=0)))


def test_terms_the_data_cannot_tell_apart_are_refused_by_name():
    m = exact_motion(("x",))
    with pytest.raises(IdentificationError, match=r"the term damping equals \+2 viscous"):
        identify_linear(machine(terms=["inertia", "viscous"], extra={"x": {"damping": "2*vx"}}),
                        m, {"x": m["ax"]})
    forwards = {"x": 0.1 * m["x"] + 0.2 * np.arange(m["x"].size) / RATE, "vx": 0.1 * m["vx"]
                + 0.2, "ax": 0.1 * m["ax"]}  # never reverses: Coulomb is an offset
    with pytest.raises(IdentificationError, match=r"axis x: on these data the term offset "
                                                  r"equals \+1 coulomb: the data cannot tell"):
        identify_linear(machine(), forwards, {"x": forwards["vx"]})
    with pytest.raises(IdentificationError, match=r"the term coulomb_negative is zero on every"):
        identify_linear(machine(terms=OFFSET[0]), forwards, {"x": forwards["vx"]})
    still = {**m, "ax": 0 * m["ax"]}
    with pytest.raises(IdentificationError, match=r"the term inertia is zero on every sample"):
        identify_linear(machine(terms=["inertia", "viscous"]), still, {"x": m["vx"]})
    with pytest.raises(IdentificationError, match=r"axis x: 2 samples cannot determine 2"):
        identify_linear(machine(terms=["inertia", "viscous"]),
                        {k: v[:2] for k, v in m.items()}, {"x": m["vx"][:2]})
    with pytest.raises(InputError, match=r"decimation: expected a whole number >= 1, got 0"):
        parallel_filter(RATE, 5.0, decimation=0)
    with pytest.raises(InputError, match=r"too short for the filter's edges \(400 samples"):
        parallel_filter(RATE, 5.0)(np.zeros((800, 2)))
    with pytest.raises(IdentificationError, match=r"machine.prior.extra.x.viscous: the name"):
        identify_linear(machine(extra={"x": {"viscous": "vx"}}), m, {"x": m["vx"]})


@pytest.mark.parametrize("width", [0.003 * 0.5, 1e-3])  # one of WIDTHS, one between two
def test_the_width_of_the_smallest_residual_without_a_prior_width(width):
    drive = machine(width=None, terms=["inertia", "viscous", "coulomb"])
    m = exact_motion(("x",), seed=4)
    effort = 2.0 * m["ax"] + 20.0 * m["vx"] + 1.3 * np.tanh(m["vx"] / width)
    fit = identify_linear(drive, m, {"x": effort}).axes["x"]
    assert fit.width == pytest.approx(width, rel=0.02)
    np.testing.assert_allclose(fit.parameters, [2.0, 20.0, 1.3], rtol=0.01)
    assert fit.relative_error < 0.01


def test_json_casadi_and_numpy_give_the_same_efforts(tmp_path):
    names = ("x", "y")
    two = machine(names, terms=["inertia", "viscous", "coulomb_asymmetric"],
                  extra={"x": {"cogging": f"sin(2 * pi * x / {PITCH})",
                               "coupling": "ay * cos(x)"}})
    m = exact_motion(names, seed=5)
    efforts = {"x": drive_effort(m) + 0.3 * m["ay"] * np.cos(m["x"]),
               "y": 1.0 * m["ay"] + 3.0 * m["vy"] + 0.4 * np.tanh(m["vy"] / WIDTH)}
    model = identify_linear(two, m, efforts)
    again = read_linear_model(write_linear_model(model, tmp_path / "model.json"))
    for name in names:
        np.testing.assert_array_equal(again.predict(m)[name], model.predict(m)[name])
    pos, vel, acc = (np.vstack([m[f"{d}{n}"] for n in names]) for d in ("", "v", "a"))
    by_casadi = np.array(model.casadi_function().map(pos.shape[1])(pos, vel, acc))
    for k, name in enumerate(names):
        np.testing.assert_allclose(by_casadi[k], model.predict(m)[name], rtol=1e-12,
                                   atol=1e-12)
    assert "coulomb_negative" in model.summary() and "coupling" in again.summary()


@pytest.mark.parametrize("lead_s", [None, 0.0])
def test_held_efforts_pair_with_the_motion_half_a_sample_later(lead_s):
    """A 2 kg mass under efforts held over each step (a digital controller's zero-order hold):
    each effort sample acts on the motion half a sample after it. Aligned so (the default
    lead), the model explains the efforts exactly; paired sample by sample, a residual of
    the jerk's half-sample term is left."""
    h, mass = 1 / RATE, 2.0
    m = exact_motion(("x",), seconds=10.0)
    held = mass * m["ax"]  # any smooth effort, held over each step
    x, v = np.zeros(held.size), np.zeros(held.size)
    for k in range(held.size - 1):  # the exact discretization of a mass under a held effort
        x[k + 1] = x[k] + h * v[k] + h**2 / 2 * held[k] / mass
        v[k + 1] = v[k] + h * held[k] / mass
    drive = machine(terms=["inertia"], width=None)
    features = MachineFeatures(cutoff_hz=20.0, lead_s=lead_s).resolved(RATE, [], drive)
    moved, efforts = motion({"x_measured": x, "x_effort": held}, RATE, drive, features)
    fit = identify_linear(drive, named_motion(moved, drive), {"x": efforts[:, 0]},
                          parallel_filter(RATE, 20.0), features.lead_s).axes["x"]
    assert fit.parameters[0] == pytest.approx(mass, rel=1e-4)
    if lead_s is None:
        assert fit.relative_error < 2e-4 and features.lead_s == h / 2
    else:
        assert fit.relative_error > 1e-3
