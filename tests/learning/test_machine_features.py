"""Features and labels for any machine: filtered measured motion, defaults from the data."""

import numpy as np
import pytest

from flexff.cosim.machine import parse_machine
from flexff.fmu.errors import InputError
from flexff.learning.feature_spec import feature_function, feature_names
from flexff.learning.machine_features import MachineFeatures, data_cutoff, prepare
from flexff.learning.samples import evaluate_samples

RATE = 1000.0


def machine(names=("x",)):
    return parse_machine({"axis": [
        {"name": n, "measured": f"p.{n}", "feedforward": f"c.{n}_ff", "effort": f"c.{n}_u",
         "range": [-0.1, 0.1], "velocity": 0.5, "acceleration": 5.0} for n in names]}, "m")


def sine(frequencies, seconds=20.0):
    t = np.arange(0.0, seconds, 1 / RATE)
    signals = {}
    for name, f in frequencies.items():
        w = 2 * np.pi * f
        signals.update({f"{name}_ref": 0.05 * np.sin(w * t),
                        f"v{name}_ref": 0.05 * w * np.cos(w * t),
                        f"a{name}_ref": -0.05 * w**2 * np.sin(w * t),
                        f"j{name}_ref": -0.05 * w**3 * np.cos(w * t),
                        f"{name}_measured": 0.05 * np.sin(w * t),
                        f"{name}_effort": 2.0 * -0.05 * w**2 * np.sin(w * t)})
    return signals


def test_the_corner_and_the_model_rate_come_from_the_references():
    one = machine()
    config = MachineFeatures().resolved(RATE, [sine({"x": 0.5})], one)
    assert config.cutoff_hz == pytest.approx(2.0, rel=0.15)  # four times the 0.5 Hz band
    assert RATE / config.model_rate_hz == 45  # at least 10 times the 2.2 Hz, dividing 1 kHz
    assert config.lead_s == 0.5 / RATE  # a zero-order hold
    assert data_cutoff([sine({"x": 4.0})], one, RATE) == pytest.approx(16.0, rel=0.05)


def test_features_of_clean_motion_are_the_motion_and_labels_the_effort():
    one = machine()
    config = MachineFeatures(cutoff_hz=5.0, model_rate_hz=100.0, jerk=True, lead_s=0.0
                             ).resolved(RATE, [], one)
    signals = sine({"x": 0.5})
    features, labels = prepare(signals, RATE, one, config)
    assert feature_names(one, config.inputs) == [
        "x", "vx", "ax", "jx", "dir_x_0.003", "dir_x_0.01", "dir_x_0.03",
        "moving_x_0.003", "moving_x_0.01", "moving_x_0.03"]
    inner = slice(200, -200)  # away from the filter's ends
    expected = [signals[n][::10] for n in ("x_ref", "vx_ref", "ax_ref", "jx_ref")]
    for column, values in zip(features.T, expected):
        np.testing.assert_allclose(column[inner], values[inner], atol=1e-4 * np.abs(values).max())
    moving = np.abs(features[:, 1]) > 0.5 * np.abs(features[:, 1]).max()  # past the filtered step
    assert np.array_equal(np.sign(features[moving, 4]), np.sign(features[moving, 1]))
    assert np.abs(features[:, 4:7]).max() < 1.2  # a smoothed step: the filter rings a little
    np.testing.assert_allclose(features[moving, 7:], 1.0, atol=0.05)  # moving at all (rings)
    np.testing.assert_allclose(labels[inner, 0], signals["x_effort"][::10][inner], rtol=0,
                               atol=1e-4 * np.abs(signals["x_effort"]).max())


def test_the_same_function_runs_on_the_reference():
    three = machine(("q1", "q2", "z"))
    config = MachineFeatures(cutoff_hz=5.0, jerk=False).resolved(RATE, [], three)
    signals = sine({"q1": 0.5, "q2": 0.3, "z": 0.2})
    reference = np.column_stack([signals[n] for n in three.reference_signals])
    features = evaluate_samples(feature_function(three, config.inputs), reference)
    assert features.shape == (reference.shape[0], 3 * 9)  # motion, 3 directions, 3 "moving"
    np.testing.assert_allclose(features[:, 9 + 1], signals["vq2_ref"])


def test_quantization_and_noise_are_settings_per_axis():
    one = machine()
    signals = sine({"x": 0.5})
    plain = MachineFeatures(cutoff_hz=5.0).resolved(RATE, [], one)
    counted = MachineFeatures(cutoff_hz=5.0, quantization={"x": 1e-3}).resolved(RATE, [], one)
    noisy = MachineFeatures(cutoff_hz=5.0, effort_noise={"x": 0.1}).resolved(RATE, [], one)
    assert not np.allclose(prepare(signals, RATE, one, plain)[0],
                           prepare(signals, RATE, one, counted)[0])
    no_rng = prepare(signals, RATE, one, noisy)[1]
    np.testing.assert_array_equal(no_rng, prepare(signals, RATE, one, plain)[1])
    assert not np.allclose(no_rng, prepare(signals, RATE, one, noisy,
                                           np.random.default_rng(0))[1])


@pytest.mark.parametrize("settings, words", [
    ({"cutoff_hz": 600.0}, "Nyquist"),
    ({"quantization": {"y": 1e-3}}, r"quantization\.y"),
    ({"effort_noise": {"x": -1.0}}, r"effort_noise\.x"),
    ({"cutoff_hz": 5.0, "model_rate_hz": 300.0}, "divide the data rate"),
])
def test_bad_settings_are_refused(settings, words):
    with pytest.raises(InputError, match=words):
        config = MachineFeatures(**settings).resolved(RATE, [sine({"x": 0.5})], machine())
        config.decimation(RATE)


def test_the_direction_widths_are_the_identified_friction_widths():
    """Each axis's identified Coulomb width over its velocity limit, each once; the fixed
    widths for a prior without Coulomb friction."""
    from dataclasses import replace

    from flexff.learning.feature_spec import DIRECTION_WIDTHS
    from flexff.learning.linear_prior import AxisFit, LinearModel
    from flexff.learning.machine_features import friction_widths

    two = machine(("x", "y"))  # velocity limits 0.5 (default prior: Coulomb friction)

    def fit(width):
        return AxisFit(["coulomb"], [1.0], [0.0], width, 1.0, 0.0, 0.0)
    model = LinearModel(two, {"x": fit(2e-3), "y": fit(1e-3)})
    assert friction_widths(model) == (0.002, 0.004)
    assert friction_widths(LinearModel(two, {"x": fit(2e-3), "y": fit(2.0000001e-3)})) == (
        0.004,)
    viscous = replace(two, prior=replace(two.prior, terms=("inertia", "viscous")))
    assert friction_widths(LinearModel(viscous, model.axes)) == DIRECTION_WIDTHS
