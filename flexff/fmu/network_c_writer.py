"""The C text of a planned graph as it is written (fmu.network_c): which C name holds each
tensor, the constants as `static const` arrays, and the buffers of the work struct.

Every tensor a node computes gets a buffer `w->tK` in the work struct (allocated once by the
caller), read through a `const` pointer `tK` declared after its node; a node that only
reinterprets its input (Reshape, Squeeze, ...) makes its output another name of the same
pointer. A constant of one element is written into the expressions as a literal.
"""

from __future__ import annotations

import math

import numpy as np
import onnx
from onnx import TensorProto

from flexff.fmu.errors import InputError
from flexff.fmu.network_plan import C_TYPES, Plan, Tensor

PER_LINE = 8  # values per line of a constant array


class Writer:
    """The pieces of the C file of `plan` while the nodes are written."""

    def __init__(self, plan: Plan) -> None:
        self.plan = plan
        self.pointers: dict[str, str] = {}  # tensor -> C pointer expression
        self.constants: list[str] = []  # static const declarations
        self.fields: list[str] = []  # work struct members
        self.fresh: list[tuple[str, str]] = []  # (C type, pointer) written by the current node
        for k, tensor in enumerate(plan.inputs):
            self.pointers[tensor.name] = f"in{k}"

    def tensor(self, name: str) -> Tensor:
        return self.plan.tensors[name]

    def value(self, node: onnx.NodeProto, name: str, what: str) -> np.ndarray:
        """The value of the constant input `name` of `node`; InputError if it is computed."""
        value = self.tensor(name).value
        if value is None:
            raise refuse(node, f"its {what} ({name!r}) must be a constant")
        return value

    def read(self, name: str) -> str:
        """A C expression of the pointer to the tensor's first element."""
        if name not in self.pointers:
            tensor = self.tensor(name)
            assert tensor.value is not None, f"{name} is read before it is computed"
            self.pointers[name] = self.array(tensor.value, tensor.dtype)
        return self.pointers[name]

    def element(self, name: str, index: str) -> str:
        """A C expression of the tensor's element at `index` (a literal for a scalar constant)."""
        tensor = self.tensor(name)
        if tensor.value is not None and tensor.size == 1:
            return literal(tensor.value.ravel()[0], tensor.dtype)
        return f"{self.read(name)}[{index}]"

    def array(self, values: np.ndarray, dtype: int) -> str:
        """A new static const array of `values`; its C name."""
        name = f"c{len(self.constants)}"
        flat = [literal(v, dtype) for v in np.asarray(values).ravel()] or ["0"]
        lines = [", ".join(flat[i:i + PER_LINE]) for i in range(0, len(flat), PER_LINE)]
        body = ",\n    ".join(lines)
        self.constants.append(f"static const {C_TYPES[dtype]} {name}[{len(flat)}] = {{\n"
                              f"    {body}}};")
        return name

    def buffer(self, ctype: str, size: int) -> str:
        """A new member of the work struct of `size` elements; its C expression."""
        name = f"t{len(self.fields)}"
        self.fields.append(f"{ctype} {name}[{max(size, 1)}];")
        return f"w->{name}"

    def output(self, name: str) -> str:
        """The work buffer the node computing tensor `name` writes (read as `tK` after it)."""
        tensor = self.tensor(name)
        target = self.buffer(tensor.ctype, tensor.size)
        self.bind(name, target)
        return target

    def bind(self, name: str, target: str) -> None:
        """Tensor `name` is in the work buffer `target` once the current node has run."""
        self.pointers[name] = target.removeprefix("w->")
        self.fresh.append((self.tensor(name).ctype, self.pointers[name]))

    def alias(self, name: str, source: str) -> list[str]:
        """Tensor `name` is tensor `source`'s elements under another shape: the same pointer."""
        self.pointers[name] = self.read(source)
        return []

    def declarations(self) -> list[str]:
        """The `const` pointers to the work buffers the current node wrote; the next node
        starts."""
        lines = [f"const {ctype} *{pointer} = w->{pointer};" for ctype, pointer in self.fresh]
        self.fresh = []
        return lines


def literal(value: object, dtype: int) -> str:
    """`value` as a C literal of the element type `dtype`, exact: the shortest decimal that
    reads back as the same float32 (numpy's) or float64 (Python's)."""
    if dtype == TensorProto.BOOL:
        return "1" if bool(value) else "0"
    if dtype in (TensorProto.INT64, TensorProto.INT32):
        number = int(value)  # type: ignore[call-overload]
        return f"{number}LL" if dtype == TensorProto.INT64 else str(number)
    number = float(value)  # type: ignore[arg-type]
    single = dtype == TensorProto.FLOAT
    if math.isnan(number):
        return "NAN"
    if math.isinf(number):
        text = "INFINITY" if number > 0 else "-INFINITY"
        return text if single else f"(double){text}"
    text = str(np.float32(number)) if single else repr(number)
    if not any(c in text for c in ".e"):
        text += ".0"
    return text + ("f" if single else "")


def refuse(node: onnx.NodeProto, why: str) -> InputError:
    """The one-line error for a node the C network cannot compute."""
    return InputError(f"node {node.name or node.output[0]!r} ({node.op_type}): {why}")
