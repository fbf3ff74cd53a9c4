"""An ONNX graph embedded in a System's FMU, run by onnxruntime's C API (c/onnx_network.c).

The graph follows one convention: a float64 input (T, n_inputs), a float64 output
(T, n_outputs), and float32 state tensors, each state input NAME of fixed shape with the output
NAME_out of the same shape (where the graph leaves a dimension symbolic, the run checks it)
(the recurrent state or input buffer of a sequence model, zero at the
start). The FMU runs it every `period` communication steps on `input_function(x, u, p)` and
hands the result to the System's output function (see System); `table` switches it to the
precomputed mode, `task` runs it in its own task (a worker thread of the FMU, its result used
one period after the call started, c/wrapper_task.c). `runtime` says what computes the graph:
"c" (default), the graph generated as C (fmu.network_c) and compiled into the FMU, which then
needs nothing but its own sources; "onnxruntime", the FMU bundles the graph (resources/) and
the libonnxruntime of the installed onnxruntime wheel (binaries/<platform>/).
fmu.onnx_graph brings any graph of fixed-size float tensors to this convention.
"""

from __future__ import annotations

import importlib.util
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import casadi as ca
import numpy as np
import onnx

from flexff.fmu.errors import InputError, MissingPackage
from flexff.fmu.network_runtime import RUNTIMES, check_runtime

MAX_RANK = 4  # of a state tensor (NET_MAX_RANK in onnx_network.h)
MAX_TENSORS = 64  # inputs, or outputs, of one graph (MAX_TENSORS in onnx_network.c)
ELEMENT_TYPES: dict[int, str] = {onnx.TensorProto.FLOAT: "float32",
                                 onnx.TensorProto.DOUBLE: "float64"}


@dataclass(frozen=True)
class StateTensor:
    """A float32 state tensor of the graph: input `name`, output `name`_out."""

    name: str
    shape: tuple[int, ...]

    @property
    def output(self) -> str:
        return f"{self.name}_out"

    @property
    def size(self) -> int:
        return int(np.prod(self.shape))


@dataclass(frozen=True)
class Network:
    """The graph of `model` with its signature, when it runs and on what."""

    model: Path
    input: str
    output: str
    n_inputs: int
    n_outputs: int
    states: tuple[StateTensor, ...]
    input_function: ca.Function  # network_input(x, u, p) -> (n_inputs,)
    period: int = 1  # communication steps between calls
    table: np.ndarray | None = None  # precomputed mode: rows (time, inputs...) at every step
    task: bool = False  # in its own task: the result of the call at step k used from k + period
    runtime: str = RUNTIMES[0]  # generated C compiled into the FMU, or onnxruntime
    primed: bool = False  # the first call starts from the state of a network at rest on its
    # inputs since ever (run on them until the state stops changing), else from zero

    def __post_init__(self) -> None:
        check_runtime(self.runtime)
        if self.period < 1:
            raise InputError(f"the network's period must be at least one step, got {self.period}")
        if self.task and self.table is not None:
            raise InputError("a precomputed network makes no calls while stepping: it cannot "
                             "run in its own task")
        if self.table is not None and (self.table.ndim != 2 or self.table.shape[0] < 1
                                       or not np.all(np.isfinite(self.table))):
            raise ValueError("the precomputation table must be a finite 2-D array with rows "
                             "(time, inputs...)")


def read_network(model: str | Path, input_function: ca.Function, period: int = 1,
                 table: np.ndarray | None = None) -> Network:
    """The Network of the ONNX file `model`; InputError (what is wrong) if the graph does not
    follow the convention of this module or does not fit `input_function`."""
    path = Path(model)
    graph = load_model(path).graph
    inputs = {v.name: _tensor(v, path) for v in graph.input}
    outputs = {v.name: _tensor(v, path) for v in graph.output}
    sequence_in = [n for n, (kind, _) in inputs.items() if kind == "float64"]
    sequence_out = [n for n, (kind, _) in outputs.items() if kind == "float64"]
    if len(sequence_in) != 1 or len(sequence_out) != 1:
        raise InputError(f"{path}: the graph needs exactly one float64 input and one float64 "
                         f"output (T, n), found inputs {_describe(inputs)} and outputs "
                         f"{_describe(outputs)}")
    n_in, n_out = (_columns(path, name, table[name][1])
                   for name, table in ((sequence_in[0], inputs), (sequence_out[0], outputs)))
    states = []
    for name, (kind, shape) in inputs.items():
        if name == sequence_in[0]:
            continue
        state = StateTensor(name, _fixed_shape(path, name, kind, shape))
        out_kind, out_shape = outputs.get(state.output, (None, ()))
        if out_kind != kind or len(out_shape) != len(shape) or any(
                isinstance(o, int) and o != d for o, d in zip(out_shape, shape)):
            raise InputError(f"{path}: state input {name!r} {list(shape)} needs an output "
                             f"{state.output!r} of the same type and shape")
        states.append(state)
    if 1 + len(states) > MAX_TENSORS:
        raise InputError(f"{path}: {len(states)} state tensors; the FMU runs graphs with at most "
                         f"{MAX_TENSORS - 1}")
    if len(outputs) != 1 + len(states):
        raise InputError(f"{path}: outputs {_describe(outputs)} are not the float64 output and "
                         f"one NAME_out per state input")
    if input_function.n_out() != 1 or input_function.numel_out(0) != n_in:
        raise InputError(f"{path}: the graph takes {n_in} inputs per step, but the network's "
                         f"input function gives {input_function.numel_out(0)}")
    return Network(path, sequence_in[0], sequence_out[0], n_in, n_out, tuple(states),
                   input_function, period, table)


