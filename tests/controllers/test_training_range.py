"""The training-range check against circles whose feature ranges are known in closed form: a
circle of radius r at angular rate w reaches +-r w in velocity and +-r w^2 in acceleration, so
twice the rate leaves the velocity range by half a span (for the 2/3 of the time |sin| > 1/2)
and the acceleration range by 1.5 spans (where |cos| > 1/4)."""

import json

import numpy as np
import onnx
import pytest

from flexff.controllers.features import feature_names, reference_features
from flexff.controllers.training_range import MARGIN, training_range_excess
from flexff.plant.signals import REFERENCE, names

RADIUS, RATE = 0.01, 2 * np.pi * 0.5  # m, rad/s


def circle(rate: float, radius: float = RADIUS) -> dict[str, np.ndarray]:
    """A steady circle about the centre sampled at 1 kHz over two of its slowest turns."""
    angle = rate * np.arange(0.0, 4.0, 1e-3)
    c, s = np.cos(angle), np.sin(angle)
    values = (radius * c, radius * s, -radius * rate * s, radius * rate * c,
              -radius * rate**2 * c, -radius * rate**2 * s)
    return dict(zip(names(REFERENCE), values))


def model_file(path, feature_set: str, trained_on: dict | None, rate_hz: float = 1000.0) -> str:
    """A flexff-format ONNX file (an identity graph) run at `rate_hz` and trained, says its
    metadata, on the features of `trained_on`."""
    n = len(feature_names(feature_set))
    x = onnx.helper.make_tensor_value_info("inputs", onnx.TensorProto.DOUBLE, ["time", n])
    y = onnx.helper.make_tensor_value_info("forces", onnx.TensorProto.DOUBLE, ["time", n])
    model = onnx.helper.make_model(onnx.helper.make_graph(
        [onnx.helper.make_node("Identity", ["inputs"], ["forces"])], "identity", [x], [y]))
    meta = {"format": "flexff-feedforward", "input_kind": "features", "feature_set": feature_set,
            "input_signals": json.dumps(feature_names(feature_set)),
            "sample_rate_hz": repr(rate_hz)}
    if trained_on is not None:
        features = reference_features(trained_on, feature_set)
        meta["feature_range"] = json.dumps({"signals": feature_names(feature_set),
                                            "low": features.min(axis=0).tolist(),
                                            "high": features.max(axis=0).tolist()})
    onnx.helper.set_model_props(model, meta)
    onnx.save(model, str(path))
    return str(path)


def test_the_training_motion_itself_stays_inside(tmp_path):
    for feature_set in ("compact", "full"):
        model = model_file(tmp_path / f"{feature_set}.onnx", feature_set, circle(RATE))
        assert training_range_excess(model, circle(RATE)) == []


def test_a_faster_circle_leaves_velocity_and_acceleration_ranges_by_the_expected_spans(tmp_path):
    model = model_file(tmp_path / "compact.onnx", "compact", circle(RATE))
    excess = {e.signal: e for e in training_range_excess(model, circle(2 * RATE))}
    assert set(excess) == {"vx", "vy", "ax", "ay"}  # same radius: positions stay inside
    for name in ("vx", "vy"):
        assert excess[name].spans == pytest.approx(0.5, rel=1e-3)
        assert excess[name].reached_high == pytest.approx(2 * RADIUS * RATE, rel=1e-6)
        assert excess[name].unit == "m/s"
        assert excess[name].fraction == pytest.approx(2 / 3, abs=2e-3)  # where |sin| > 1/2
    for name in ("ax", "ay"):
        assert excess[name].spans == pytest.approx(1.5, rel=1e-3)
        assert excess[name].fraction == pytest.approx(1 - 2 * np.arcsin(0.25) / np.pi, abs=2e-3)
    assert next(iter(excess)) in ("ax", "ay")  # farthest first
    assert "spans beyond" in excess["ax"].describe()


def test_the_full_set_flags_the_joint_rates_of_a_faster_circle(tmp_path):
    model = model_file(tmp_path / "full.onnx", "full", circle(RATE))
    names = {e.signal for e in training_range_excess(model, circle(2 * RATE))}
    assert "theta_s1_dot" in names and "x_ee_ddot" in names
    assert all(n.endswith(("_dot", "_ddot")) for n in names)  # positions stay inside


def test_a_small_excess_within_the_margin_is_not_reported(tmp_path):
    model = model_file(tmp_path / "compact.onnx", "compact", circle(RATE))
    faster = 1 + MARGIN / 2  # acceleration 1.1025 times the trained: 0.05 spans beyond
    assert training_range_excess(model, circle(RATE * faster)) == []


def test_only_the_samples_the_network_sees_are_judged(tmp_path):
    """A 100 Hz model in a 1 kHz loop runs on every 10th sample: a one-sample excursion in
    between never reaches it."""
    model = model_file(tmp_path / "compact.onnx", "compact", circle(RATE), rate_hz=100.0)
    for k, flagged in ((1205, False), (1200, True)):
        reference = circle(RATE)
        reference["ax_ref"] = reference["ax_ref"].copy()
        reference["ax_ref"][k] = 1.0  # m/s2: ten times the circle's
        assert [e.signal for e in training_range_excess(model, reference)] == (
            ["ax"] if flagged else [])


def test_a_model_exported_without_its_range_is_not_judged(tmp_path):
    model = model_file(tmp_path / "old.onnx", "compact", None)
    assert training_range_excess(model, circle(2 * RATE)) is None
