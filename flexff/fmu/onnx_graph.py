"""Any ONNX graph of fixed-size float tensors as the network of a System's FMU.

`read_graph` reads a graph whose inputs and outputs are float32 or float64 tensors of fixed
size, tells state tensors from the others and names every element; `graph_network` wraps a
graph that does not follow fmu.network's convention (one float64 input and output, float32
state NAME -> NAME_out) in an adapter graph that does. Optional metadata (JSON in
metadata_props): `state`, the recurrent state tensors; `input_signals` / `output_signals`,
the names of the elements in graph order (default `u[k]`).

Docs: "Bring your own network" (docs/how-to/own-network.md) and "File formats", section An
exported model (docs/reference/file-formats.md).
"""

from __future__ import annotations

import json
import math
import tempfile
from dataclasses import dataclass, replace
from pathlib import Path

import casadi as ca
import numpy as np
import onnx
import onnxruntime as ort
from onnx import TensorProto
from onnx import helper as oh

from flexff.fmu import cache
from flexff.fmu.errors import InputError
from flexff.fmu.limits import ONNX_ELEMENTS
from flexff.fmu.network import Network, load_model, read_network, type_name
from flexff.fmu.network_c import fmu_network_sources
from flexff.fmu.network_runtime import RUNTIMES, check_runtime

FLOATS: dict[int, str] = {TensorProto.FLOAT: "float32", TensorProto.DOUBLE: "float64"}
RESERVED = "flexff/"  # names of the adapter: FMU_INPUTS, FMU_OUTPUTS, the graph's under GRAPH
FMU_INPUTS, FMU_OUTPUTS, GRAPH = f"{RESERVED}inputs", f"{RESERVED}outputs", f"{RESERVED}graph/"
MIN_OPSET = 6  # Gather, Cast (`to` an integer), Reshape, Concat, Identity as the adapter uses them


@dataclass(frozen=True)
class Port:
    """A non-state input or output tensor of the graph and the names of its elements."""

    name: str
    dtype: int  # onnx.TensorProto element type
    shape: tuple[int | str, ...]
    elements: tuple[str, ...]

    def describe(self) -> str:
        return f"{FLOATS[self.dtype]} {list(self.shape)}"


@dataclass(frozen=True)
class Graph:
    """An ONNX model read by `read_graph`: its ports and state tensors (input, output names)."""

    path: Path
    model: onnx.ModelProto
    inputs: tuple[Port, ...]
    outputs: tuple[Port, ...]
    states: tuple[tuple[str, str], ...]
    time_axis: bool

    @property
    def input_names(self) -> list[str]:
        return [e for port in self.inputs for e in port.elements]

    @property
    def output_names(self) -> list[str]:
        return [e for port in self.outputs for e in port.elements]


def read_graph(model: str | Path, time_axis: bool = False) -> Graph:
    """The Graph of the ONNX file `model`; InputError naming the file and tensor if it is not
    ONNX, a tensor is not float32/float64 or has a dynamic size, or the metadata does not fit.

    With `time_axis`, the first dimension of every input and output that is not state is time
    (any length, dynamic allowed; one row per call), as in flexff's exported models.
    """
    path = Path(model)
    loaded = load_model(path)
    graph, meta = loaded.graph, {p.key: p.value for p in loaded.metadata_props}
    constants = {t.name for t in graph.initializer}  # inputs with a default (IR < 4 lists them)
    inputs = {v.name: v for v in graph.input if v.name not in constants}
    outputs = {v.name: v for v in graph.output}
    states = _states(path, meta, inputs, outputs)
    stateful = {name for pair in states for name in pair}
    ports = {role: _ports(path, meta, role, [v for n, v in tensors.items() if n not in stateful],
                          time_axis)
             for role, tensors in (("input", inputs), ("output", outputs))}
    return Graph(path, loaded, ports["input"], ports["output"], states, time_axis)