def load_model(model: str | Path) -> onnx.ModelProto:
    """The ONNX model in the file `model`; InputError naming the file if it is missing or is not
    an ONNX model."""
    path = Path(model)
    if not path.is_file():
        raise InputError(f"ONNX model {path} does not exist")
    try:
        loaded = onnx.load(str(path))
    except Exception as exc:  # onnx raises DecodeError and others for a broken file
        raise InputError(f"{path} is not a readable ONNX model: {exc}") from exc
    if loaded.ir_version < 1 or not loaded.graph.output:  # protobuf reads some junk as empty
        raise InputError(f"{path} is not a readable ONNX model: it has no IR version or no "
                         f"graph outputs")
    field = _not_text(loaded)
    if field is not None:
        raise InputError(f"{path} is not a readable ONNX model: a {field} is not UTF-8 text")
    return loaded


def _not_text(message: Any) -> str | None:
    """The name of the first string field in `message` (nested messages too) that holds bytes
    that are not UTF-8: protobuf reads them (ONNX's proto2 does not check) as bytes where text
    is expected, which breaks any use as a name."""
    for field, value in message.ListFields():
        values = value if field.is_repeated else [value]
        if field.type == field.TYPE_STRING and any(isinstance(v, bytes) for v in values):
            return f"{message.DESCRIPTOR.name}.{field.name}"
        if field.type == field.TYPE_MESSAGE:
            found = next((f for v in values if (f := _not_text(v)) is not None), None)
            if found is not None:
                return found
    return None


def runtime_library() -> Path:
    """libonnxruntime of the installed onnxruntime wheel (its capi/ folder)."""
    spec = importlib.util.find_spec("onnxruntime")
    if spec is None or not spec.submodule_search_locations:
        raise MissingPackage("onnxruntime is not installed: pip install onnxruntime (its wheel "
                             "holds the libonnxruntime the network FMU bundles)")
    folder = Path(next(iter(spec.submodule_search_locations))) / "capi"
    found = sorted(folder.glob("libonnxruntime.so.*")) + sorted(folder.glob("onnxruntime.dll"))
    found += sorted(folder.glob("libonnxruntime.*.dylib"))
    if not found:
        raise MissingPackage(f"no libonnxruntime in {folder}: reinstall onnxruntime")
    return found[0]


def type_name(elem_type: int) -> str:
    """An ONNX element type's name (FLOAT, INT64, ...), also for a number ONNX does not
    define (a damaged file's)."""
    try:
        return str(onnx.TensorProto.DataType.Name(elem_type))
    except ValueError:
        return f"the undefined element type {elem_type}"


def _tensor(value: onnx.ValueInfoProto, path: Path) -> tuple[str, tuple[int | str, ...]]:
    tensor = value.type.tensor_type
    kind = ELEMENT_TYPES.get(tensor.elem_type)
    if kind is None:
        raise InputError(f"{path}: tensor {value.name!r} has element type "
                         f"{type_name(tensor.elem_type)}; only float32 "
                         f"(state) and float64 (input, output) are supported")
    shape = tuple(d.dim_value if d.HasField("dim_value") else (d.dim_param or "?")
                  for d in tensor.shape.dim)
    return kind, shape


def _describe(tensors: dict[str, tuple[str, tuple[int | str, ...]]]) -> str:
    return ", ".join(f"{n} {kind} {list(shape)}" for n, (kind, shape) in tensors.items())


def _columns(path: Path, name: str, shape: tuple[int | str, ...]) -> int:
    if len(shape) != 2 or not isinstance(shape[1], int) or shape[1] < 1:
        raise InputError(f"{path}: {name!r} must have the shape (T, n) with a fixed n, "
                         f"not {list(shape)}")
    return shape[1]


def _fixed_shape(path: Path, name: str, kind: str, shape: tuple[int | str, ...]) -> tuple[int, ...]:
    if kind != "float32" or not 1 <= len(shape) <= MAX_RANK or not all(
            isinstance(d, int) and d > 0 for d in shape):
        raise InputError(f"{path}: state tensor {name!r} must be float32 with a fixed shape of "
                         f"rank 1 to {MAX_RANK}, not {kind} {list(shape)}")
    return tuple(int(d) for d in shape)
