"""Every operator of the C network (fmu.network_c_ops.OPERATORS) against onnxruntime: a graph
of one node per case, random inputs, broadcasting, attributes and constant operands as the
operator allows; float results to 1e-5 of the largest, the others exactly."""

import numpy as np
import onnx
import onnxruntime as ort
import pytest
from onnx import TensorProto, numpy_helper
from onnx import helper as oh

from flexff.fmu.network_c import supported_operators
from tests.fmu.test_network_c import CNetwork

F, D, B, I64 = TensorProto.FLOAT, TensorProto.DOUBLE, TensorProto.BOOL, TensorProto.INT64
X = ("x", F, (2, 3, 4))  # the common input
UNARY = ["Abs", "Atan", "Ceil", "Cos", "Cosh", "Erf", "Exp", "Floor", "Neg", "Relu", "Round",
         "Sigmoid", "Sign", "Sin", "Sinh", "Softplus", "Tan", "Tanh"]
POSITIVE = ["Log", "Sqrt", "Reciprocal"]  # inputs in (0.5, 2)
UNIT = ["Acos", "Asin"]  # inputs in (-1, 1)
COMPARISONS = ["Equal", "Greater", "Less", "GreaterOrEqual", "LessOrEqual"]


def case(op, inputs, outputs, constants=(), **attributes):
    """(op, inputs (name, type, shape), outputs (name, type), constants {name: array},
    attributes) of a one-node graph; constants are inputs with a value (initializers)."""
    return op, list(inputs), list(outputs), dict(constants), attributes


def const(values, dtype=np.float32):
    return np.asarray(values, dtype=dtype)


CASES = {
    **{op: case(op, [X], [("y", F)]) for op in UNARY + POSITIVE + UNIT},
    "LeakyRelu": case("LeakyRelu", [X], [("y", F)], alpha=0.2),
    "Identity": case("Identity", [X], [("y", F)]),
    "Add": case("Add", [X, ("b", F, (4,))], [("y", F)]),
    "Sub": case("Sub", [X, ("b", F, (3, 1))], [("y", F)]),
    "Mul": case("Mul", [("a", F, (2, 1, 4)), ("b", F, (3, 1))], [("y", F)]),
    "Div": case("Div", [X, ("b", F, (2, 3, 4))], [("y", F)]),
    "Div-double": case("Div", [("a", D, (3,)), ("b", D, (1,))], [("y", D)]),
    "Pow": case("Pow", [X, ("b", F, (4,))], [("y", F)]),
    "Max": case("Max", [X, ("b", F, (4,)), ("c", F, (3, 1))], [("y", F)]),
    "Min": case("Min", [X, ("b", F, (4,))], [("y", F)]),
    "Sum": case("Sum", [X, ("b", F, (4,)), ("c", F, (2, 3, 4))], [("y", F)]),
    **{op: case(op, [X, ("b", F, (3, 1))], [("y", B)]) for op in COMPARISONS},
    **{op: case(op, [("a", B, (2, 3)), ("b", B, (3,))], [("y", B)]) for op in ("And", "Or",
                                                                                "Xor")},
    "Not": case("Not", [("a", B, (2, 3))], [("y", B)]),
    "IsNaN": case("IsNaN", [("a", F, (4,))], [("y", B)]),
    "IsInf": case("IsInf", [("a", F, (4,))], [("y", B)], detect_negative=0),
    "Where": case("Where", [("c", B, (3, 1)), X, ("b", F, (4,))], [("y", F)]),
    "Cast": case("Cast", [X], [("y", D)], to=D),
    "Cast-bool": case("Cast", [X], [("y", B)], to=B),
    "Clip": case("Clip", [X, ("lo", F, ()), ("hi", F, ())], [("y", F)],
                 {"lo": const(-0.5), "hi": const(0.7)}),
    "Reshape": case("Reshape", [X, ("s", I64, (2,))], [("y", F)], {"s": const([4, 6], np.int64)}),
    "Flatten": case("Flatten", [X], [("y", F)], axis=2),
    "Squeeze": case("Squeeze", [("a", F, (2, 1, 4)), ("ax", I64, (1,))], [("y", F)],
                    {"ax": const([1], np.int64)}),
    "Unsqueeze": case("Unsqueeze", [X, ("ax", I64, (1,))], [("y", F)],
                      {"ax": const([0], np.int64)}),
    "Transpose": case("Transpose", [X], [("y", F)], perm=[2, 0, 1]),
    "Slice": case("Slice", [X, ("s", I64, (2,)), ("e", I64, (2,)), ("ax", I64, (2,)),
                            ("st", I64, (2,))], [("y", F)],
                  {"s": const([-1, 0], np.int64), "e": const([-10, 3], np.int64),
                   "ax": const([2, 1], np.int64), "st": const([-2, 2], np.int64)}),
    "Gather": case("Gather", [X, ("i", I64, (3,))], [("y", F)],
                   {"i": const([2, 0, -1], np.int64)}, axis=1),
    "Expand": case("Expand", [("a", F, (3, 1)), ("s", I64, (3,))], [("y", F)],
                   {"s": const([2, 3, 4], np.int64)}),
    "Concat": case("Concat", [X, ("b", F, (2, 2, 4))], [("y", F)], axis=1),
    "ReduceSum": case("ReduceSum", [X, ("ax", I64, (1,))], [("y", F)],
                      {"ax": const([1], np.int64)}, keepdims=0),
    "ReduceMean": case("ReduceMean", [X], [("y", F)], axes=[0, 2]),
    "ReduceMax": case("ReduceMax", [X], [("y", F)], axes=[2], keepdims=1),
    "ReduceMin": case("ReduceMin", [X], [("y", F)]),
    "ReduceProd": case("ReduceProd", [X], [("y", F)], axes=[-1]),
    "CumSum": case("CumSum", [X, ("ax", I64, ())], [("y", F)], {"ax": const(1, np.int64)}),
    "CumSum-reverse": case("CumSum", [X, ("ax", I64, ())], [("y", F)],
                           {"ax": const(2, np.int64)}, exclusive=1, reverse=1),
    "MatMul": case("MatMul", [X, ("w", F, (4, 5))], [("y", F)]),
    "MatMul-weights": case("MatMul", [X, ("w", F, (4, 5))], [("y", F)], {"w": "random"}),
    "MatMul-batched": case("MatMul", [X, ("w", F, (2, 4, 5))], [("y", F)]),
    "Gemm": case("Gemm", [("a", F, (3, 4)), ("w", F, (5, 4)), ("c", F, (5,))], [("y", F)],
                 {"w": "random"}, transB=1, alpha=0.5, beta=2.0),
    "Gemm-transposed": case("Gemm", [("a", F, (4, 3)), ("w", F, (4, 5)), ("c", F, (3, 1))],
                            [("y", F)], transA=1),
    "Conv": case("Conv", [("a", F, (2, 3, 10)), ("w", F, (4, 3, 3)), ("b", F, (4,))],
                 [("y", F)], {"w": "random", "b": "random"}, pads=[1, 2], strides=[2],
                 dilations=[2]),
    "Conv-groups": case("Conv", [("a", F, (1, 4, 7)), ("w", F, (6, 2, 2))], [("y", F)],
                        {"w": "random"}, group=2),
    "LSTM": case("LSTM", [("a", F, (3, 2, 4)), ("W", F, (1, 20, 4)), ("R", F, (1, 20, 5)),
                          ("B", F, (1, 40)), ("", F, ()), ("h", F, (1, 2, 5)),
                          ("c", F, (1, 2, 5))],
                 [("y", F), ("hn", F), ("cn", F)],
                 {"W": "random", "R": "random", "B": "random"}, hidden_size=5),
}