def graph_network(graph: Graph, input_function: ca.Function, period: int = 1,
                  table: np.ndarray | None = None, task: bool = False,
                  runtime: str = RUNTIMES[0], primed: bool = False) -> Network:
    """The Network running `graph` on `input_function(x, u, p)` (a column of the graph's input
    elements, in the order of `graph.input_names`) every `period` steps, see fmu.network: the
    graph's own file if it follows the wrapper's convention, else its adapter graph, written
    to the build cache. The precomputed mode (`table`) runs all calls in one: it needs the
    time axis; `task` runs the calls in their own task (fmu.network.Network); `runtime` computes
    the graph ("c" or "onnxruntime"), which is checked to be able to now; `primed` starts it
    at rest on its first inputs (Network.primed)."""
    check_runtime(runtime)
    if table is not None and not graph.time_axis:
        raise InputError(f"{graph.path}: the precomputed mode needs a graph with a time axis")
    if _follows_convention(graph):
        file = graph.path
    else:
        data = _adapter(graph).SerializeToString()
        key = cache.digest({"adapter.onnx": data})
        file = cache.cached_path(key, ".onnx")
        if not file.exists():
            with tempfile.TemporaryDirectory() as tmp:
                (Path(tmp) / "adapter.onnx").write_bytes(data)
                cache.store(key, ".onnx", Path(tmp) / "adapter.onnx")
    if runtime == "c":  # what cannot be generated as C, say so now, naming the graph
        try:
            fmu_network_sources(file)
        except InputError as exc:
            raise InputError(str(exc).replace(str(file), str(graph.path))) from exc
    else:
        _check_onnxruntime(graph, file)
    return replace(read_network(file, input_function, period, table), task=task,
                   runtime=runtime, primed=primed)


def _check_onnxruntime(graph: Graph, file: Path) -> None:
    """InputError if the onnxruntime the FMU bundles cannot load the graph."""
    try:
        options = ort.SessionOptions()
        options.intra_op_num_threads = options.inter_op_num_threads = 1
        ort.InferenceSession(str(file), options, providers=["CPUExecutionProvider"])
    except Exception as exc:  # onnxruntime raises its own Fail, InvalidGraph, ...
        raise InputError(f"{graph.path}: onnxruntime {ort.__version__}, which the FMU bundles, "
                         f"cannot load the graph: {exc}") from exc


def _states(path: Path, meta: dict[str, str], inputs: dict[str, onnx.ValueInfoProto],
            outputs: dict[str, onnx.ValueInfoProto]) -> tuple[tuple[str, str], ...]:
    """The (input, output) names of the state tensors that metadata `state` declares."""
    try:
        declared = json.loads(meta.get("state", "[]"))
        pairs = tuple((str(s["input"]), str(s["output"])) for s in declared)
    except (ValueError, TypeError, KeyError) as exc:
        raise InputError(f"{path}: metadata 'state' must be a JSON list of "
                         f'{{"input": NAME, "output": NAME}}, not {meta["state"]!r}') from exc
    for name_in, name_out in pairs:
        if name_in not in inputs or name_out not in outputs:
            raise InputError(f"{path}: metadata 'state' declares the state input {name_in!r} "
                             f"and output {name_out!r}, but the graph's inputs are "
                             f"{list(inputs)} and its outputs {list(outputs)}")
        shape_in, shape_out = ([d.dim_value if d.HasField("dim_value") else None
                                for d in v.type.tensor_type.shape.dim]
                               for v in (inputs[name_in], outputs[name_out]))
        types = {v.type.tensor_type.elem_type for v in (inputs[name_in], outputs[name_out])}
        if (types != {TensorProto.FLOAT} or None in shape_in or len(shape_out) != len(shape_in)
                or any(o not in (None, i) for o, i in zip(shape_out, shape_in))):
            raise InputError(f"{path}: state tensors {name_in!r} and {name_out!r} must both be "
                             f"float32, the input of a fixed shape and the output of the same "
                             f"(the FMU carries its state in float32)")
        ONNX_ELEMENTS.check(math.prod(d or 0 for d in shape_in), f"{path}: state {name_in!r}")
    names = [n for pair in pairs for n in pair]
    wrapped = [FMU_INPUTS, FMU_OUTPUTS, *[n for name_in, _ in pairs
                                          for n in (name_in, f"{name_in}_out")]]
    if len(set(names)) != len(names) or len(set(wrapped)) != len(wrapped) or any(
            n.startswith(RESERVED) for n in names):
        raise InputError(f"{path}: state tensors {names} must be distinct, no input NAME may be "
                         f"another's NAME_out, and no name may start with {RESERVED!r}")
    return pairs


