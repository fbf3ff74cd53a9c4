"""Any ONNX graph as an FMU (`flexff fmu build onnx MODEL.onnx -o M.fmu`).

A discrete, stateless System: its inputs are the elements of the graph's input tensors, its
outputs the elements of its output tensors, as fmu.onnx_graph names them; the network's inputs
are the FMU's inputs and its result is the FMU's outputs. The graph runs as generated C
compiled into the FMU (runtime "c", the default; fmu.network_c) or in onnxruntime (the library
of the installed wheel, bundled) every `every` communication steps of `step` seconds,
its results extrapolated linearly from the last two calls in between (fmu.system); its
recurrent state tensors are carried from call to call and in the FMU state. With `task` the
graph runs in its own task, a worker thread of the FMU (fmu.network.Network): the step never
waits for it, its result comes one call period later and is extrapolated one period further.
"""

from __future__ import annotations

import json
from pathlib import Path

import casadi as ca

from flexff.fmu.defaults import DEFAULT_STEP
from flexff.fmu.errors import InputError
from flexff.fmu.network_runtime import RUNTIMES, runtime_label
from flexff.fmu.onnx_graph import Port, graph_network, read_graph
from flexff.fmu.system import System, Variable


def onnx_system(model: str | Path, step: float = DEFAULT_STEP, every: int = 1,
                task: bool = False, runtime: str = RUNTIMES[0]) -> System:
    """The System of the FMU running the ONNX graph in the file `model` with `runtime` ("c"
    or "onnxruntime"); InputError (what is wrong, what to do) if the graph cannot be one (see
    fmu.onnx_graph.read_graph)."""
    if not step > 0:
        raise InputError(f"the communication step must be positive, got {step}")
    graph = read_graph(model)
    x, p, w = ca.SX.sym("x", 0), ca.SX.sym("p", 0), ca.SX.sym("w", 0)
    u = ca.SX.sym("u", len(graph.input_names))
    r = ca.SX.sym("r", len(graph.output_names))
    network = graph_network(graph, ca.Function("network_input", [x, u, p], [u]), every,
                            task=task, runtime=runtime)
    calls = "every step" if every == 1 else f"every {every} steps, extrapolated in between"
    if task:
        calls += ", in its own task (its result one call later)"
    return System(
        name=graph.path.stem,
        description=f"ONNX graph {graph.path.name} in {runtime_label(runtime)}, called {calls}",
        kind="discrete",
        states=(),
        inputs=_variables(graph.inputs, "input"),
        outputs=_variables(graph.outputs, "output"),
        parameters=(),
        initial_state=ca.Function("initial_state", [p], [ca.SX(0, 1)]),
        dynamics=ca.Function("dynamics", [x, u, p], [ca.SX(0, 1)]),
        output=ca.Function("output", [x, u, p, w, r], [r]),
        sample_time=step,
        extra={"flexff.onnx.model": graph.path.name, "flexff.onnx.every": str(every),
               "flexff.onnx.task": str(task).lower(),
               "flexff.onnx.state": json.dumps([list(pair) for pair in graph.states])},
        network=network,
    )


def _variables(ports: tuple[Port, ...], role: str) -> tuple[Variable, ...]:
    return tuple(Variable(name, description=f"element {k} of the graph's {role} {port.name!r}, "
                                            f"{port.describe()}")
                 for port in ports for k, name in enumerate(port.elements))
