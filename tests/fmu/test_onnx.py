"""Any ONNX graph as an FMU (fmu/onnx_graph.py, fmu/onnx_fmu.py, `flexff fmu build onnx`):
graphs exported from torch here (an MLP of three input and two output tensors, an LSTM whose
(h, c) are state declared in metadata) run step by step in the FMU exactly as onnxruntime's
Python API runs them with the state carried by hand; calls every N steps extrapolate as
documented; both validators pass; libcosim agrees; bad graphs give a ValueError naming them."""

import json
import warnings
import zipfile

import casadi as ca
import numpy as np
import onnx
import onnxruntime as ort
import pytest
import torch
from fmpy.validation import validate_fmu as fmpy_validate
from onnx import TensorProto
from onnx import helper as oh

from flexff.cli import main
from flexff.fmu.build import build_fmu
from flexff.fmu.fmpy_instance import FmpyInstance
from flexff.fmu.onnx_fmu import onnx_system
from flexff.fmu.onnx_graph import graph_network, read_graph
from flexff.fmu.validation import validate_fmu
from tests.runners import run_fmu, run_fmu_libcosim

STEPS = 40
H = 1e-3
EVERY = 3
LSTM_STATE = {"h": "h_next", "c": "c_next"}
EPS32 = float(np.finfo(np.float32).eps)


class Mlp(torch.nn.Module):
    """a (1, 1) float32, b (2,) float32, c (1,) float64 -> y (1, 2) float32, s (1,) float64."""

    def __init__(self):
        super().__init__()
        self.hidden, self.out = torch.nn.Linear(4, 8), torch.nn.Linear(8, 3)

    def forward(self, a, b, c):
        z = torch.cat([a.reshape(1, 1), b.reshape(1, 2), c.reshape(1, 1).float()], dim=1)
        y = self.out(torch.tanh(self.hidden(z)))
        return y[:, :2], y[:, 2].double()


class Lstm(torch.nn.Module):
    """u (1, 1, 3), state h, c (1, 1, 5) -> y (1, 1, 2), h_next, c_next."""

    def __init__(self):
        super().__init__()
        self.lstm, self.out = torch.nn.LSTM(3, 5), torch.nn.Linear(5, 2)

    def forward(self, u, h, c):
        y, (h_next, c_next) = self.lstm(u, (h, c))
        return self.out(y), h_next, c_next


def _export(module, example, path, inputs, outputs, metadata=None, dynamic_axes=None) -> str:
    torch.manual_seed(0)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        torch.onnx.export(module, example, str(path), dynamo=False, opset_version=17,
                          input_names=inputs, output_names=outputs, dynamic_axes=dynamic_axes)
    if metadata:
        model = onnx.load(str(path))
        onnx.helper.set_model_props(model, metadata)
        onnx.save(model, str(path))
    return str(path)


def mlp_graph(path, **kw) -> str:
    torch.manual_seed(0)
    example = (torch.zeros(1, 1), torch.zeros(2), torch.zeros(1, dtype=torch.float64))
    return _export(Mlp(), example, path, ["a", "b", "c"], ["y", "s"], **kw)


def lstm_graph(path) -> str:
    torch.manual_seed(1)
    example = (torch.zeros(1, 1, 3), torch.zeros(1, 1, 5), torch.zeros(1, 1, 5))
    metadata = {"state": json.dumps([{"input": i, "output": o} for i, o in LSTM_STATE.items()]),
                "input_signals": json.dumps(["x1", "x2", "x3"]),
                "output_signals": json.dumps(["Fx", "Fy"])}
    return _export(Lstm(), example, path, ["u", "h", "c"], ["y", "h_next", "c_next"], metadata)


def onnxruntime_steps(model: str, rows: np.ndarray, state: dict[str, str]) -> np.ndarray:
    """The graph called once per row by onnxruntime's Python API, each row cut into the input
    tensors in graph order, the state outputs fed back (zeros first); the outputs flattened."""
    options = ort.SessionOptions()
    options.intra_op_num_threads = options.inter_op_num_threads = 1
    session = ort.InferenceSession(model, options, providers=["CPUExecutionProvider"])
    inputs = [i for i in session.get_inputs() if i.name not in state]
    outputs = [o.name for o in session.get_outputs() if o.name not in state.values()]
    carried = {i.name: np.zeros(i.shape, np.float32) for i in session.get_inputs()
               if i.name in state}
    results = []
    for row in rows:
        feed, offset = dict(carried), 0
        for i in inputs:
            n = int(np.prod(i.shape))
            dtype = np.float32 if i.type == "tensor(float)" else np.float64
            feed[i.name] = row[offset:offset + n].astype(dtype).reshape(i.shape)
            offset += n
        values = dict(zip([o.name for o in session.get_outputs()], session.run(None, feed)))
        carried = {name_in: values[name_out] for name_in, name_out in state.items()}
        results.append(np.concatenate([values[o].ravel() for o in outputs]).astype(np.float64))
    return np.array(results)


