"""The C of each ONNX operator the C network computes (fmu.network_c), one function per kind.

Each takes the Writer and the node and returns the C lines that compute the node's outputs
from its inputs, all shapes fixed (fmu.network_plan). Elementwise operators broadcast as
numpy does; data movement (Slice, Transpose, Gather, Expand) is an index map computed here,
written as block copies where it has runs, else as a table; the heavy operators call the
kernels of c/net_kernels.h. `OPERATORS` lists what is supported: a node of another kind,
or of a supported kind with attributes outside what is written here, is refused by name.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
import onnx
from onnx import TensorProto
from onnx import helper as oh

from flexff.fmu.network_c_writer import Writer, literal, refuse

Emitter = Callable[[Writer, onnx.NodeProto], list[str]]
FLOATS = (TensorProto.FLOAT, TensorProto.DOUBLE)
MAX_BLOCKS = 8  # block copies written out one by one before an index table is used


def attributes(node: onnx.NodeProto) -> dict[str, object]:
    return {a.name: oh.get_attribute_value(a) for a in node.attribute}


def _math(ctype: str, function: str) -> str:
    """The libm function of the C type: sinf for float, sin for double."""
    return function + ("f" if ctype == "float" else "")


def _loops(out_shape: tuple[int, ...], shapes: list[tuple[int, ...]]
           ) -> tuple[list[str], str, list[str], int]:
    """Loops over the elements of `out_shape`: the opening lines, the output's index, each
    input's index (numpy broadcasting) and the number of braces to close."""
    size = int(np.prod(out_shape, dtype=np.int64))
    rank = len(out_shape)
    same = [(1,) * (rank - len(s)) + s == out_shape for s in shapes]
    if all(equal or int(np.prod(s)) == 1 for equal, s in zip(same, shapes)):
        return ([f"for (int i = 0; i < {size}; i++) {{"], "i",
                ["i" if equal else "0" for equal in same], 1)
    opening = [f"for (int i{d} = 0; i{d} < {n}; i{d}++) {{" for d, n in enumerate(out_shape)]

    def index(shape: tuple[int, ...], strides_of: tuple[int, ...]) -> str:
        padded = (1,) * (rank - len(shape)) + shape
        strides = (0,) * (rank - len(shape)) + strides_of
        terms = [f"i{d}" if strides[d] == 1 else f"i{d} * {strides[d]}"
                 for d in range(rank) if padded[d] != 1 and strides[d] != 0]
        return " + ".join(terms) or "0"

    def strides(shape: tuple[int, ...]) -> tuple[int, ...]:
        return tuple(int(np.prod(shape[d + 1:], dtype=np.int64)) for d in range(len(shape)))

    return (opening, index(out_shape, strides(out_shape)),
            [index(s, strides(s)) for s in shapes], rank)


def _map(w: Writer, node: onnx.NodeProto, inputs: list[str],
         expression: Callable[[list[str]], str]) -> list[str]:
    """out[...] = expression(the inputs' elements), broadcast."""
    out = node.output[0]
    target = w.output(out)
    opening, out_index, indices, depth = _loops(w.tensor(out).shape,
                                                [w.tensor(n).shape for n in inputs])
    elements = [w.element(n, i) for n, i in zip(inputs, indices)]
    return [*opening, f"    {target}[{out_index}] = {expression(elements)};", "}" * depth]


def _float_input(w: Writer, node: onnx.NodeProto) -> str:
    """The C type of the node's first input; InputError unless it is float or double."""
    ctype = w.tensor(node.input[0]).ctype
    if w.tensor(node.input[0]).dtype not in FLOATS:
        raise refuse(node, f"supported on float32 and float64 only, not {ctype}")
    return ctype


def _unary(template: str, float_only: bool = True) -> Emitter:
    """An elementwise operator of one input: `template` with {x}, {T} (C type), {f} (libm
    suffix)."""
    def emit(w: Writer, node: onnx.NodeProto) -> list[str]:
        ctype = _float_input(w, node) if float_only else w.tensor(node.input[0]).ctype
        suffix = "f" if ctype == "float" else ""
        return _map(w, node, [node.input[0]],
                    lambda e: template.format(x=e[0], T=ctype, f=suffix))
    return emit


