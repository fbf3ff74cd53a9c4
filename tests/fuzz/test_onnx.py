"""Fuzzing ONNX graphs (fmu.onnx_fmu.onnx_system: `flexff fmu build onnx` up to the compiler,
the graph read, wrapped and generated as C or loaded in onnxruntime): small graphs built with
onnx.helper, valid ones and ones with shapes, types, names, metadata, opsets and nodes
edited, their bytes mutated, and garbage (tests/fuzz/harness.py)."""

from __future__ import annotations

import copy
import itertools
import json
from pathlib import Path

import numpy as np
import onnx
import pytest
from hypothesis import given
from hypothesis import strategies as st
from onnx import TensorProto, numpy_helper
from onnx import helper as oh

from flexff.fmu.errors import InputError
from flexff.fmu.onnx_fmu import onnx_system
from tests.fuzz.harness import check, fast, fuzz_seconds, run_for, slow
from tests.fuzz.mutations import garbage, mutated_bytes

UNARY = ["Relu", "Tanh", "Sigmoid", "Identity", "Neg", "Abs"]
BINARY = ["Add", "Mul", "Sub"]
DTYPES = {TensorProto.FLOAT: np.float32, TensorProto.DOUBLE: np.float64}
ODD_NAMES = ["", "x", "y", "h", "flexff/inputs", "flexff/graph/x", "x_out", "a b", "é"]
ODD_JSON = ["[]", "[{}]", "null", "{", '["a"]', "[1]", '[""]', '[{"input": "h"}]',
            '[{"input": "h", "output": "h_out"}]', '[{"input": "x", "output": "y"}]',
            json.dumps(["u"] * 10_000), '"text"', "1e999"]
_files = itertools.count()


@st.composite
def graphs(draw: st.DrawFn) -> onnx.ModelProto:
    """A valid graph: x (1, n) through a chain of elementwise and MatMul nodes to y, with or
    without a float32 state h -> h_out and metadata naming the elements."""
    dtype = draw(st.sampled_from(sorted(DTYPES)))
    width = draw(st.integers(1, 4))
    nodes, constants, current = [], [], "x"
    inputs = [oh.make_tensor_value_info("x", dtype, [1, width])]
    for k in range(draw(st.integers(0, 4))):
        op = draw(st.sampled_from([*UNARY, *BINARY, "MatMul"]))
        out = f"t{k}"
        if op in UNARY:
            nodes.append(oh.make_node(op, [current], [out]))
        else:
            columns = draw(st.integers(1, 4)) if op == "MatMul" else width
            shape = (width, columns) if op == "MatMul" else (1, width)
            constants.append(numpy_helper.from_array(
                np.full(shape, 0.5, DTYPES[dtype]), f"c{k}"))
            nodes.append(oh.make_node(op, [current, f"c{k}"], [out]))
            width = columns
        current = out
    nodes.append(oh.make_node("Identity", [current], ["y"]))
    outputs = [oh.make_tensor_value_info("y", dtype, [1, width])]
    meta = {}
    if draw(st.booleans()):
        nodes.append(oh.make_node("Tanh", ["h"], ["h_out"]))
        inputs.append(oh.make_tensor_value_info("h", TensorProto.FLOAT, [1, 2]))
        outputs.append(oh.make_tensor_value_info("h_out", TensorProto.FLOAT, [1, 2]))
        meta["state"] = json.dumps([{"input": "h", "output": "h_out"}])
    if draw(st.booleans()):
        meta["output_signals"] = json.dumps([f"out{k}" for k in range(width)])
    model = oh.make_model(oh.make_graph(nodes, "fuzz", inputs, outputs, constants),
                          opset_imports=[oh.make_opsetid("", draw(st.integers(13, 17)))])
    model.ir_version = 8
    oh.set_model_props(model, meta)
    return model


@st.composite
def edited(draw: st.DrawFn, model: onnx.ModelProto) -> onnx.ModelProto:
    """`model` with one to three edits of its shapes, types, names, metadata, versions and
    nodes."""
    model = copy.deepcopy(model)
    graph = model.graph
    for _ in range(draw(st.integers(1, 3))):
        edit = draw(st.sampled_from(["dim", "dtype", "name", "drop", "meta", "opset", "ir",
                                     "op"]))
        values = [*graph.input, *graph.output]
        value = draw(st.sampled_from(values)) if values else onnx.ValueInfoProto()
        if edit == "dim" and value.type.tensor_type.shape.dim:
            dim = draw(st.sampled_from(list(value.type.tensor_type.shape.dim)))
            size = draw(st.sampled_from([0, -1, 10**9, 2**40, "N", None]))
            if isinstance(size, int):
                dim.dim_value = size
            elif size is None:
                value.type.tensor_type.shape.dim.remove(dim)
            else:
                dim.dim_param = size
        elif edit == "dtype":
            value.type.tensor_type.elem_type = draw(st.integers(0, 20))
        elif edit == "name":
            value.name = draw(st.sampled_from(ODD_NAMES))
        elif edit == "drop":
            for part in (graph.input, graph.output, graph.node):
                if len(part) and draw(st.booleans()):
                    del part[draw(st.integers(0, len(part) - 1))]
        elif edit == "meta":
            key = draw(st.sampled_from(["state", "input_signals", "output_signals"]))
            oh.set_model_props(model, {**{p.key: p.value for p in model.metadata_props},
                                       key: draw(st.sampled_from(ODD_JSON))})
        elif edit == "opset":
            model.opset_import[0].version = draw(st.sampled_from([0, 1, 5, 6, 100]))
        elif edit == "ir":
            model.ir_version = draw(st.sampled_from([0, 1, 3, 100]))
        elif graph.node:
            node = draw(st.sampled_from(list(graph.node)))
            node.op_type = draw(st.sampled_from(["Foo", "Gemm", "Concat", "Loop", *UNARY]))
    return model


