"""Evaluate a CasADi SX Function with torch operations, instruction by instruction.

The plant's kinematics and rigid-body dynamics are written once, in CasADi. To put them inside
a torch model (and from there into an ONNX graph) they are replayed here op by op on batched
tensors instead of being written a second time by hand: the SX Function's instruction list is
a straight-line program of scalar operations, and each scalar becomes a tensor of any shape.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import Any

import casadi as ca
import torch

_UNARY: dict[int, Callable[[torch.Tensor], torch.Tensor]] = {
    ca.OP_ASSIGN: lambda a: a,
    ca.OP_NEG: torch.neg,
    ca.OP_SQ: lambda a: a * a,
    ca.OP_TWICE: lambda a: 2 * a,
    ca.OP_SQRT: torch.sqrt,
    ca.OP_INV: torch.reciprocal,
    ca.OP_SIN: torch.sin,
    ca.OP_COS: torch.cos,
    ca.OP_TAN: torch.tan,
    ca.OP_ASIN: torch.asin,
    ca.OP_ACOS: torch.acos,
    ca.OP_ATAN: torch.atan,
    ca.OP_EXP: torch.exp,
    ca.OP_LOG: torch.log,
    ca.OP_TANH: torch.tanh,
    ca.OP_FABS: torch.abs,
    ca.OP_SIGN: torch.sign,
    ca.OP_FLOOR: torch.floor,
    ca.OP_CEIL: torch.ceil,
}
# arithmetic takes a Python float for either operand; the rest need tensors (see __call__)
_ARITHMETIC: dict[int, Callable[[torch.Tensor | float, torch.Tensor | float],
                                 torch.Tensor | float]] = {
    ca.OP_ADD: lambda a, b: a + b,
    ca.OP_SUB: lambda a, b: a - b,
    ca.OP_MUL: lambda a, b: a * b,
    ca.OP_DIV: lambda a, b: a / b,
    ca.OP_POW: lambda a, b: a ** b,
}
def atan2(y: torch.Tensor, x: torch.Tensor) -> torch.Tensor:
    """torch.atan2, but for float64 built from ops onnxruntime has float64 kernels for.

    onnxruntime implements Atan in float32 only. The float32 angle a0 is refined by one step:
    the remaining rotation's tangent, (y cos a0 - x sin a0) / (x cos a0 + y sin a0), is about
    1e-7 and equals that rotation to within 1e-21, so the result is exact to float64 precision.
    """
    if y.dtype != torch.float64:
        return torch.atan2(y, x)
    a0 = torch.atan2(y.float(), x.float()).double()
    c, s = torch.cos(a0), torch.sin(a0)
    return a0 + (y * c - x * s) / (x * c + y * s)


_BINARY: dict[int, Callable[[torch.Tensor, torch.Tensor], torch.Tensor]] = {
    ca.OP_ATAN2: atan2,
    ca.OP_FMIN: torch.minimum,
    ca.OP_FMAX: torch.maximum,
}
_OP_NAMES = {getattr(ca, n): n for n in dir(ca) if n.startswith("OP_")}


class TorchFunction:
    """A CasADi SX Function (dense vector inputs and outputs) evaluated on torch tensors.

    Call with one tensor per Function input, each shaped (..., n_i) with the Function input's
    length last; returns one tensor per output, shaped (..., m_j). Leading dimensions broadcast.
    """

    def __init__(self, function: ca.Function) -> None:
        if not function.is_a("SXFunction"):
            function = function.expand()
        for k in range(function.n_in()):
            if not function.sparsity_in(k).is_dense() or function.size2_in(k) != 1:
                raise ValueError(f"{function.name()}: input {k} must be a dense column vector")
        for k in range(function.n_out()):
            if not function.sparsity_out(k).is_dense() or function.size2_out(k) != 1:
                raise ValueError(f"{function.name()}: output {k} must be a dense column vector")
        self.name = function.name()
        self.n_out = [function.size1_out(k) for k in range(function.n_out())]
        self.n_in = [function.size1_in(k) for k in range(function.n_in())]
        self._program = [(function.instruction_id(k), function.instruction_input(k),
                          function.instruction_output(k),
                          function.instruction_constant(k)
                          if function.instruction_id(k) == ca.OP_CONST else None)
                         for k in range(function.n_instructions())]
        unknown = {op for op, *_ in self._program
                   if op not in _UNARY and op not in _BINARY and op not in _ARITHMETIC
                   and op not in (ca.OP_CONST, ca.OP_INPUT, ca.OP_OUTPUT)}
        if unknown:
            raise NotImplementedError(f"{self.name}: no torch translation for "
                                      f"{sorted(_OP_NAMES.get(op, str(op)) for op in unknown)}")

    def __call__(self, *inputs: torch.Tensor) -> list[torch.Tensor]:
        if len(inputs) != len(self.n_in):
            raise ValueError(f"{self.name} takes {len(self.n_in)} inputs, got {len(inputs)}")
        for k, (x, n) in enumerate(zip(inputs, self.n_in)):
            if x.shape[-1] != n:
                raise ValueError(f"{self.name}: input {k} must end in size {n}, got {x.shape}")
        like = inputs[0]
        work: dict[int, torch.Tensor | float] = {}
        outputs: list[list[Any]] = [[None] * m for m in self.n_out]  # set by OP_OUTPUT
        for op, args, res, constant in self._program:
            if op == ca.OP_CONST:
                if constant is None:
                    raise ValueError(f"{self.name}: a constant without a value")
                work[res[0]] = constant
            elif op == ca.OP_INPUT:
                work[res[0]] = inputs[args[0]][..., args[1]]
            elif op == ca.OP_OUTPUT:
                outputs[res[0]][res[1]] = work[args[0]]
            elif op in _ARITHMETIC:
                work[res[0]] = _ARITHMETIC[op](work[args[0]], work[args[1]])
            elif op in _UNARY:
                work[res[0]] = _UNARY[op](_tensor(work[args[0]], like))
            else:
                work[res[0]] = _BINARY[op](_tensor(work[args[0]], like),
                                           _tensor(work[args[1]], like))
        shape = torch.broadcast_shapes(*[x.shape[:-1] for x in inputs])
        return [torch.stack([_tensor(v, like).expand(shape) for v in out], dim=-1)
                for out in outputs]


def _tensor(value: torch.Tensor | float, like: torch.Tensor) -> torch.Tensor:
    if isinstance(value, torch.Tensor):
        return value
    return torch.tensor(value, dtype=like.dtype, device=like.device)


def frozen(function: ca.Function, fixed: Sequence[int], values: Sequence[Any]) -> ca.Function:
    """`function` with the inputs at positions `fixed` replaced by numeric `values` (an SX
    Function of the remaining inputs), so that constants fold into the expression graph."""
    symbols = [ca.SX.sym(function.name_in(k), function.sparsity_in(k))
               for k in range(function.n_in())]
    args: list[ca.SX | ca.DM] = list(symbols)
    for k, value in zip(fixed, values):
        args[k] = ca.DM(value)
    free = [k for k in range(function.n_in()) if k not in fixed]
    return ca.Function(function.name(), [symbols[k] for k in free], function.call(args),
                       [function.name_in(k) for k in free],
                       [function.name_out(k) for k in range(function.n_out())])