def _binary(template: str) -> Emitter:
    def emit(w: Writer, node: onnx.NodeProto) -> list[str]:
        ctype = w.tensor(node.input[0]).ctype
        return _map(w, node, list(node.input[:2]),
                    lambda e: template.format(a=e[0], b=e[1], T=ctype,
                                              f="f" if ctype == "float" else ""))
    return emit


def _variadic(template: str) -> Emitter:
    """Max, Min, Sum of any number of inputs: `template` with {a}, {b} folded left."""
    def emit(w: Writer, node: onnx.NodeProto) -> list[str]:
        def fold(e: list[str]) -> str:
            result = e[0]
            for other in e[1:]:
                result = template.format(a=result, b=other)
            return result
        return _map(w, node, list(node.input), fold)
    return emit


def _pow(w: Writer, node: onnx.NodeProto) -> list[str]:
    ctype = _float_input(w, node)
    if w.tensor(node.input[1]).dtype != w.tensor(node.input[0]).dtype:
        raise refuse(node, "its exponent must have the base's type")
    return _map(w, node, list(node.input[:2]),
                lambda e: f"{_math(ctype, 'pow')}({e[0]}, {e[1]})")


def _where(w: Writer, node: onnx.NodeProto) -> list[str]:
    return _map(w, node, list(node.input[:3]), lambda e: f"({e[0]} ? {e[1]} : {e[2]})")


def _cast(w: Writer, node: onnx.NodeProto) -> list[str]:
    to = w.tensor(node.output[0])
    if to.dtype == TensorProto.BOOL:
        return _map(w, node, [node.input[0]], lambda e: f"({e[0]} != 0)")
    return _map(w, node, [node.input[0]], lambda e: f"({to.ctype})({e[0]})")


def _clip(w: Writer, node: onnx.NodeProto) -> list[str]:
    _float_input(w, node)
    dtype = w.tensor(node.input[0]).dtype
    bounds = []
    for k, key in ((1, "min"), (2, "max")):
        if len(node.input) > k and node.input[k]:
            bounds.append(w.element(node.input[k], "0"))
        elif key in attributes(node):
            bounds.append(literal(attributes(node)[key], dtype))
        else:
            bounds.append("")
    low, high = bounds

    def clip(e: list[str]) -> str:
        x = e[0]
        if low:
            x = f"({x} < {low} ? {low} : {x})"
        if high:
            x = f"({x} > {high} ? {high} : {x})"
        return x
    return _map(w, node, [node.input[0]], clip)


def _leaky_relu(w: Writer, node: onnx.NodeProto) -> list[str]:
    _float_input(w, node)
    alpha = literal(attributes(node).get("alpha", 0.01), w.tensor(node.input[0]).dtype)
    return _map(w, node, [node.input[0]], lambda e: f"({e[0]} >= 0 ? {e[0]} : {alpha} * {e[0]})")


def _is_inf(w: Writer, node: onnx.NodeProto) -> list[str]:
    _float_input(w, node)
    a = attributes(node)
    positive = int(a.get("detect_positive", 1))  # type: ignore[call-overload]
    negative = int(a.get("detect_negative", 1))  # type: ignore[call-overload]
    return _map(w, node, [node.input[0]],
                lambda e: f"(isinf({e[0]}) && ({e[0]} > 0 ? {positive} : {negative}))")


def _alias(w: Writer, node: onnx.NodeProto) -> list[str]:
    return w.alias(node.output[0], node.input[0])