models = st.one_of(
    graphs().map(lambda m: m.SerializeToString()),
    graphs().flatmap(edited).map(lambda m: m.SerializeToString()),
    graphs().map(lambda m: m.SerializeToString()).flatmap(mutated_bytes),
    garbage())


def fuzz_onnx(folder: Path, data: bytes, runtime: str, every: int) -> None:
    """The property for one ONNX file, as an FMU's System run by `runtime`."""
    path = folder / f"fuzz-{next(_files)}.onnx"
    path.write_bytes(data)
    check(lambda: onnx_system(path, every=every, runtime=runtime))
    path.unlink()


@pytest.fixture
def cache(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> Path:
    """A fresh build cache, where the adapter graphs are written."""
    monkeypatch.setenv("FLEXFF_CACHE", str(tmp_path / "cache"))
    return tmp_path


examples = dict(data=models, runtime=st.sampled_from(["c", "onnxruntime"]),
                every=st.sampled_from([1, 4]))


@fast()
@given(**examples)
def test_onnx_fast(cache: Path, data: bytes, runtime: str, every: int) -> None:
    fuzz_onnx(cache, data, runtime, every)


@pytest.mark.slow
def test_onnx_slow(cache: Path) -> None:
    @slow()
    @given(**examples)
    def fuzz_round(data: bytes, runtime: str, every: int) -> None:
        fuzz_onnx(cache, data, runtime, every)

    run_for(fuzz_seconds(), fuzz_round)


def _model(nodes: list[onnx.NodeProto], inputs: list[onnx.ValueInfoProto],
           outputs: list[onnx.ValueInfoProto], meta: dict[str, str] | None = None
           ) -> onnx.ModelProto:
    """A regression case's graph: opset 13, IR version 8, its metadata `meta`."""
    model = oh.make_model(oh.make_graph(nodes, "fuzz", inputs, outputs),
                          opset_imports=[oh.make_opsetid("", 13)])
    model.ir_version = 8
    oh.set_model_props(model, meta or {})
    return model


def _refused(path: Path, data: bytes, message: str) -> None:
    """The ONNX file of bytes `data` at `path` is refused by onnx_system with `message`."""
    path.write_bytes(data)
    with pytest.raises(InputError, match=message):
        onnx_system(path, runtime="c")


def test_output_no_node_computes(cache: Path) -> None:
    """Found by the fuzzer: a graph output that no node computes (here one of the wrapper's
    convention, read as it is) was a KeyError in the C network's plan (fmu.network_plan);
    now one line naming the tensor."""
    model = _model([oh.make_node("Identity", ["x"], ["y"])],
                   [oh.make_tensor_value_info("x", TensorProto.DOUBLE, [1, 1])],
                   [oh.make_tensor_value_info("h", TensorProto.DOUBLE, [1, 1])])
    _refused(cache / "orphan.onnx", model.SerializeToString(),
             "tensor 'h' is neither an input")


def test_metadata_key_not_utf8(cache: Path) -> None:
    """Found by the fuzzer: a metadata key of bytes that are not UTF-8 (protobuf reads them
    as bytes) was a UnicodeDecodeError while wrapping the graph; now one line."""
    model = _model([oh.make_node("Relu", ["x"], ["y"])],
                   [oh.make_tensor_value_info("x", TensorProto.FLOAT, [1, 1])],
                   [oh.make_tensor_value_info("y", TensorProto.FLOAT, [1, 1])],
                   {"output_signals": '["out0"]'})
    data = model.SerializeToString().replace(b"output_signals", b"\x80utput_signals")
    _refused(cache / "bytes.onnx", data, r"StringStringEntryProto\.key is not UTF-8 text")


def test_state_of_negative_size(cache: Path) -> None:
    """Found by the fuzzer: a state input of dimension -1 was a ValueError from numpy in the
    C network's plan; now one line naming the input."""
    model = _model(
        [oh.make_node("Identity", ["x"], ["y"]), oh.make_node("Tanh", ["h"], ["h_out"])],
        [oh.make_tensor_value_info("x", TensorProto.DOUBLE, [1, 1]),
         oh.make_tensor_value_info("h", TensorProto.FLOAT, [-1, 2])],
        [oh.make_tensor_value_info("y", TensorProto.DOUBLE, [1, 1]),
         oh.make_tensor_value_info("h_out", TensorProto.FLOAT, [-1, 2])],
        {"state": json.dumps([{"input": "h", "output": "h_out"}])})
    _refused(cache / "negative.onnx", model.SerializeToString(),
             "input 'h' has a negative dimension")


def test_undefined_element_type(cache: Path) -> None:
    """Found by the fuzzer: an input of element type 29, which ONNX does not define, was a
    ValueError from protobuf while naming the type; now one line naming the input."""
    model = _model([oh.make_node("Identity", ["x"], ["y"])],
                   [oh.make_tensor_value_info("x", TensorProto.DOUBLE, [1, 1])],
                   [oh.make_tensor_value_info("y", TensorProto.DOUBLE, [1, 1])])
    model.graph.input[0].type.tensor_type.elem_type = 29
    _refused(cache / "undefined.onnx", model.SerializeToString(),
             "input 'x' holds the undefined element type 29")
