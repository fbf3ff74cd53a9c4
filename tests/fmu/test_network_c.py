"""The network generated as C (fmu.network_c) against onnxruntime: every model kind flexff
exports, step by step with the state carried, on realistic and on random inputs; graphs it
must refuse; the learned feedforward FMU built with it (self-contained sources, validation,
FMPy, the same forces as the onnxruntime build)."""

import ctypes
import json
import shutil
import subprocess
import zipfile

import numpy as np
import onnx
import pytest
from onnx import TensorProto
from onnx import helper as oh

from flexff.controllers.features import reference_features
from flexff.controllers.learned_feedforward import learned_feedforward_system
from flexff.cosim.config import config_examples, parse_config
from flexff.cosim.run import run_config
from flexff.fmu.build import build_fmu
from flexff.fmu.compile import compiler
from flexff.fmu.errors import InputError
from flexff.fmu.network_c import generate_network_c, supported_operators
from flexff.fmu.network_plan import plan_graph
from flexff.fmu.onnx_fmu import onnx_system
from flexff.fmu.validation import validate_fmu
from flexff.learning.dataset import REFERENCE_SIGNALS
from flexff.learning.export import export, run_steps, session
from flexff.learning.threads import torch_threads
from flexff.plant.references import thesis_evaluation
from tests.helpers import REPOSITORY, train_tiny_models
from tests.runners import run_fmu

TOLERANCE = 1e-5  # float32: |C - onnxruntime| relative to the largest |force|
STEPS = 300  # consecutive calls, the state carried
TINY = {"lstm": {"hidden": 12, "layers": 2},
        "cnn-lstm": {"hidden": 8, "conv_channels": [6, 4], "conv_kernels": [3, 2]},
        "tcn": {"channels": 8, "levels": 3, "feature_set": "directions"},
        "pgnn": {"channels": 8, "levels": 3}}
# the graph of each kind that computes its own features from the reference, for one kind:
# the features' operators (Atan, Sqrt, Where, ...) besides the network's
GRAPHS = [*TINY, "tcn-reference"]
KERNELS = REPOSITORY / "flexff" / "fmu" / "c"


@pytest.fixture(scope="module")
def models(tmp_path_factory):
    folder = train_tiny_models(tmp_path_factory.mktemp("cnet"), TINY, seed=7)
    with torch_threads():
        export(folder / "tcn", folder / "tcn-reference.onnx", inputs="reference")
    return folder


class CNetwork:
    """The generated C of a graph compiled into a shared library, called through ctypes."""

    def __init__(self, model, folder):
        files = generate_network_c(model, "net")
        for name, text in files.items():
            (folder / name).write_text(text)
        library = folder / "net.so"
        subprocess.run([compiler(), "-O2", "-std=c99", "-fPIC", "-shared", "-ffp-contract=off",
                        "-Wall", "-Wextra", "-pedantic", "-Werror", f"-I{KERNELS}",
                        str(folder / "net.c"), "-o", str(library), "-lm"], check=True)
        self.lib = ctypes.CDLL(str(library))
        self.lib.net_work_size.restype = ctypes.c_size_t
        self.work = ctypes.create_string_buffer(self.lib.net_work_size())
        plan = plan_graph(onnx.load(str(model)), str(model))  # the shapes of one row per call
        self.inputs = [t.name for t in plan.inputs]
        self.outputs = {t.name: (t.shape, oh.tensor_dtype_to_np_dtype(t.dtype))
                        for t in plan.outputs}

    def run(self, feeds: dict[str, np.ndarray]) -> list[np.ndarray]:
        ins = [np.ascontiguousarray(feeds[n]) for n in self.inputs]
        outs = [np.zeros(shape, dtype) for shape, dtype in self.outputs.values()]
        pointers = [(ctypes.c_void_p * len(a))(*[x.ctypes.data for x in a]) for a in (ins, outs)]
        assert self.lib.net_run(self.work, *pointers) == 0
        return outs