def _copy_map(w: Writer, node: onnx.NodeProto, source: str, index: np.ndarray) -> list[str]:
    """out[i] = source[index[i]] for every element: the same pointer for the identity, block
    copies for runs of consecutive elements, else a loop over an index table."""
    index = np.asarray(index, dtype=np.int64).ravel()
    if index.size == w.tensor(source).size and np.array_equal(index, np.arange(index.size)):
        return w.alias(node.output[0], source)
    target = w.output(node.output[0])
    src = w.read(source)
    ctype = w.tensor(source).ctype
    breaks = np.flatnonzero(np.diff(index) != 1) + 1
    starts = np.concatenate([[0], breaks])
    lengths = np.diff(np.concatenate([starts, [index.size]]))
    sources = index[starts]
    if len(starts) <= MAX_BLOCKS:
        return [f"memcpy({target} + {s}, {src} + {int(f)}, sizeof({ctype}) * {int(n)});"
                for s, f, n in zip(starts, sources, lengths)]
    if np.all(lengths == lengths[0]) and np.all(np.diff(sources) == sources[1] - sources[0]):
        n, step = int(lengths[0]), int(sources[1] - sources[0])
        return [f"for (int k = 0; k < {len(starts)}; k++)",
                f"    memcpy({target} + k * {n}, {src} + {int(sources[0])} + k * {step}, "
                f"sizeof({ctype}) * {n});"]
    table = w.array(index.astype(np.int32), TensorProto.INT32)
    return [f"for (int i = 0; i < {index.size}; i++) {target}[i] = {src}[{table}[i]];"]


def _positions(w: Writer, name: str) -> np.ndarray:
    """The flat index of every element of tensor `name`, in its shape."""
    shape = w.tensor(name).shape
    return np.arange(int(np.prod(shape, dtype=np.int64))).reshape(shape)


def _transpose(w: Writer, node: onnx.NodeProto) -> list[str]:
    positions = _positions(w, node.input[0])
    perm = attributes(node).get("perm")
    return _copy_map(w, node, node.input[0],
                     positions.transpose(perm if perm is None else list(perm)))  # type: ignore


def _slice(w: Writer, node: onnx.NodeProto) -> list[str]:
    positions = _positions(w, node.input[0])
    rank = positions.ndim
    if len(node.input) > 1:  # opset 10: starts, ends, axes, steps as inputs
        starts, ends = (w.value(node, node.input[k], what) for k, what in ((1, "starts"),
                                                                            (2, "ends")))
        axes = (w.value(node, node.input[3], "axes") if len(node.input) > 3 and node.input[3]
                else np.arange(len(starts)))
        steps = (w.value(node, node.input[4], "steps") if len(node.input) > 4 and node.input[4]
                 else np.ones(len(starts), dtype=np.int64))
    else:
        a = attributes(node)
        starts, ends = np.array(a["starts"]), np.array(a["ends"])
        axes = np.array(a.get("axes", range(len(starts))))
        steps = np.ones(len(starts), dtype=np.int64)
    cut: list[slice] = [slice(None)] * rank
    for start, end, axis, step in zip(starts, ends, axes, steps):
        cut[int(axis) % rank] = slice(int(start), int(end), int(step))  # ONNX clamps as Python
    return _copy_map(w, node, node.input[0], positions[tuple(cut)])


def _gather(w: Writer, node: onnx.NodeProto) -> list[str]:
    indices = w.value(node, node.input[1], "indices")
    axis = int(attributes(node).get("axis", 0))  # type: ignore[call-overload]
    return _copy_map(w, node, node.input[0],
                     np.take(_positions(w, node.input[0]), indices, axis=axis))


def _expand(w: Writer, node: onnx.NodeProto) -> list[str]:
    out = w.tensor(node.output[0])
    return _copy_map(w, node, node.input[0],
                     np.broadcast_to(_positions(w, node.input[0]), out.shape))


