"""FMUs with an embedded ONNX graph (fmu/network.py, c/onnx_network.c) against a reference
written out here: a running-sum graph with a float32 state, called every PERIOD steps, its
results extrapolated linearly in between; precomputed and step-by-step modes agree; states
restore exactly; libcosim agrees; bad graphs, a missing library and NaN give clear errors."""

import shutil
import struct
import zipfile
from ctypes import byref, c_char
from dataclasses import replace

import casadi as ca
import fmpy
import numpy as np
import onnx
import pytest
from fmpy import read_model_description
from fmpy.fmi2 import FMU2Slave, fmi2Error, fmi2FMUstate, fmi2OK
from onnx import TensorProto
from onnx import helper as oh

from flexff.fmu.codegen import NET_TABLE_FILE
from flexff.fmu.compile import run_compiler
from flexff.fmu.network import read_network
from flexff.fmu.system import System, Variable
from flexff.fmu.validation import validate_fmu
from tests.fmu_toys import LoggedSlave, build_toy, logging_callbacks, status_of
from tests.runners import run_fmu, run_fmu_libcosim

PERIOD = 3
STEPS = 40
H = 1e-3


def _save(graph: onnx.GraphProto, path) -> str:
    model = oh.make_model(graph, opset_imports=[oh.make_opsetid("", 17)], ir_version=8)
    onnx.checker.check_model(model)
    onnx.save(model, str(path))
    return str(path)


def running_sum_graph(path, n: int = 2) -> str:
    """forces[t] = acc + sum of inputs[0..t]; acc_out = acc + sum of all inputs (float32)."""
    nodes = [
        oh.make_node("Constant", [], ["axis"],
                     value=oh.make_tensor("axis", TensorProto.INT64, [], [0])),
        oh.make_node("CumSum", ["inputs", "axis"], ["running"]),
        oh.make_node("Cast", ["acc"], ["acc64"], to=TensorProto.DOUBLE),
        oh.make_node("Add", ["running", "acc64"], ["forces"]),
        oh.make_node("Constant", [], ["axes"],
                     value=oh.make_tensor("axes", TensorProto.INT64, [1], [0])),
        oh.make_node("ReduceSum", ["inputs", "axes"], ["total"], keepdims=1),
        oh.make_node("Cast", ["total"], ["total32"], to=TensorProto.FLOAT),
        oh.make_node("Add", ["acc", "total32"], ["acc_out"]),
    ]
    graph = oh.make_graph(nodes, "running_sum", [
        oh.make_tensor_value_info("inputs", TensorProto.DOUBLE, ["time", n]),
        oh.make_tensor_value_info("acc", TensorProto.FLOAT, [1, n])], [
        oh.make_tensor_value_info("forces", TensorProto.DOUBLE, ["time", n]),
        oh.make_tensor_value_info("acc_out", TensorProto.FLOAT, [1, n])])
    return _save(graph, path)


def sqrt_graph(path, n: int = 2) -> str:
    """Stateless forces = sqrt(inputs): NaN for a negative input."""
    graph = oh.make_graph([oh.make_node("Sqrt", ["inputs"], ["forces"])], "root", [
        oh.make_tensor_value_info("inputs", TensorProto.DOUBLE, ["time", n])], [
        oh.make_tensor_value_info("forces", TensorProto.DOUBLE, ["time", n])])
    return _save(graph, path)


def network_system(model, table=None, name="toy_network", runtime="c") -> System:
    """y = r + u, the network fed with 2 u."""
    x, u, p, w = ca.SX.sym("x", 0), ca.SX.sym("u", 2), ca.SX.sym("p", 0), ca.SX.sym("w", 0)
    r = ca.SX.sym("r", 2)
    net = replace(read_network(model, ca.Function("network_input", [x, u, p], [2 * u]), PERIOD,
                               table), runtime=runtime)
    return System(
        name=name, description="running sum network toy", kind="discrete", states=(),
        inputs=(Variable("u1"), Variable("u2")), outputs=(Variable("y1"), Variable("y2")),
        parameters=(), initial_state=ca.Function("i", [p], [ca.SX(0, 1)]),
        dynamics=ca.Function("d", [x, u, p], [ca.SX(0, 1)]),
        output=ca.Function("o", [x, u, p, w, r], [r + u]), sample_time=H, network=net)


