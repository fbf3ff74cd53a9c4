"""An ONNX graph planned for C (fmu.network_c): every tensor's fixed shape and element type, the
nodes that depend on constants only folded into constants, the others kept in graph order.

Shapes are fixed: a dynamic first dimension of an input is the time axis of flexff's exports and
becomes 1 (one row per call, as the FMU calls the graph); any other dynamic input dimension is
refused. With the inputs' shapes fixed, onnx's reference evaluator runs the graph once on zeros,
which gives every tensor's shape and the value of every folded one (a node is folded when all
its inputs are constants, or it is Shape or Size of any tensor; random operators never are).
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np
import onnx
from onnx import TensorProto
from onnx.reference import ReferenceEvaluator

from flexff.fmu.errors import InputError

# ONNX element types the generated C computes with, and their C types
C_TYPES: dict[int, str] = {TensorProto.FLOAT: "float", TensorProto.DOUBLE: "double",
                           TensorProto.INT64: "int64_t", TensorProto.INT32: "int32_t",
                           TensorProto.BOOL: "uint8_t"}
NUMPY_TYPES: dict[str, int] = {"float32": TensorProto.FLOAT, "float64": TensorProto.DOUBLE,
                               "int64": TensorProto.INT64, "int32": TensorProto.INT32,
                               "bool": TensorProto.BOOL}
ALWAYS_FOLDED = ("Shape", "Size")  # static shapes: their result is known before any call
NEVER_FOLDED = ("RandomNormal", "RandomNormalLike", "RandomUniform", "RandomUniformLike",
                "Multinomial", "Bernoulli")


@dataclass(frozen=True)
class Tensor:
    """A tensor of the planned graph; `value` for a constant (an initializer or folded)."""

    name: str
    dtype: int  # onnx.TensorProto element type
    shape: tuple[int, ...]
    value: np.ndarray | None = None

    @property
    def size(self) -> int:
        return int(np.prod(self.shape, dtype=np.int64))

    @property
    def ctype(self) -> str:
        return C_TYPES[self.dtype]


@dataclass(frozen=True)
class Plan:
    """The graph `name` ready to be written as C: its inputs and outputs in graph order, the
    nodes left to compute (in order) and every tensor they read or write."""

    name: str
    inputs: tuple[Tensor, ...]
    outputs: tuple[Tensor, ...]
    nodes: tuple[onnx.NodeProto, ...]
    tensors: Mapping[str, Tensor]
    metadata: Mapping[str, str]


def plan_graph(model: onnx.ModelProto, name: str) -> Plan:
    """The Plan of `model` (named `name` in messages); InputError (one line naming the tensor
    or node) for a graph that cannot have fixed shapes or holds what C cannot compute."""
    model = _fixed_copy(model, name)
    graph = model.graph
    if model.functions or any(o.domain not in ("", "ai.onnx") for o in model.opset_import):
        raise InputError(f"{name}: the graph uses local functions or operator domains other "
                         f"than ai.onnx ({[o.domain for o in model.opset_import]}); the C "
                         f"network supports the standard operators only")
    initializers = {t.name for t in graph.initializer}
    inputs = [v for v in graph.input if v.name not in initializers]
    feeds = {v.name: np.zeros(_input_shape(v, name), dtype=onnx.helper.tensor_dtype_to_np_dtype(
        v.type.tensor_type.elem_type)) for v in inputs}
    try:
        with np.errstate(all="ignore"):
            values = ReferenceEvaluator(model).run(None, feeds, intermediate=True)
    except Exception as exc:  # the reference evaluator raises whatever its operators raise
        raise InputError(f"{name}: onnx's reference evaluator cannot run the graph with fixed "
                         f"shapes: {exc}") from exc
    assert isinstance(values, dict)
    constants = set(initializers)
    nodes = []
    for node in graph.node:
        given = [n for n in node.input if n]
        if node.op_type not in NEVER_FOLDED and (
                node.op_type in ALWAYS_FOLDED or all(n in constants for n in given)):
            constants.update(node.output)
        else:
            nodes.append(node)
    used = {n for node in nodes for n in [*node.input, *node.output] if n}
    used |= {v.name for v in [*inputs, *graph.output]}
    missing = sorted(used - set(values))  # e.g. an output that no node computes
    if missing:
        raise InputError(f"{name}: tensor {missing[0]!r} is neither an input, an initializer "
                         f"nor computed by a node: not a valid ONNX graph")
    tensors = {n: _tensor(n, values[n], n in constants, name) for n in sorted(used)}
    return Plan(name, tuple(tensors[v.name] for v in inputs),
                tuple(tensors[v.name] for v in graph.output), tuple(nodes), tensors,
                {p.key: p.value for p in model.metadata_props})


def _fixed_copy(model: onnx.ModelProto, name: str) -> onnx.ModelProto:
    """A copy of `model` with the dynamic first dimension of every input set to 1."""
    fixed = onnx.ModelProto()
    fixed.CopyFrom(model)
    for value in fixed.graph.input:
        for axis, dim in enumerate(value.type.tensor_type.shape.dim):
            if not dim.HasField("dim_value"):
                if axis > 0:
                    raise InputError(f"{name}: input {value.name!r} has the dynamic dimension "
                                     f"{dim.dim_param or '?'!r} at axis {axis}; the C network "
                                     f"needs fixed shapes (only a first, time axis may be "
                                     f"dynamic: it is one row per call)")
                dim.dim_value = 1
    return fixed


def _input_shape(value: onnx.ValueInfoProto, name: str) -> list[int]:
    tensor = value.type.tensor_type
    if not value.type.HasField("tensor_type") or tensor.elem_type not in C_TYPES \
            or not tensor.HasField("shape"):
        raise InputError(f"{name}: input {value.name!r} must be a tensor of a known shape and "
                         f"one of the types {_type_names()}")
    shape = [d.dim_value for d in tensor.shape.dim]
    if any(d < 0 for d in shape):
        raise InputError(f"{name}: input {value.name!r} has a negative dimension in its shape "
                         f"{shape}: not a valid ONNX graph")
    return shape


def _tensor(tensor: str, value: object, constant: bool, name: str) -> Tensor:
    array = np.asarray(value)
    dtype = NUMPY_TYPES.get(array.dtype.name)
    if dtype is None:
        raise InputError(f"{name}: tensor {tensor!r} holds {array.dtype.name}; the C network "
                         f"computes with {_type_names()} only")
    return Tensor(tensor, dtype, tuple(int(d) for d in array.shape),
                  array.copy() if constant else None)


def _type_names() -> str:
    return ", ".join(TensorProto.DataType.Name(t).lower() for t in C_TYPES)