def _concat(w: Writer, node: onnx.NodeProto) -> list[str]:
    out = w.tensor(node.output[0])
    axis = int(attributes(node)["axis"]) % len(out.shape)  # type: ignore[call-overload]
    target = w.output(node.output[0])
    outer = int(np.prod(out.shape[:axis], dtype=np.int64))
    row = int(np.prod(out.shape[axis:], dtype=np.int64))
    lines, offset = [], 0
    for name in node.input:
        tensor = w.tensor(name)
        chunk = int(np.prod(tensor.shape[axis:], dtype=np.int64))
        if chunk == 0:
            continue
        copy = (f"memcpy({target} + {offset} + k * {row}, {w.read(name)} + k * {chunk}, "
                f"sizeof({out.ctype}) * {chunk});")
        lines += ([copy.replace(" + k * " + str(row), "").replace(" + k * " + str(chunk), "")]
                  if outer == 1 else [f"for (int k = 0; k < {outer}; k++) {copy}"])
        offset += chunk
    return lines


REDUCTIONS = {"ReduceSum": ("{a} + {b}", "0"), "ReduceMean": ("{a} + {b}", "0"),
              "ReduceMax": ("({b} > {a} ? {b} : {a})", ""),
              "ReduceMin": ("({b} < {a} ? {b} : {a})", ""), "ReduceProd": ("{a} * {b}", "1")}


def _reduce(w: Writer, node: onnx.NodeProto) -> list[str]:
    source = w.tensor(node.input[0])
    a = attributes(node)
    if len(node.input) > 1 and node.input[1]:
        axes = [int(x) for x in w.value(node, node.input[1], "axes").ravel()]
    else:
        axes = [int(x) for x in a.get("axes", [])]  # type: ignore[attr-defined]
    rank = len(source.shape)
    if not axes:
        if a.get("noop_with_empty_axes", 0):
            return w.alias(node.output[0], node.input[0])
        axes = list(range(rank))
    axes = sorted(x % rank for x in axes)
    kept = [d for d in range(rank) if d not in axes]
    table = _positions(w, node.input[0]).transpose(kept + axes)
    n_out = int(np.prod([source.shape[d] for d in kept], dtype=np.int64))
    table = table.reshape(n_out, -1)
    combine, start = REDUCTIONS[node.op_type]
    target, src = w.output(node.output[0]), w.read(node.input[0])
    n_in = table.shape[1]
    if np.array_equal(table, np.arange(table.size).reshape(table.shape)):
        at = f"o * {n_in} + j"
    else:
        at = f"{w.array(table.astype(np.int32), TensorProto.INT32)}[o * {n_in} + j]"
    first = start or f"{src}[{at.replace('j', '0')}]"
    mean = f" / ({source.ctype}){n_in}" if node.op_type == "ReduceMean" else ""
    return [f"for (int o = 0; o < {n_out}; o++) {{",
            f"    {source.ctype} acc = {first};",
            f"    for (int j = {0 if start else 1}; j < {n_in}; j++) "
            f"acc = {combine.format(a='acc', b=f'{src}[{at}]')};",
            f"    {target}[o] = acc{mean};", "}"]


def _cumsum(w: Writer, node: onnx.NodeProto) -> list[str]:
    source = w.tensor(node.input[0])
    axis = int(w.value(node, node.input[1], "axis").ravel()[0]) % len(source.shape)
    a = attributes(node)
    lines_of = np.moveaxis(_positions(w, node.input[0]), axis, -1).reshape(-1, source.shape[axis])
    if a.get("reverse", 0):
        lines_of = lines_of[:, ::-1]
    table = w.array(lines_of.astype(np.int32), TensorProto.INT32)
    target, src, n = w.output(node.output[0]), w.read(node.input[0]), lines_of.shape[1]
    add, store = (f"acc += {src}[{table}[o * {n} + j]];",
                  f"{target}[{table}[o * {n} + j]] = acc;")
    return [f"for (int o = 0; o < {lines_of.shape[0]}; o++) {{",
            f"    {source.ctype} acc = 0;",
            f"    for (int j = 0; j < {n}; j++) {{",
            *(["        " + store, "        " + add] if a.get("exclusive", 0)
              else ["        " + add, "        " + store]),
            "    }", "}"]


def _suffix(w: Writer, node: onnx.NodeProto, name: str) -> str:
    tensor = w.tensor(name)
    if tensor.dtype not in FLOATS:
        raise refuse(node, f"supported on float32 and float64 only, not {tensor.ctype}")
    return "f" if tensor.dtype == TensorProto.FLOAT else "d"