def _ports(path: Path, meta: dict[str, str], role: str, tensors: list[onnx.ValueInfoProto],
           time_axis: bool) -> tuple[Port, ...]:
    """The inputs (or outputs) that are not state, their elements named."""
    if not tensors:
        raise InputError(f"{path}: the graph has no {role} besides its state tensors; the FMU "
                         f"needs at least one")
    shapes = [_port_shape(path, role, v, time_axis) for v in tensors]
    sizes = [math.prod(_fixed(shape[1:] if time_axis else shape)) for shape in shapes]
    names = ", ".join(repr(v.name) for v in tensors)
    ONNX_ELEMENTS.check(sum(sizes), f"{path}: {role}s {names}")  # before naming each element
    elements = iter(_element_names(path, meta, f"{role}_signals", [v.name for v in tensors],
                                   sizes))
    return tuple(Port(v.name, v.type.tensor_type.elem_type, shape,
                      tuple(next(elements) for _ in range(n)))
                 for v, shape, n in zip(tensors, shapes, sizes))


def _port_shape(path: Path, role: str, value: onnx.ValueInfoProto, time_axis: bool
                ) -> tuple[int | str, ...]:
    """The shape of an input or output, checked: float32/float64 and a fixed size."""
    tensor = value.type.tensor_type
    if not value.type.HasField("tensor_type") or tensor.elem_type not in FLOATS:
        kind = (type_name(tensor.elem_type) if value.type.HasField("tensor_type")
                else value.type.WhichOneof("value"))
        raise InputError(f"{path}: {role} {value.name!r} holds {kind}; FMU variables are reals, "
                         f"so every input and output must be a float32 or float64 tensor")
    if not tensor.HasField("shape"):
        raise InputError(f"{path}: {role} {value.name!r} has no shape in the graph; export it "
                         f"with its shape")
    shape = tuple(d.dim_value if d.HasField("dim_value") else (d.dim_param or "?")
                  for d in tensor.shape.dim)
    if time_axis and not shape:
        raise InputError(f"{path}: {role} {value.name!r} is a scalar, but the graph's first "
                         f"dimension must be time")
    for dim in shape[1:] if time_axis else shape:
        if not isinstance(dim, int):
            raise InputError(_dynamic(path, role, value.name, shape, dim))
        if dim < 0:
            raise InputError(f"{path}: {role} {value.name!r} has the negative dimension {dim} "
                             f"in its shape {list(shape)}: not a valid ONNX graph")
    return shape


def _fixed(dims: tuple[int | str, ...]) -> list[int]:
    """Dimensions that `_port_shape` checked to be fixed, as ints."""
    return [int(d) for d in dims]


def _dynamic(path: Path, role: str, name: str, shape: tuple[int | str, ...], dim: str) -> str:
    """What to do about the dynamic dimension `dim` of a tensor."""
    fix = "python -m onnxruntime.tools.make_dynamic_shape_fixed"
    fixed = ",".join(str(d) if isinstance(d, int) else "1" for d in shape)
    how = (f"{fix} --dim_param {dim} --dim_value 1 {path} FIXED.onnx" if dim != "?" else
           f"{fix} --input_name {name} --input_shape {fixed} {path} FIXED.onnx" if role == "input"
           else "export the graph again with fixed output sizes")
    return (f"{path}: {role} {name!r} has the dynamic dimension {dim!r} in its shape "
            f"{list(shape)}; the FMU needs a fixed number of elements. Export with fixed sizes "
            f"(torch.onnx.export without dynamic_axes) or fix it: {how}")


def _element_names(path: Path, meta: dict[str, str], key: str, tensors: list[str],
                   sizes: list[int]) -> list[str]:
    """The names of all elements: metadata `key` if present, else u[k] (u for one element)."""
    if key not in meta:
        return [f"{t}[{k}]" if n > 1 else t for t, n in zip(tensors, sizes) for k in range(n)]
    try:
        names = json.loads(meta[key])
    except ValueError as exc:
        raise InputError(f"{path}: metadata {key!r} is not JSON: {exc}") from exc
    if (not isinstance(names, list) or len(names) != sum(sizes)
            or not all(isinstance(n, str) and n for n in names)):
        raise InputError(f"{path}: metadata {key!r} must list {sum(sizes)} names, one per element "
                         f"of {', '.join(f'{t} ({n})' for t, n in zip(tensors, sizes))}; "
                         f"got {meta[key]!r}")
    return names