@pytest.fixture(scope="module")
def graphs(tmp_path_factory):
    folder = tmp_path_factory.mktemp("graphs")
    return {"mlp": mlp_graph(folder / "mlp.onnx"), "lstm": lstm_graph(folder / "lstm.onnx")}


@pytest.fixture(scope="module")
def fmus(graphs, tmp_path_factory):
    folder = tmp_path_factory.mktemp("fmus")
    built = {kind: build_fmu(onnx_system(path), folder / f"{kind}.fmu")
             for kind, path in graphs.items()}
    built["mlp_every"] = build_fmu(onnx_system(graphs["mlp"], every=EVERY),
                                   folder / "mlp_every.fmu")
    return built


ROWS = {"mlp": np.random.default_rng(3).normal(size=(STEPS, 4)),
        "lstm": np.random.default_rng(4).normal(size=(STEPS, 3))}
NAMES = {"mlp": (["a", "b[0]", "b[1]", "c"], ["y[0]", "y[1]", "s"]),
         "lstm": (["x1", "x2", "x3"], ["Fx", "Fy"])}
STATES = {"mlp": {}, "lstm": LSTM_STATE}


def _inputs(kind: str) -> dict[str, np.ndarray]:
    return {name: ROWS[kind][:, k] for k, name in enumerate(NAMES[kind][0])}


def _outputs(result: dict[str, np.ndarray], kind: str) -> np.ndarray:
    return np.column_stack([result[name] for name in NAMES[kind][1]])


def test_every_float_element_is_a_named_variable(graphs):
    for kind, (inputs, outputs) in NAMES.items():
        system = onnx_system(graphs[kind])
        assert [v.name for v in system.inputs] == inputs
        assert [v.name for v in system.outputs] == outputs
    described = onnx_system(graphs["mlp"]).inputs[1].description
    assert described == "element 0 of the graph's input 'b', float32 [2]"


@pytest.mark.parametrize("kind", ["mlp", "lstm"])
def test_outputs_equal_onnxruntime_at_every_step(graphs, fmus, kind):
    expected = onnxruntime_steps(graphs[kind], ROWS[kind], STATES[kind])
    got = _outputs(run_fmu(fmus[kind], STEPS, H, _inputs(kind)), kind)[:STEPS]
    np.testing.assert_allclose(got, expected, rtol=4 * EPS32,
                               atol=4 * EPS32 * np.abs(expected).max())