def _matmul(w: Writer, node: onnx.NodeProto) -> list[str]:
    a, b = (w.tensor(n) for n in node.input[:2])
    s = _suffix(w, node, node.input[0])
    if len(b.shape) != 2 or len(a.shape) < 1:
        return _batched_matmul(w, node)
    k, n = b.shape
    rows = int(np.prod(a.shape[:-1], dtype=np.int64))
    target = w.output(node.output[0])
    if b.value is not None:  # weights: stored transposed, each output a dot product of rows
        transposed = w.array(b.value.T, b.dtype)
        return [f"for (int p = 0; p < {rows}; p++)",
                f"    nk_matvec_{s}({transposed}, {w.read(node.input[0])} + p * {k}, NULL, "
                f"{target} + p * {n}, {n}, {k});"]
    return _product_loops(target, w.read(node.input[0]), w.read(node.input[1]), a.ctype,
                          rows, k, n, (k, 1), (n, 1))


def _batched_matmul(w: Writer, node: onnx.NodeProto) -> list[str]:
    a, b = (w.tensor(n) for n in node.input[:2])
    if len(a.shape) != len(b.shape) or len(a.shape) < 3 or a.shape[:-2] != b.shape[:-2]:
        raise refuse(node, f"MatMul of shapes {list(a.shape)} x {list(b.shape)}: supported are "
                           f"a second operand of rank 2, or equal batch dimensions")
    batch = int(np.prod(a.shape[:-2], dtype=np.int64))
    m, k = a.shape[-2:]
    n = b.shape[-1]
    target = w.output(node.output[0])
    inner = _product_loops(f"{target} + q * {m * n}", f"{w.read(node.input[0])} + q * {m * k}",
                           f"{w.read(node.input[1])} + q * {k * n}", a.ctype, m, k, n, (k, 1),
                           (n, 1))
    return [f"for (int q = 0; q < {batch}; q++) {{", *("    " + line for line in inner), "}"]


def _product_loops(target: str, a: str, b: str, ctype: str, m: int, k: int, n: int,
                   a_strides: tuple[int, int], b_strides: tuple[int, int]) -> list[str]:
    """target (m, n) = a (m, k) b (k, n), the operands' elements at the given strides."""
    return [f"for (int i = 0; i < {m}; i++)",
            f"    for (int j = 0; j < {n}; j++) {{",
            f"        {ctype} acc = 0;",
            f"        for (int l = 0; l < {k}; l++) acc += ({a})[i * {a_strides[0]} + "
            f"l * {a_strides[1]}] * ({b})[l * {b_strides[0]} + j * {b_strides[1]}];",
            f"        ({target})[i * {n} + j] = acc;", "    }"]


def _gemm(w: Writer, node: onnx.NodeProto) -> list[str]:
    at = attributes(node)
    a, b = (w.tensor(n) for n in node.input[:2])
    s = _suffix(w, node, node.input[0])
    trans_a, trans_b = int(at.get("transA", 0)), int(at.get("transB", 0))  # type: ignore
    m, k = a.shape[::-1] if trans_a else a.shape
    n = b.shape[0] if trans_b else b.shape[1]
    out = w.tensor(node.output[0])
    alpha = literal(at.get("alpha", 1.0), a.dtype)
    beta = literal(at.get("beta", 1.0), a.dtype)
    product = w.buffer(a.ctype, m * n)
    if b.value is not None and not trans_a:
        weights = w.array(b.value if trans_b else b.value.T, b.dtype)
        lines = [f"for (int p = 0; p < {m}; p++)",
                 f"    nk_matvec_{s}({weights}, {w.read(node.input[0])} + p * {k}, NULL, "
                 f"{product} + p * {n}, {n}, {k});"]
    else:
        lines = _product_loops(product, w.read(node.input[0]), w.read(node.input[1]), a.ctype,
                               m, k, n, (1, m) if trans_a else (k, 1),
                               (1, k) if trans_b else (n, 1))
    has_c = len(node.input) > 2 and bool(node.input[2])
    target = w.output(node.output[0])
    opening, o, (p, c), depth = _loops(out.shape, [out.shape, w.tensor(node.input[2]).shape
                                                   if has_c else out.shape])
    term = f" + {beta} * {w.element(node.input[2], c)}" if has_c else ""
    return [*lines, *opening, f"    {target}[{o}] = {alpha} * {product}[{p}]{term};",
            "}" * depth]