def c_steps(net: CNetwork, model, inputs):
    """Forces (T, 2), one row per call of the C network `net` of `model`, its state outputs
    fed back."""
    state = {i.name: np.zeros(i.shape, np.float32) for i in session(model).get_inputs()
             if i.name != "inputs"}
    forces = []
    for row in inputs:
        result = net.run({"inputs": row[None, :], **state})
        forces.append(result[0][0])
        state = {n[:-len("_out")]: v for n, v in zip(list(net.outputs)[1:], result[1:])}
    return np.array(forces)


def realistic_inputs(model):
    """The model's inputs along the thesis's evaluation reference at its 100 Hz: the
    features, or the reference itself."""
    meta = {p.key: p.value for p in onnx.load(str(model)).metadata_props}
    signals = thesis_evaluation().signals()
    reference = {n: signals[n][2000:2000 + 10 * STEPS:10] for n in REFERENCE_SIGNALS}
    if meta["input_kind"] == "reference":
        return np.column_stack([reference[n] for n in REFERENCE_SIGNALS])
    return reference_features(reference, meta["feature_set"])


def random_inputs(model, rng):
    """Inputs drawn uniformly from the training range of each feature (for a reference
    model, the evaluation reference with noise of a few percent of each signal's span)."""
    meta = {p.key: p.value for p in onnx.load(str(model)).metadata_props}
    if meta["input_kind"] == "reference":
        base = realistic_inputs(model)
        return base + 0.03 * np.ptp(base, axis=0) * rng.standard_normal(base.shape)
    span = json.loads(meta["feature_range"])
    low, high = np.array(span["low"]), np.array(span["high"])
    return low + (high - low) * rng.random((STEPS, low.size))


def relative(got, expected):
    return float(np.abs(got - expected).max() / np.abs(expected).max())


@pytest.mark.parametrize("kind", GRAPHS)
def test_generated_c_equals_onnxruntime_step_by_step(models, kind, rng, tmp_path):
    model = models / f"{kind}.onnx"
    net = CNetwork(model, tmp_path)  # loaded once: a library is never rewritten while loaded
    for inputs in (realistic_inputs(model), random_inputs(model, rng)):
        expected = run_steps(session(model), inputs)
        assert np.all(np.isfinite(expected))
        assert relative(c_steps(net, model, inputs), expected) <= TOLERANCE


def graph_of(node, inputs, outputs, initializers=()):
    graph = oh.make_graph([node], "g", inputs, outputs, list(initializers))
    return oh.make_model(graph, opset_imports=[oh.make_opsetid("", 17)])


def test_an_unsupported_operator_is_refused_by_name():
    model = graph_of(oh.make_node("Hardmax", ["x"], ["y"], name="pick"),
                     [oh.make_tensor_value_info("x", TensorProto.FLOAT, [1, 4])],
                     [oh.make_tensor_value_info("y", TensorProto.FLOAT, [1, 4])])
    with pytest.raises(InputError, match=r"^g: node 'pick' \(Hardmax\): operator not supported "
                                         r"by the C network; supported: .*LSTM") as error:
        generate_network_c(model, name="g")
    assert "\n" not in str(error.value)
    assert "Hardmax" not in supported_operators() and "Conv" in supported_operators()


def test_a_dynamic_dimension_other_than_time_is_refused():
    model = graph_of(oh.make_node("Relu", ["x"], ["y"]),
                     [oh.make_tensor_value_info("x", TensorProto.FLOAT, ["time", "width"])],
                     [oh.make_tensor_value_info("y", TensorProto.FLOAT, ["time", "width"])])
    with pytest.raises(InputError, match="input 'x' has the dynamic dimension 'width' at axis 1"):
        generate_network_c(model, name="g")


def test_a_2d_convolution_is_refused_naming_the_node():
    weight = oh.make_tensor("w", TensorProto.FLOAT, [1, 1, 1, 1], [1.0])
    model = graph_of(oh.make_node("Conv", ["x", "w"], ["y"], name="conv2d"),
                     [oh.make_tensor_value_info("x", TensorProto.FLOAT, [1, 1, 2, 2])],
                     [oh.make_tensor_value_info("y", TensorProto.FLOAT, [1, 1, 2, 2])], [weight])
    with pytest.raises(InputError, match=r"node 'conv2d' \(Conv\): only 1-D convolutions"):
        generate_network_c(model, name="g")