def reference_outputs(u: np.ndarray) -> np.ndarray:
    """The documented scheme by hand: calls at k = 0, PERIOD, ...; r extrapolated in between."""
    calls = np.cumsum(2 * u[::PERIOD], axis=0)
    out = np.empty_like(u)
    for k in range(len(u)):
        j, phase = divmod(k, PERIOD)
        before = calls[max(j - 1, 0)]
        out[k] = calls[j] + phase / PERIOD * (calls[j] - before) + u[k]
    return out


INPUTS = np.column_stack([np.arange(STEPS) % 7 - 3.0, (np.arange(STEPS) // 2) * 0.5])


@pytest.fixture(scope="module")
def graph(tmp_path_factory):
    return running_sum_graph(tmp_path_factory.mktemp("graph") / "running_sum.onnx")


@pytest.fixture(scope="module")
def step_fmu(graph, tmp_path_factory):
    return build_toy(network_system(graph), tmp_path_factory)


@pytest.fixture(scope="module")
def ort_fmu(graph, tmp_path_factory):
    """The step FMU with the graph in onnxruntime."""
    return build_toy(network_system(graph, name="toy_network_ort", runtime="onnxruntime"),
                     tmp_path_factory)


@pytest.fixture(scope="module")
def precomputed_fmu(graph, tmp_path_factory):
    held = np.vstack([INPUTS, INPUTS[-1]])  # run_fmu reads the last sample with the last inputs
    table = np.column_stack([np.arange(STEPS + 1) * H, held])
    return build_toy(network_system(graph, table, "toy_network_pre"), tmp_path_factory)


def _run(fmu, runner=run_fmu):
    out = runner(fmu, STEPS, H, {"u1": INPUTS[:, 0], "u2": INPUTS[:, 1]})
    return np.column_stack([out["y1"], out["y2"]])


def test_outputs_follow_the_call_and_extrapolation_scheme(step_fmu):
    assert np.array_equal(_run(step_fmu)[:STEPS], reference_outputs(INPUTS))


def test_precomputed_mode_equals_step_by_step(step_fmu, precomputed_fmu):
    assert np.array_equal(_run(precomputed_fmu), _run(step_fmu))


def test_fmus_pass_validation(step_fmu, precomputed_fmu, ort_fmu):
    assert validate_fmu(step_fmu) == []
    assert validate_fmu(precomputed_fmu) == []
    assert validate_fmu(ort_fmu) == []
    names = zipfile.ZipFile(step_fmu).namelist()  # the graph compiled in as C
    assert "sources/flexff_net.c" in names
    assert not any("onnxruntime" in n or n.endswith(".onnx") for n in names)
    names = zipfile.ZipFile(ort_fmu).namelist()
    assert "resources/model.onnx" in names
    assert any(n.startswith("binaries/") and "libonnxruntime" in n for n in names)


def test_both_runtimes_give_the_same_outputs(step_fmu, ort_fmu):
    assert np.array_equal(_run(step_fmu), _run(ort_fmu))


def test_libcosim_gives_the_same_outputs(step_fmu, precomputed_fmu):
    """libcosim reads the outputs after each step with that step's inputs still applied."""
    for fmu in (step_fmu, precomputed_fmu):
        s = LoggedSlave(fmu)
        s.initialize()
        ours = []
        for k in range(STEPS):
            s.set(u1=INPUTS[k, 0], u2=INPUTS[k, 1])
            s.slave.doStep(k * H, H)
            ours.append(s.get("y1", "y2"))
        s.free()
        assert np.array_equal(_run(fmu, run_fmu_libcosim), ours)


def _steps(s, ks):
    """Set the inputs of step k, read the outputs, step; for each k."""
    out = []
    for k in ks:
        s.set(u1=INPUTS[k, 0], u2=INPUTS[k, 1])
        out.append(s.get("y1", "y2"))
        s.slave.doStep(k * H, H)
    return out


@pytest.mark.parametrize("split", [PERIOD * 4, PERIOD * 4 + 1, PERIOD * 4 + 2])
def test_restored_state_continues_exactly(step_fmu, split):
    s = LoggedSlave(step_fmu)
    s.initialize()
    _steps(s, range(split))
    saved = s.slave.getFMUstate()
    blob = s.slave.serializeFMUstate(saved)
    straight = _steps(s, range(split, STEPS))
    s.slave.setFMUstate(saved)
    assert _steps(s, range(split, STEPS)) == straight
    s.slave.setFMUstate(s.slave.deSerializeFMUstate(blob))
    assert _steps(s, range(split, STEPS)) == straight
    s.slave.freeFMUstate(saved)
    s.free()


def test_read_network_names_what_does_not_fit(graph, tmp_path):
    x, u, p = ca.SX.sym("x", 0), ca.SX.sym("u", 3), ca.SX.sym("p", 0)
    with pytest.raises(ValueError, match=r"takes 2 inputs per step.*gives 3"):
        read_network(graph, ca.Function("f", [x, u, p], [u]))
    with pytest.raises(ValueError, match="does not exist"):
        read_network(tmp_path / "missing.onnx", ca.Function("f", [x, u, p], [u]))
    (tmp_path / "junk.onnx").write_bytes(b"not a graph")
    with pytest.raises(ValueError, match="not a readable ONNX model"):
        read_network(tmp_path / "junk.onnx", ca.Function("f", [x, u, p], [u]))
    lonely = oh.make_graph([oh.make_node("Identity", ["inputs"], ["forces"])], "g", [
        oh.make_tensor_value_info("inputs", TensorProto.DOUBLE, ["time", 2]),
        oh.make_tensor_value_info("h", TensorProto.FLOAT, [1, 2])], [
        oh.make_tensor_value_info("forces", TensorProto.DOUBLE, ["time", 2])])
    v = ca.SX.sym("v", 2)
    with pytest.raises(ValueError, match=r"state input 'h'.*needs an output 'h_out'"):
        read_network(_save(lonely, tmp_path / "lonely.onnx"), ca.Function("f", [x, v, p], [v]))


def _instantiate_log(fmu, folder) -> str:
    """The messages of a failing fmi2Instantiate of the FMU unpacked in `folder`."""
    md = read_model_description(str(fmu))
    slave = FMU2Slave(guid=md.guid, unzipDirectory=str(folder),
                      modelIdentifier=md.coSimulation.modelIdentifier, instanceName="x")
    callbacks, messages = logging_callbacks()
    with pytest.raises(Exception, match="instantiate"):
        slave.instantiate(callbacks=callbacks)
    return "\n".join(m for _, _, m in messages)


def _unpacked(fmu, folder):
    with zipfile.ZipFile(fmu) as zf:
        zf.extractall(folder)
    return folder


def test_a_swapped_graph_is_reported(ort_fmu, tmp_path):
    folder = _unpacked(ort_fmu, tmp_path / "fmu")
    sqrt_graph(folder / "resources" / "model.onnx")
    assert "state tensors" in _instantiate_log(ort_fmu, folder)  # 1 input, 2 expected
    running_sum_graph(folder / "resources" / "model.onnx", n=3)
    assert ("graph tensor 'inputs' has size 3 in dimension 1, expected 2"
            in _instantiate_log(ort_fmu, folder))


def test_a_missing_library_is_reported(ort_fmu, tmp_path):
    folder = _unpacked(ort_fmu, tmp_path / "never-loaded")  # a path dlopen has not seen
    for library in (folder / "binaries").rglob("libonnxruntime*"):
        library.unlink()
    assert "cannot load the onnxruntime library" in _instantiate_log(ort_fmu, folder)


def test_inputs_off_the_precomputed_table_are_refused(precomputed_fmu):
    s = LoggedSlave(precomputed_fmu)
    s.initialize()
    s.set(u1=INPUTS[0, 0], u2=INPUTS[0, 1])
    s.slave.doStep(0.0, H)
    s.set(u1=INPUTS[1, 0] + 0.5, u2=INPUTS[1, 1])
    assert status_of(s.slave.doStep, H, H) == fmi2Error
    assert "Input 'u1'" in s.log() and "differs from the precomputation table" in s.log()
    s.free()


def _with_long_table(fmu, folder, rows: int):
    """The FMU unpacked in `folder` with a precomputation table of `rows` valid rows."""
    folder = _unpacked(fmu, folder)
    lines = ["time,u1,u2", *(f"{k * H!r},0.0,0.0" for k in range(rows))]
    (folder / "resources" / NET_TABLE_FILE).write_text("\n".join(lines) + "\n")
    return folder


def test_a_table_that_cannot_grow_is_an_error(precomputed_fmu, tmp_path):
    """The table starts with room for 1024 rows and doubles; when realloc fails (a library
    rebuilt from sources/ with a realloc that always fails), fmi2Instantiate fails with a
    message, never with a truncated table."""
    md = read_model_description(str(precomputed_fmu))
    intact = _with_long_table(precomputed_fmu, tmp_path / "intact", 2000)
    slave = FMU2Slave(guid=md.guid, unzipDirectory=str(intact), instanceName="x",
                      modelIdentifier=md.coSimulation.modelIdentifier)
    slave.instantiate()  # the table itself is valid
    slave.freeInstance()
    folder = _with_long_table(precomputed_fmu, tmp_path / "no-realloc", 2000)
    (tmp_path / "failing.c").write_text(
        "#include <stddef.h>\nvoid *failing_realloc(void *p, size_t n) "
        "{ (void)p; (void)n; return NULL; }\n")
    sources = [folder / "sources" / f for f in
               md.buildConfigurations[0].sourceFileSets[0].sourceFiles]
    library = folder / "binaries" / fmpy.platform / f"{md.coSimulation.modelIdentifier}.so"
    run_compiler([*sources, tmp_path / "failing.c"], library, [folder / "sources"],
                 extra_flags=("-shared", "-Drealloc=failing_realloc"), libraries=("-lm", "-ldl"))
    assert ("out of memory reading" in (log := _instantiate_log(precomputed_fmu, folder))
            and "(at row 1025)" in log), log


def test_a_non_finite_result_stops_the_step(tmp_path_factory):
    fmu = build_toy(network_system(sqrt_graph(tmp_path_factory.mktemp("g") / "sqrt.onnx"),
                                   name="toy_sqrt"), tmp_path_factory)
    s = LoggedSlave(fmu)
    s.initialize()
    s.set(u1=4.0, u2=1.0)
    assert s.get("y1", "y2") == [4.0 + np.sqrt(8.0), 1.0 + np.sqrt(2.0)]
    s.slave.doStep(0.0, H)
    s.slave.doStep(H, H)
    s.slave.doStep(2 * H, H)
    s.set(u1=-1.0)
    assert status_of(s.slave.doStep, 3 * H, H) == fmi2Error
    assert "The network returned" in s.log() and "(result 1 of 2) at t = 0.003" in s.log()
    s.free()


def test_a_failed_network_call_leaves_no_result_behind(tmp_path_factory):
    """After a call that returned NaN, going back to the inputs of the call before must run
    the graph again: the failed call had overwritten the kept result (NaN read with fmi2OK)."""
    fmu = build_toy(network_system(sqrt_graph(tmp_path_factory.mktemp("g") / "sqrt.onnx"),
                                   name="toy_sqrt_again"), tmp_path_factory)
    s = LoggedSlave(fmu)
    s.initialize()
    s.set(u1=4.0, u2=1.0)
    good = s.get("y1", "y2")
    s.set(u1=-1.0)
    assert status_of(lambda: s.get("y1")) == fmi2Error
    s.set(u1=4.0)
    assert s.get("y1", "y2") == good
    s.free()


def test_a_copy_of_the_fmu_runs_from_elsewhere(step_fmu, tmp_path):
    """The library is found next to the FMU's own binary, wherever it was unpacked."""
    moved = tmp_path / "a folder with spaces" / "copy.fmu"
    moved.parent.mkdir()
    shutil.copy(step_fmu, moved)
    assert np.array_equal(_run(moved), _run(step_fmu))


# --- precomputed mode: restored states, corrupt states, the end of the table ----------------

@pytest.mark.parametrize("split", [PERIOD * 4, PERIOD * 4 + 1])
@pytest.mark.parametrize("how", ["set", "deserialize"])
def test_a_state_restored_into_an_uninitialized_instance_continues(precomputed_fmu, split, how):
    """Checkpoint and restart: the state of an initialized instance, restored into one that
    was never initialized, continues exactly (it crashed: the table was only computed in
    fmi2ExitInitializationMode)."""
    s = LoggedSlave(precomputed_fmu, instance_name="first")
    s.initialize()
    _steps(s, range(split))
    saved = s.slave.getFMUstate()
    blob = s.slave.serializeFMUstate(saved)
    straight = _steps(s, range(split, STEPS))
    fresh = LoggedSlave(precomputed_fmu, instance_name="restarted")
    fresh.slave.setFMUstate(saved if how == "set" else fresh.slave.deSerializeFMUstate(blob))
    assert _steps(fresh, range(split, STEPS)) == straight
    fresh.free()
    s.slave.freeFMUstate(saved)
    s.free()


def _word_offsets(before: bytes, after: bytes, fmt: str, change) -> list[int]:
    """Offsets of the aligned words of a serialized state that changed by `change` in a step
    (the header is 24 bytes; the fields follow, 8-byte aligned)."""
    return [k for k in range(24, len(before) - 7, 8)
            if abs(struct.unpack_from(fmt, after, k)[0] - struct.unpack_from(fmt, before, k)[0]
                   - change) <= 1e-15]


def _states_around_step(s, k: int) -> tuple[bytes, bytes]:
    """The serialized states of slave `s` after steps 0 .. k - 1, and after step k."""
    _steps(s, range(k))
    before = s.slave.serializeFMUstate(s.slave.getFMUstate())
    _steps(s, [k])
    return before, s.slave.serializeFMUstate(s.slave.getFMUstate())


def _patched(blob: bytes, offset: int, fmt: str, value) -> bytes:
    """`blob` with the 8-byte word at `offset` replaced by `value` packed as `fmt`."""
    return blob[:offset] + struct.pack(fmt, value) + blob[offset + 8:]


def _deserialize_status(s, blob: bytes) -> int:
    buffer = (c_char * len(blob)).from_buffer_copy(blob)
    return status_of(s.slave.fmi2DeSerializeFMUstate, s.slave.component, buffer, len(blob),
                     byref(fmi2FMUstate()))


def test_a_corrupt_serialized_state_is_refused(precomputed_fmu):
    """Every field that indexes memory is checked: a step counter outside the table (it was
    accepted and read out of bounds) or not matching the state's time, a non-finite time."""
    s = LoggedSlave(precomputed_fmu)
    s.initialize()
    before, blob = _states_around_step(s, 5)
    [counter] = _word_offsets(before, blob, "<q", 1)  # the network's step counter
    [clock] = _word_offsets(before, blob, "<d", H)  # the time
    assert _deserialize_status(s, blob) == fmi2OK
    rows = STEPS + 1
    for value in (-1, -PERIOD, rows, rows + PERIOD - 1, 2**62, -2**63):
        assert _deserialize_status(s, _patched(blob, counter, "<q", value)) == fmi2Error
        assert "corrupt state: network step counter" in s.messages[-1][2]
    assert _deserialize_status(s, _patched(blob, counter, "<q", PERIOD)) == fmi2Error
    assert "is not the time" in s.messages[-1][2]  # in the table, but not where the time is
    assert _deserialize_status(s, _patched(blob, clock, "<d", float("nan"))) == fmi2Error
    assert "corrupt state: time = nan" in s.messages[-1][2]
    s.free()


def test_a_corrupt_step_counter_is_refused_step_by_step(step_fmu):
    """Without a table the counter only needs to be one a run can reach (one near LONG_MAX
    overflowed in the next step, a negative one gave a negative phase)."""
    s = LoggedSlave(step_fmu)
    s.initialize()
    before, blob = _states_around_step(s, 4)
    [counter] = _word_offsets(before, blob, "<q", 1)
    for value in (-1, 2**63 - 1, 2**53 + 1):
        assert _deserialize_status(s, _patched(blob, counter, "<q", value)) == fmi2Error
        assert "corrupt state: network step counter" in s.messages[-1][2]
    s.free()


@pytest.fixture(scope="module")
def short_table_fmu(graph, tmp_path_factory):
    """Precomputed over 4 model periods: the last row of the table is a call point."""
    rows = 4 * PERIOD
    table = np.column_stack([np.arange(rows) * H, INPUTS[:rows]])
    return build_toy(network_system(graph, table, "toy_network_short"), tmp_path_factory)


def test_no_step_past_the_end_of_the_table(short_table_fmu, step_fmu):
    """A step from the table's last row is refused (the next read was past the table), and
    the last row itself reads as step by step."""
    rows = 4 * PERIOD
    s, reference = LoggedSlave(short_table_fmu), LoggedSlave(step_fmu)
    for slave in (s, reference):
        slave.initialize()
        _steps(slave, range(rows - 1))
        slave.set(u1=INPUTS[rows - 1, 0], u2=INPUTS[rows - 1, 1])
    assert status_of(s.slave.doStep, (rows - 1) * H, H) == fmi2Error
    assert f"the precomputation table ({rows} rows) ends at t = 0.011" in s.log()
    assert s.get("y1", "y2") == reference.get("y1", "y2")  # still at the last row
    s.free()
    reference.free()