def _conv(w: Writer, node: onnx.NodeProto) -> list[str]:
    x, weights = (w.tensor(n) for n in node.input[:2])
    s = _suffix(w, node, node.input[0])
    at = attributes(node)
    if len(x.shape) != 3:
        raise refuse(node, f"only 1-D convolutions (input rank 3) are supported, not rank "
                           f"{len(x.shape)}")
    if at.get("auto_pad", b"NOTSET") not in (b"NOTSET", b"VALID", "NOTSET", "VALID"):
        raise refuse(node, f"auto_pad {at['auto_pad']!r} is not supported: export with "
                           f"explicit pads")
    kernel_values = w.value(node, node.input[1], "weight")
    pads = list(at.get("pads", [0, 0]))  # type: ignore[call-overload]
    stride = int(next(iter(at.get("strides", [1]))))  # type: ignore[call-overload]
    dilation = int(next(iter(at.get("dilations", [1]))))  # type: ignore[call-overload]
    groups = int(at.get("group", 1))  # type: ignore[call-overload]
    batch, channels, length = x.shape
    filters, per_group, kernel = weights.shape
    out = w.tensor(node.output[0])
    bias = (w.read(node.input[2]) if len(node.input) > 2 and node.input[2] else "NULL")
    col = w.buffer(x.ctype, per_group * kernel)
    target, source = w.output(node.output[0]), w.read(node.input[0])
    filters_ = w.array(kernel_values, weights.dtype)
    out_length = out.shape[2]
    return [f"for (int b = 0; b < {batch}; b++)",
            f"    nk_conv1d_{s}({source} + b * {channels * length}, {channels}, {length}, "
            f"{filters_}, {bias}, {filters}, {kernel}, {stride}, {dilation}, {int(pads[0])}, "
            f"{groups}, {target} + b * {filters * out_length}, {out_length}, {col});"]


def _lstm(w: Writer, node: onnx.NodeProto) -> list[str]:
    at = attributes(node)
    names = [*node.input, *[""] * (8 - len(node.input))]
    x = w.tensor(names[0])
    s = _suffix(w, node, names[0])
    activations = [bytes(a) for a in at.get("activations", [])]  # type: ignore[attr-defined]
    if at.get("direction", b"forward") != b"forward" or \
            activations not in ([], [b"Sigmoid", b"Tanh", b"Tanh"]) or \
            "clip" in at or at.get("input_forget", 0) or at.get("layout", 0) or names[7]:
        raise refuse(node, "supported is the forward LSTM with the default activations, no "
                           "clip, no coupled input-forget gate, no peepholes, layout 0")
    steps, batch, n_in = x.shape
    hidden = int(at["hidden_size"])  # type: ignore[call-overload]
    weights = w.array(w.value(node, names[1], "W")[0], x.dtype)
    recurrent = w.array(w.value(node, names[2], "R")[0], x.dtype)
    bias = "NULL"
    if names[3]:
        both = w.value(node, names[3], "B")[0]
        bias = w.array(both[:4 * hidden] + both[4 * hidden:], x.dtype)
    if names[4]:
        lengths = w.value(node, names[4], "sequence_lens")
        if np.any(lengths != steps):
            raise refuse(node, "sequence_lens must be the whole sequence")
    h, c = w.buffer(x.ctype, batch * hidden), w.buffer(x.ctype, batch * hidden)
    gates = w.buffer(x.ctype, 4 * hidden)
    size = f"sizeof({x.ctype}) * {batch * hidden}"
    lines = [f"memcpy({h}, {w.read(names[5])}, {size});" if names[5] else
             f"memset({h}, 0, {size});",
             f"memcpy({c}, {w.read(names[6])}, {size});" if names[6] else
             f"memset({c}, 0, {size});"]
    outputs = [*node.output, "", "", ""][:3]
    y = w.output(outputs[0]) if outputs[0] else ""
    step = [f"    for (int b = 0; b < {batch}; b++) {{",
            f"        nk_lstm_{s}({weights}, {recurrent}, {bias}, {w.read(names[0])} + "
            f"(t * {batch} + b) * {n_in}, {n_in}, {hidden}, {h} + b * {hidden}, "
            f"{c} + b * {hidden}, {gates});"]
    if y:
        step.append(f"        memcpy({y} + (t * {batch} + b) * {hidden}, {h} + b * {hidden}, "
                    f"sizeof({x.ctype}) * {hidden});")
    lines += [f"for (int t = 0; t < {steps}; t++) {{", *step, "    }", "}"]
    for name, state in ((outputs[1], h), (outputs[2], c)):
        if name:
            w.bind(name, state)
    return lines


