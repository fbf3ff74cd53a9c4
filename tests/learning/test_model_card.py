"""The exported model's card: its metadata round trip, every bad field named, and the
manipulator's part of it given by its registration (learning.implicit_machine)."""

from dataclasses import replace

import onnx
import pytest
from onnx import TensorProto
from onnx import helper as oh

from flexff.learning.implicit_machine import implicit_machine, register_implicit_machine
from flexff.learning.model_card import FORMAT, ModelCard, read_card
from tests.flexff.test_generic_floors import offences
from tests.helpers import REPOSITORY

CARD = ModelCard(feature_set="compact", input_kind="features",
                 input_signals=["x", "y", "vx", "vy", "ax", "ay"], sample_rate_hz=100.0,
                 model_kind="pgnn", preset="fast",
                 input_units=["m", "m", "m/s", "m/s", "m/s2", "m/s2"],
                 state=[{"input": "h", "output": "h_out", "shape": [1, 2], "initial": "zeros"}],
                 history_samples=7, prior="rigid-body",
                 prior_parameters={"tau_coulomb1": 0.007, "w_stribeck": 0.01},
                 feature_range={"signals": ["x"], "low": [-0.05], "high": [0.05]},
                 ensemble_members=3)


def _saved(path, props):
    """A one-node graph carrying `props` as its metadata."""
    graph = oh.make_graph([oh.make_node("Identity", ["a"], ["b"])], "g",
                          [oh.make_tensor_value_info("a", TensorProto.DOUBLE, [1])],
                          [oh.make_tensor_value_info("b", TensorProto.DOUBLE, [1])])
    model = oh.make_model(graph, opset_imports=[oh.make_opsetid("", 17)], ir_version=8)
    oh.set_model_props(model, props)
    onnx.save(model, str(path))
    return path


def test_the_card_survives_the_graph(tmp_path):
    props = CARD.metadata()
    assert props["format"] == FORMAT and props["sample_rate_hz"] == "100.0"
    assert props["prior_parameters"] == '{"tau_coulomb1": 0.007, "w_stribeck": 0.01}'
    assert "extrapolate" in props["usage"]
    assert read_card(_saved(tmp_path / "m.onnx", props)) == CARD


def test_an_older_export_reads_with_defaults():
    props = {"format": FORMAT, "feature_set": "full", "input_kind": "reference",
             "input_signals": '["x_ref"]', "sample_rate_hz": "50.0"}
    card = ModelCard.from_metadata(props, "old.onnx")
    assert (card.prior, card.prior_parameters, card.feature_range, card.state) == (
        "none", {}, None, [])
    assert card.output_signals == ["Fx_ff", "Fy_ff"] and card.output_units == ["N", "N"]


@pytest.mark.parametrize("change, message", [
    ({"format": "other"}, "not a flexff feedforward model"),
    ({"input_kind": None}, "metadata lacks input_kind"),
    ({"sample_rate_hz": "fast"}, "sample_rate_hz = 'fast' is not valid"),
    ({"state": "[{"}, "state = .* is not valid"),
    ({"input_signals": "0"}, "input_signals = '0' is not a list of names"),  # found by fuzzing
    ({"output_units": '["N", 1]'}, "output_units = .* is not a list of names"),
    ({"input_kind": "currents"}, "unknown input kind 'currents'"),
    ({"prior": "friction"}, "unknown prior 'friction'"),
    ({"prior_parameters": '{"tau_coulomb9": 1}'}, "prior_parameters .* are not nominal-model"),
    ({"prior_parameters": '{"tau_coulomb1": -1}'}, "must not be negative"),
    ({"force_input": '{"m_ee9": 1}'}, "force_input .* are not nominal-model"),
    ({"output_signals": '["x_ff"]'}, "are neither the forces .* nor the currents"),
])
def test_every_bad_field_is_named(change, message):
    props = {k: v for k, v in {**CARD.metadata(), **change}.items() if v is not None}
    with pytest.raises(ValueError, match=message):
        ModelCard.from_metadata(props, "m.onnx")


def test_a_file_that_is_no_model_is_named(tmp_path):
    with pytest.raises(ValueError, match="does not exist"):
        read_card(tmp_path / "none.onnx")
    (tmp_path / "junk.onnx").write_bytes(b"junk")
    with pytest.raises(ValueError, match="not a readable ONNX model"):
        read_card(tmp_path / "junk.onnx")


CARD_MODULES = ("model_card", "implicit_machine", "export", "deploy")


def test_the_card_export_and_deploy_name_no_machine():
    """What they need of the manipulator reaches them from its registration."""
    found = [o for module in CARD_MODULES
             for o in offences((REPOSITORY / "flexff" / "learning" / f"{module}.py").read_text(),
                               module)]
    assert not found, "\n".join(found)


def test_the_manipulator_is_the_implicit_machine():
    """Its registration gives the card's default outputs, its label levels and its part of the
    usage text."""
    implicit = implicit_machine()
    assert {k: [v.name for v in o] for k, o in implicit.outputs.items()} == {
        "forces": ["Fx_ff", "Fy_ff"], "currents": ["i1_ff", "i2_ff", "i3_ff"]}
    assert implicit.output_level(["i1_ff", "i2_ff", "i3_ff"]) == "currents"
    assert implicit.output_level(["x_ff"]) is None
    assert "(Fx_id, Fy_id); with linear_inputs" in CARD.metadata()["usage"]
    with pytest.raises(ValueError, match="already registered"):
        register_implicit_machine(replace(implicit, usage=""))
    assert implicit_machine() is implicit