@pytest.fixture(scope="module")
def feedforward_fmus(models, tmp_path_factory):
    folder = tmp_path_factory.mktemp("ff")
    return {(kind, runtime): build_fmu(learned_feedforward_system(
        models / f"{kind}.onnx", 1e-3, runtime=runtime), folder / f"{kind}-{runtime}.fmu")
        for kind in ("lstm", "tcn") for runtime in ("c", "onnxruntime")}


def reference_run(fmu, steps=1000):
    signals = thesis_evaluation().signals()
    inputs = {n: signals[n][2000:2000 + steps] for n in REFERENCE_SIGNALS}
    out = run_fmu(fmu, steps, 1e-3, inputs)
    return np.column_stack([out["Fx_ff"], out["Fy_ff"]])


@pytest.mark.parametrize("kind", ["lstm", "tcn"])
def test_the_feedforward_fmu_with_c_needs_no_runtime(feedforward_fmus, kind):
    fmu = feedforward_fmus[kind, "c"]
    names = zipfile.ZipFile(fmu).namelist()
    assert not any("onnxruntime" in n for n in names)
    assert "sources/flexff_net.c" in names and not any(n.startswith("resources/") for n in names)
    assert validate_fmu(fmu) == []
    expected = reference_run(feedforward_fmus[kind, "onnxruntime"])
    assert relative(reference_run(fmu), expected) <= TOLERANCE


def test_fmpy_builds_the_binary_from_the_sources_alone(feedforward_fmus, tmp_path):
    """FMPy's CMake build of the sources (nothing but the FMU's own files) runs as ours."""
    build = pytest.importorskip("fmpy.build")
    if shutil.which("cmake") is None:
        pytest.skip("FMPy builds FMUs with CMake, which is not installed")
    folder = tmp_path / "unzipped"
    with zipfile.ZipFile(feedforward_fmus["lstm", "c"]) as zf:
        zf.extractall(folder)
    shutil.rmtree(folder / "binaries")
    (tmp_path / "build").mkdir()
    build.build_platform_binary(folder, tmp_path / "build")
    fmu = tmp_path / "lstm.fmu"
    with zipfile.ZipFile(fmu, "w") as zf:
        for path in sorted(folder.rglob("*")):
            if path.is_file():
                zf.write(path, path.relative_to(folder).as_posix())
    expected = reference_run(feedforward_fmus["lstm", "c"], 200)
    assert np.array_equal(reference_run(fmu, 200), expected)


def test_closed_loop_e2_is_the_same_with_either_runtime(models, tmp_path):
    """The thesis's evaluation loop with the physics-guided model: e2 of the C network within
    1e-3 (relative) of onnxruntime's."""
    e2 = {}
    for runtime in ("c", "onnxruntime"):
        text = config_examples()["thesis-eval-pid"].replace(
            'kind = "none"', f'kind = "learned"\nmodel = "{models / "pgnn.onnx"}"\n'
                             f'runtime = "{runtime}"').replace("stop = 15.0", "stop = 2.0")
        metrics = run_config(parse_config(text, name=runtime), tmp_path / runtime)
        e2[runtime] = np.array([metrics[axis]["e2"] for axis in ("x", "y")])
    assert np.all(np.abs(e2["c"] - e2["onnxruntime"]) <= 1e-3 * e2["onnxruntime"])


def test_fmu_build_onnx_refuses_what_c_cannot_compute_unless_told_onnxruntime(tmp_path):
    model = graph_of(oh.make_node("Hardmax", ["x"], ["y"], name="pick"),
                     [oh.make_tensor_value_info("x", TensorProto.FLOAT, [1, 4])],
                     [oh.make_tensor_value_info("y", TensorProto.FLOAT, [1, 4])])
    path = tmp_path / "hardmax.onnx"
    onnx.save(model, str(path))
    with pytest.raises(InputError, match=rf"^{path}: node '.*pick' \(Hardmax\): operator not "
                                         rf"supported by the C network"):
        onnx_system(path)
    assert onnx_system(path, runtime="onnxruntime").network.runtime == "onnxruntime"