UNARY = {
    "Relu": ("({x} > 0 ? {x} : ({T})0)", False), "Neg": ("(-{x})", False),
    "Abs": ("({x} < 0 ? -{x} : {x})", False),
    "Sigmoid": ("(({T})1 / (({T})1 + exp{f}(-{x})))", True),
    "Tanh": ("tanh{f}({x})", True), "Exp": ("exp{f}({x})", True), "Log": ("log{f}({x})", True),
    "Sqrt": ("sqrt{f}({x})", True), "Sin": ("sin{f}({x})", True), "Cos": ("cos{f}({x})", True),
    "Tan": ("tan{f}({x})", True), "Atan": ("atan{f}({x})", True), "Asin": ("asin{f}({x})", True),
    "Acos": ("acos{f}({x})", True), "Sinh": ("sinh{f}({x})", True),
    "Cosh": ("cosh{f}({x})", True), "Erf": ("erf{f}({x})", True),
    "Floor": ("floor{f}({x})", True), "Ceil": ("ceil{f}({x})", True),
    "Round": ("nearbyint{f}({x})", True), "Reciprocal": ("(({T})1 / {x})", True),
    "Softplus": ("log{f}(exp{f}({x}) + ({T})1)", True),
    "Sign": ("(({T})({x} > 0) - ({T})({x} < 0))", False), "Not": ("(!{x})", False),
    "IsNaN": ("isnan({x})", True),
}
BINARY = {
    "Add": "({a} + {b})", "Sub": "({a} - {b})", "Mul": "({a} * {b})", "Div": "({a} / {b})",
    "Equal": "({a} == {b})", "Greater": "({a} > {b})", "Less": "({a} < {b})",
    "GreaterOrEqual": "({a} >= {b})", "LessOrEqual": "({a} <= {b})", "And": "({a} && {b})",
    "Or": "({a} || {b})", "Xor": "(!{a} != !{b})",
}
OPERATORS: dict[str, Emitter] = {
    **{op: _unary(template, float_only) for op, (template, float_only) in UNARY.items()},
    **{op: _binary(template) for op, template in BINARY.items()},
    "Max": _variadic("({a} > {b} ? {a} : {b})"), "Min": _variadic("({a} < {b} ? {a} : {b})"),
    "Sum": _variadic("({a} + {b})"),
    "Pow": _pow, "Where": _where, "Cast": _cast, "Clip": _clip, "LeakyRelu": _leaky_relu,
    "IsInf": _is_inf,
    "Identity": _alias, "Reshape": _alias, "Flatten": _alias, "Squeeze": _alias,
    "Unsqueeze": _alias,
    "Transpose": _transpose, "Slice": _slice, "Gather": _gather, "Expand": _expand,
    "Concat": _concat, **dict.fromkeys(REDUCTIONS, _reduce), "CumSum": _cumsum,
    "MatMul": _matmul, "Gemm": _gemm, "Conv": _conv, "LSTM": _lstm,
}