def _follows_convention(graph: Graph) -> bool:
    """Whether the graph already is one float64 input and output (T, n) and NAME_out states."""
    return (len(graph.inputs) == len(graph.outputs) == 1
            and len(graph.model.graph.input) == 1 + len(graph.states)
            and all(p.dtype == TensorProto.DOUBLE and len(p.shape) == 2
                    and (graph.time_axis or p.shape[0] == 1)
                    for p in graph.inputs + graph.outputs)
            and all(name_out == f"{name_in}_out" for name_in, name_out in graph.states))


def _adapter(graph: Graph) -> onnx.ModelProto:
    """The graph inside one in the wrapper's convention (its own names prefixed by GRAPH)."""
    opset = max((o.version for o in graph.model.opset_import if o.domain in ("", "ai.onnx")),
                default=0)
    if opset < MIN_OPSET:
        raise InputError(f"{graph.path}: the graph uses opset {opset}; the FMU needs {MIN_OPSET} "
                         f"or newer (onnx.version_converter.convert_version converts it)")
    model = onnx.compose.add_prefix(graph.model, GRAPH)
    inner = model.graph
    rows = "time" if graph.time_axis else 1
    nodes: list[onnx.NodeProto] = []
    constants: list[onnx.TensorProto] = []
    offset = 0

    def constant(values: list[int]) -> str:
        name = f"{RESERVED}constant{len(constants)}"
        constants.append(oh.make_tensor(name, TensorProto.INT64, [len(values)], values))
        return name

    for k, port in enumerate(graph.inputs):
        n = len(port.elements)
        index = constant(list(range(offset, offset + n)))
        shape = constant([-1, *_fixed(port.shape[1:])] if graph.time_axis
                         else _fixed(port.shape))
        nodes += [oh.make_node("Gather", [FMU_INPUTS, index], [f"{RESERVED}in{k}"], axis=1),
                  oh.make_node("Cast", [f"{RESERVED}in{k}"], [f"{RESERVED}in{k}/cast"],
                               to=port.dtype),
                  oh.make_node("Reshape", [f"{RESERVED}in{k}/cast", shape],
                               [GRAPH + port.name])]
        offset += n
    nodes += [oh.make_node("Identity", [name_in], [GRAPH + name_in])
              for name_in, _ in graph.states]
    nodes += list(inner.node)
    flat = []
    for k, port in enumerate(graph.outputs):
        flat.append(f"{RESERVED}out{k}")
        nodes += [oh.make_node("Cast", [GRAPH + port.name], [f"{RESERVED}out{k}/cast"],
                               to=TensorProto.DOUBLE),
                  oh.make_node("Reshape", [f"{RESERVED}out{k}/cast",
                                           constant([-1, len(port.elements)])], [flat[-1]])]
    nodes.append(oh.make_node("Concat", flat, [FMU_OUTPUTS], axis=1))
    nodes += [oh.make_node("Identity", [GRAPH + name_out], [f"{name_in}_out"])
              for name_in, name_out in graph.states]
    state_info = {v.name: v for v in graph.model.graph.input}
    state_inputs = [state_info[name_in] for name_in, _ in graph.states]
    wrapped = oh.make_graph(
        nodes, inner.name,
        [oh.make_tensor_value_info(FMU_INPUTS, TensorProto.DOUBLE,
                                   [rows, len(graph.input_names)]), *state_inputs],
        [oh.make_tensor_value_info(FMU_OUTPUTS, TensorProto.DOUBLE,
                                   [rows, len(graph.output_names)]),
         *[oh.make_tensor_value_info(f"{name_in}_out", TensorProto.FLOAT,
                                     [d.dim_value for d in v.type.tensor_type.shape.dim])
           for (name_in, _), v in zip(graph.states, state_inputs)]],
        [*inner.initializer, *constants], value_info=inner.value_info,
        sparse_initializer=inner.sparse_initializer)
    model.graph.CopyFrom(wrapped)  # the model keeps its opsets, functions and metadata,
    oh.set_model_props(model, {**{p.key: p.value for p in model.metadata_props},  # which names
                               "input_signals": json.dumps(graph.input_names),  # the columns
                               "output_signals": json.dumps(graph.output_names)})
    model.ir_version = max(model.ir_version, 4)  # initializers that are not inputs
    return model