def inputs_for(op, inputs, rng):
    """Random values of each input: positive or within (-1, 1) where the operator needs it."""
    values = {}
    for name, dtype, shape in inputs:
        if not name:
            continue
        if dtype == B:
            values[name] = rng.random(shape) < 0.5
        elif op in ("IsNaN", "IsInf"):
            values[name] = np.array([np.nan, np.inf, -np.inf, 1.0], dtype=np.float32)
        elif op in POSITIVE or (op == "Pow" and name == "x"):
            values[name] = rng.uniform(0.5, 2.0, shape).astype(np.float32)
        elif op in UNIT:
            values[name] = rng.uniform(-0.95, 0.95, shape).astype(np.float32)
        else:
            values[name] = (2 * rng.standard_normal(shape)).astype(
                np.float64 if dtype == D else np.float32)
    return values


def one_node_model(key, rng):
    op, inputs, outputs, constants, attributes = CASES[key]
    values = inputs_for(op, inputs, rng)
    initializers = []
    for name, value in constants.items():
        if isinstance(value, str):
            value = values[name]
        initializers.append(numpy_helper.from_array(np.asarray(value), name))
        values.pop(name, None)
    node = oh.make_node(op, [name for name, _, _ in inputs], [name for name, _ in outputs],
                        name=key, **attributes)
    graph = oh.make_graph(
        [node], key, [oh.make_tensor_value_info(n, t, s) for n, t, s in inputs
                      if n and n not in constants],
        [oh.make_tensor_value_info(n, t, None) for n, t in outputs], initializers)
    model = oh.make_model(graph, opset_imports=[oh.make_opsetid("", 17)])
    return model, values


@pytest.mark.parametrize("key", list(CASES))
def test_each_operator_equals_onnxruntime(key, rng, tmp_path):
    model, feeds = one_node_model(key, rng)
    path = tmp_path / f"{key}.onnx"
    onnx.save(model, str(path))
    expected = ort.InferenceSession(str(path), providers=["CPUExecutionProvider"]).run(
        None, feeds)
    got = CNetwork(path, tmp_path).run(feeds)
    for e, g in zip(expected, got):
        assert g.shape == e.shape and g.dtype == e.dtype
        if e.dtype.kind == "f":
            assert np.abs(g - e).max() <= 1e-5 * max(np.abs(e).max(), 1e-30), key
        else:
            assert np.array_equal(g, e), key


def test_every_operator_has_a_case():
    assert sorted({op for op, *_ in CASES.values()}) == supported_operators()