def test_calls_every_n_steps_are_extrapolated_in_between(graphs, fmus):
    calls = onnxruntime_steps(graphs["mlp"], ROWS["mlp"][::EVERY], {})
    expected = np.array([calls[k // EVERY] + (k % EVERY) / EVERY
                         * (calls[k // EVERY] - calls[max(k // EVERY - 1, 0)])
                         for k in range(STEPS)])
    got = _outputs(run_fmu(fmus["mlp_every"], STEPS, H, _inputs("mlp")), "mlp")[:STEPS]
    np.testing.assert_allclose(got, expected, rtol=8 * EPS32,
                               atol=8 * EPS32 * np.abs(expected).max())


def test_fmus_pass_both_validators(fmus):
    for fmu in fmus.values():
        assert fmpy_validate(str(fmu)) == []
        assert validate_fmu(fmu) == []


@pytest.mark.parametrize("kind", ["mlp", "lstm"])
def test_libcosim_gives_the_same_outputs(fmus, kind):
    """libcosim reads the outputs after each step, that step's inputs still applied."""
    with FmpyInstance(fmus[kind]) as s:
        s.initialize()
        ours = []
        for k, row in enumerate(ROWS[kind]):
            s.set(dict(zip(NAMES[kind][0], row)))
            s.fmu.doStep(k * H, H)
            ours.append(s.get(NAMES[kind][1]))
    theirs = _outputs(run_fmu_libcosim(fmus[kind], STEPS, H, _inputs(kind)), kind)
    assert np.array_equal(theirs, ours)


def test_a_time_axis_graph_is_adapted_row_by_row(tmp_path):
    """Two inputs with a dynamic time axis (p float32 (T, 2), q float64 (T, 1)) -> o = p + q:
    the adapter graph takes rows (p0, p1, q) and gives o for every row at once."""
    graph = oh.make_graph([oh.make_node("Cast", ["q"], ["q32"], to=TensorProto.FLOAT),
                           oh.make_node("Add", ["p", "q32"], ["o"])], "sum", [
        oh.make_tensor_value_info("p", TensorProto.FLOAT, ["time", 2]),
        oh.make_tensor_value_info("q", TensorProto.DOUBLE, ["time", 1])], [
        oh.make_tensor_value_info("o", TensorProto.FLOAT, ["time", 2])])
    path = tmp_path / "sum.onnx"
    onnx.save(oh.make_model(graph, opset_imports=[oh.make_opsetid("", 17)], ir_version=10),
              str(path))
    read = read_graph(path, time_axis=True)
    assert read.input_names == ["p[0]", "p[1]", "q"] and read.output_names == ["o[0]", "o[1]"]
    x, u, p = ca.SX.sym("x", 0), ca.SX.sym("u", 3), ca.SX.sym("p", 0)
    network = graph_network(read, ca.Function("f", [x, u, p], [u]))
    session = ort.InferenceSession(str(network.model))
    assert json.loads(session.get_modelmeta().custom_metadata_map["input_signals"]) == [
        "p[0]", "p[1]", "q"]  # the names of its columns, for the FMU's messages
    rows = np.random.default_rng(5).normal(size=(4, 3))
    out = session.run(None, {network.input: rows})[0]
    assert np.array_equal(out, (rows[:, :2].astype(np.float32)
                                + rows[:, 2:].astype(np.float32)).astype(np.float64))
    with pytest.raises(ValueError, match="input 'p' has the dynamic dimension 'time'"):
        read_graph(path)


def _graph_file(path, inputs, outputs, nodes, metadata=None) -> str:
    model = oh.make_model(oh.make_graph(nodes, "g", inputs, outputs),
                          opset_imports=[oh.make_opsetid("", 17)], ir_version=10)
    onnx.helper.set_model_props(model, metadata or {})
    onnx.save(model, str(path))
    return str(path)


def test_graphs_that_cannot_be_an_fmu_are_named(tmp_path):
    dynamic = mlp_graph(tmp_path / "dynamic.onnx", dynamic_axes={"b": {0: "n"}})
    with pytest.raises(ValueError, match=r"dynamic.onnx: input 'b' has the dynamic dimension "
                                         r"'n'.*make_dynamic_shape_fixed --dim_param n"):
        onnx_system(dynamic)
    counts = _graph_file(tmp_path / "counts.onnx", [
        oh.make_tensor_value_info("k", TensorProto.INT64, [1])], [
        oh.make_tensor_value_info("y", TensorProto.FLOAT, [1])],
        [oh.make_node("Cast", ["k"], ["y"], to=TensorProto.FLOAT)])
    with pytest.raises(ValueError, match=r"counts.onnx: input 'k' holds INT64.*float32 or float64"):
        onnx_system(counts)
    (tmp_path / "weights.onnx").write_text("time,x\n0,1\n")
    with pytest.raises(ValueError, match=r"weights.onnx is not a readable ONNX model"):
        onnx_system(tmp_path / "weights.onnx")
    (tmp_path / "empty.onnx").write_bytes(b"")
    with pytest.raises(ValueError, match=r"empty.onnx is not a readable ONNX model"):
        onnx_system(tmp_path / "empty.onnx")
    identity = [oh.make_tensor_value_info("u", TensorProto.FLOAT, [2])], [
        oh.make_tensor_value_info("y", TensorProto.FLOAT, [2])], [
        oh.make_node("Identity", ["u"], ["y"])]
    missing = _graph_file(tmp_path / "missing.onnx", *identity,
                          {"state": json.dumps([{"input": "h", "output": "h_out"}])})
    with pytest.raises(ValueError, match="declares the state input 'h'"):
        onnx_system(missing)
    misnamed = _graph_file(tmp_path / "misnamed.onnx", *identity,
                           {"output_signals": json.dumps(["only one"])})
    with pytest.raises(ValueError, match=r"'output_signals' must list 2 names.*y \(2\)"):
        onnx_system(misnamed)


def test_the_command_line_builds_and_refuses(graphs, tmp_path, capsys):
    target = tmp_path / "lstm.fmu"
    assert main(["fmu", "build", "onnx", graphs["lstm"], "-o", str(target), "--every", "2"]) == 0
    assert target.is_file() and validate_fmu(target) == []
    task = tmp_path / "lstm-task.fmu"
    assert main(["fmu", "build", "onnx", graphs["lstm"], "-o", str(task), "--every", "2",
                 "--task"]) == 0
    assert validate_fmu(task) == [] and "sources/wrapper_task.c" in zipfile.ZipFile(task).namelist()
    bundled = tmp_path / "lstm-ort.fmu"
    assert main(["fmu", "build", "onnx", graphs["lstm"], "-o", str(bundled),
                 "--runtime", "onnxruntime"]) == 0
    assert "resources/model.onnx" in zipfile.ZipFile(bundled).namelist()
    assert "sources/flexff_net.c" in zipfile.ZipFile(target).namelist()  # c, the default
    assert main(["fmu", "build", "plant", "-o", str(tmp_path / "p.fmu"), "--task"]) == 2
    assert "the plant has none" in capsys.readouterr().err
    assert main(["fmu", "build", "plant", "-o", str(tmp_path / "p.fmu"), "--runtime", "c"]) == 2
    assert "the plant has none" in capsys.readouterr().err
    assert main(["fmu", "build", "onnx", str(tmp_path / "none.onnx"), "-o",
                 str(tmp_path / "none.fmu")]) == 2
    assert "none.onnx does not exist" in capsys.readouterr().err
    assert main(["fmu", "build", "onnx", "-o", str(tmp_path / "none.fmu")]) == 2
    assert "needs the graph" in capsys.readouterr().err
    assert not (tmp_path / "none.fmu").exists()
