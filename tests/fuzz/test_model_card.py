"""Fuzzing the card of an exported feedforward model (learning.model_card.read_card, which
`flexff fmu build learned-feedforward` and a run's learned feedforward read, and the training
range check of a run on it, controllers.training_range): a valid card's metadata with values
replaced by odd JSON and text, keys removed, and the graph's bytes mutated
(tests/fuzz/harness.py)."""

from __future__ import annotations

import itertools
import json
from pathlib import Path

import pytest
from hypothesis import example, given
from hypothesis import strategies as st
from onnx import TensorProto
from onnx import helper as oh

from flexff.controllers.features import feature_names
from flexff.controllers.training_range import training_range_excess
from flexff.cosim.references import build_reference
from flexff.fmu.errors import InputError
from flexff.learning.model_card import ModelCard, read_card
from flexff.plant.paths import Reference
from tests.fuzz.harness import check, fast, fuzz_seconds, run_for, slow
from tests.fuzz.mutations import mutated_bytes, odd_values

FEATURES = feature_names("compact")
CARD = ModelCard(feature_set="compact", input_kind="features", input_signals=FEATURES,
                 sample_rate_hz=250.0,
                 feature_range={"signals": FEATURES, "low": [-1.0] * 6, "high": [1.0] * 6})
METADATA = CARD.metadata()
_files = itertools.count()


def _model(metadata: dict[str, str]) -> bytes:
    """A graph of the card's sizes carrying `metadata`."""
    model = oh.make_model(oh.make_graph(
        [oh.make_node("Identity", ["x"], ["y"])], "card",
        [oh.make_tensor_value_info("x", TensorProto.DOUBLE, [1, len(FEATURES)])],
        [oh.make_tensor_value_info("y", TensorProto.DOUBLE, [1, 2])]),
        opset_imports=[oh.make_opsetid("", 13)])
    oh.set_model_props(model, metadata)
    return bytes(model.SerializeToString())


@st.composite
def metadata(draw: st.DrawFn) -> dict[str, str]:
    """The card's metadata with one to three values replaced (JSON of odd values, or odd text)
    or removed."""
    props = dict(METADATA)
    for _ in range(draw(st.integers(1, 3))):
        key = draw(st.sampled_from(sorted(METADATA)))
        value = draw(st.one_of(odd_values().map(json.dumps), st.text(max_size=12), st.none()))
        if value is None:
            props.pop(key, None)
        else:
            props[key] = value
    return props


models = st.one_of(metadata().map(_model), mutated_bytes(_model(METADATA)))


@pytest.fixture(scope="module")
def reference() -> Reference:
    return build_reference("circle", {"centre": (0.0, 0.0), "radius": 0.01, "turns": 1.0,
                                      "start_angle": 0.0, "duration": 0.5}, 1e-3)


def fuzz_card(folder: Path, data: bytes, reference: Reference) -> None:
    """The property for one model: its card read, and a run's training range check on it."""
    path = folder / f"card-{next(_files)}.onnx"
    path.write_bytes(data)
    if check(lambda: read_card(path)) is not None:
        check(lambda: training_range_excess(path, reference.signals(), 1e-3))
    path.unlink()


@fast()
@given(data=models)
# found by the fuzzer: a sample rate of 5e-324 Hz times the step underflowed to 0 (a
# ZeroDivisionError in controllers.learned_feedforward.model_period)
@example(data=_model({**METADATA, "sample_rate_hz": "5e-324"}))
def test_model_card_fast(tmp_path: Path, reference: Reference, data: bytes) -> None:
    fuzz_card(tmp_path, data, reference)


@pytest.mark.slow
def test_model_card_slow(tmp_path: Path, reference: Reference) -> None:
    @slow()
    @given(data=models)
    def fuzz_round(data: bytes) -> None:
        fuzz_card(tmp_path, data, reference)

    run_for(fuzz_seconds(), fuzz_round)


@pytest.mark.parametrize("feature_range", [{}, "x", {"signals": ["a"], "low": [0], "high": [1]}])
def test_feature_range_checked(tmp_path: Path, reference: Reference,
                               feature_range: object) -> None:
    """Found while writing this fuzzer: a feature_range of the wrong form was a KeyError,
    TypeError or IndexError in the training range check of every run on the model."""
    path = tmp_path / "card.onnx"
    path.write_bytes(_model({**METADATA, "feature_range": json.dumps(feature_range)}))
    with pytest.raises(InputError, match="metadata feature_range is not the range of the 6"):
        training_range_excess(path, reference.signals(), 1e-3)
