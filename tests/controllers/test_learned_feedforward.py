"""The learned feedforward FMU against an independent runner of the same exported graph:
onnxruntime's Python API at the model's rate, its forces extrapolated linearly between calls,
the rigid-body force (numpy, CasADi) added for the physics-guided model. Both modes, state
restore, libcosim, validation, closed loop, and the errors for models that do not fit."""

import dataclasses
import json
import re

import numpy as np
import onnx
import pytest
from fmpy.fmi1 import FMICallException
from fmpy.fmi2 import fmi2Error

from flexff.controllers.features import feature_names, reference_features
from flexff.controllers.learned_feedforward import learned_feedforward_system
from flexff.controllers.manipulator import range_warning
from flexff.controllers.training_range import MARGIN, RangeExcess
from flexff.cosim.config import config_examples, parse_config
from flexff.cosim.run import run_config, simulate
from flexff.cosim.scenario import resolve
from flexff.fmu.build import build_fmu
from flexff.fmu.validation import validate_fmu
from flexff.learning.dataset import REFERENCE_SIGNALS
from flexff.learning.export import session
from flexff.learning.rigid import rigid_forces
from tests.fmu.test_network import running_sum_graph
from tests.fmu_toys import LoggedSlave, status_of
from tests.helpers import NETWORK_RTOL, thesis_reference_window, train_tiny_models
from tests.runners import run_fmu, run_fmu_libcosim

STEPS = 600  # 0.6 s of the thesis evaluation reference at 1 kHz
# one model per kind of input the FMU computes in C: the full features (LSTM), the directions
# set (TCN), the full features with the rigid-body prior (pgnn) and with the identified
# rigid-body force as inputs (TCN)
TINY = {"lstm": {"hidden": 12}, "tcn": {"channels": 8, "levels": 2, "feature_set": "directions"},
        "pgnn": {"channels": 8, "levels": 3},
        "tcn-force": {"model": "tcn", "channels": 8, "levels": 2, "force_input": True}}


@pytest.fixture(scope="module")
def models(tmp_path_factory):
    return train_tiny_models(tmp_path_factory.mktemp("learned"), TINY, seed=5)


@pytest.fixture(scope="module")
def reference():
    return thesis_reference_window(STEPS)


def metadata(model) -> dict[str, str]:
    """The graph's metadata as any ONNX reader sees it."""
    return {p.key: p.value for p in onnx.load(str(model)).metadata_props}


def independent_forces(model, reference, task: bool = False) -> np.ndarray:
    """The documented scheme with onnxruntime's Python API, step by step at the model rate
    (a linear skip beside the graph at every step);
    `task`: the network in its own task, each call's result used one model period later and
    extrapolated one period further (zero before the first)."""
    meta = metadata(model)
    period = round(1e3 / float(meta["sample_rate_hz"]))
    features = reference_features(reference, meta["feature_set"])
    if "force_input" in meta:  # the identified force, as the learning side computes it
        features = np.hstack([features, rigid_forces(features, meta["feature_set"],
                                                     json.loads(meta["force_input"]))])
    runtime = session(model)
    names = [o.name for o in runtime.get_outputs()]
    state = {i.name: np.zeros(i.shape, np.float32) for i in runtime.get_inputs()
             if i.name != "inputs"}
    calls = []
    for row in features[::period]:
        result = runtime.run(names, {"inputs": row[None, :], **state})
        calls.append(result[0][0])
        state = {n[:-len("_out")]: v for n, v in zip(names[1:], result[1:])}
    calls = np.array(calls)
    forces = np.zeros((len(features), calls.shape[1]))  # 2 forces or 3 currents
    for k in range(period if task else 0, len(features)):
        j, phase = divmod(k, period)
        if task:
            j, phase = j - 1, phase + period
        forces[k] = calls[j] + phase / period * (calls[j] - calls[max(j - 1, 0)])
    if "linear_inputs" in meta:  # the skip beside the graph, at every step
        skip = json.loads(meta["linear_inputs"])
        forces += features @ np.array(skip["weights"]).T + np.array(skip["bias"])
    if meta["prior"] == "rigid-body":
        labels = "currents" if json.loads(meta["output_signals"])[0] == "i1_ff" else "forces"
        forces += rigid_forces(features, meta["feature_set"],
                               json.loads(meta["prior_parameters"]), labels)
    return forces


def fmu_forces(fmu, reference, runner=run_fmu) -> np.ndarray:
    inputs = {n: reference[n][:STEPS] for n in REFERENCE_SIGNALS}
    out = runner(fmu, STEPS, 1e-3, inputs)
    return np.column_stack([out["Fx_ff"], out["Fy_ff"]])


@pytest.fixture(scope="module")
def fmus(models, reference, tmp_path_factory):
    folder = tmp_path_factory.mktemp("ff-fmus")
    held = {n: np.append(reference[n][:STEPS], reference[n][STEPS - 1]) for n in reference}
    return {(kind, mode): build_fmu(learned_feedforward_system(
        models / f"{kind}.onnx", 1e-3, held if mode == "precomputed" else None),
        folder / f"{kind}-{mode}.fmu") for kind in TINY for mode in ("step", "precomputed")}


@pytest.mark.parametrize("kind", list(TINY))
def test_fmu_forces_equal_an_independent_runner(models, fmus, reference, kind):
    expected = independent_forces(models / f"{kind}.onnx", reference)[:STEPS]
    got = fmu_forces(fmus[kind, "step"], reference)[:STEPS]
    scale = np.abs(expected).max()
    assert np.abs(got - expected).max() <= NETWORK_RTOL * scale


def test_task_mode_uses_each_call_one_period_later(models, reference, tmp_path):
    fmu = build_fmu(learned_feedforward_system(models / "lstm.onnx", 1e-3, task=True),
                    tmp_path / "lstm-task.fmu")
    expected = independent_forces(models / "lstm.onnx", reference, task=True)[:STEPS]
    got = fmu_forces(fmu, reference)[:STEPS]
    assert np.abs(got - expected).max() <= NETWORK_RTOL * np.abs(expected).max()


def test_a_run_configuration_puts_the_network_in_its_own_task(models, tmp_path):
    config = parse_config({"run": {"stop": 0.1}, "reference": {"kind": "thesis-eval"},
                           "feedforward": {"kind": "learned", "model": str(models / "lstm.onnx"),
                                           "mode": "task"}}, name="task")
    recording = simulate(resolve(config, tmp_path), progress=False)
    tasks = recording.timing.table(recording.wall_s)["tasks"]
    assert set(tasks) == {"base", "feedforward.network"}
    assert tasks["feedforward.network"]["period_us"] == pytest.approx(10e3)  # the model's 100 Hz
    forces = recording["Fx_ff"]  # the LSTM has no prior: zero until the first result
    assert np.all(forces[:10] == 0.0) and forces[10] != 0.0


@pytest.mark.parametrize("kind", list(TINY))
def test_precomputed_mode_equals_step_by_step(fmus, reference, kind):
    step = fmu_forces(fmus[kind, "step"], reference)
    precomputed = fmu_forces(fmus[kind, "precomputed"], reference)
    assert np.abs(step - precomputed).max() <= 1e-6 * np.abs(step).max()  # float32 rounding


def test_fmus_validate_and_run_under_libcosim(fmus, reference):
    for fmu in fmus.values():
        assert validate_fmu(fmu) == []
    for mode in ("step", "precomputed"):
        fmu = fmus["pgnn", mode]
        s = LoggedSlave(fmu)  # libcosim's order: set the inputs, step, read
        s.initialize()
        ours = []
        for k in range(STEPS):
            s.set(**{n: float(reference[n][k]) for n in REFERENCE_SIGNALS})
            s.slave.doStep(k * 1e-3, 1e-3)
            ours.append(s.get("Fx_ff", "Fy_ff"))
        s.free()
        assert np.array_equal(fmu_forces(fmu, reference, run_fmu_libcosim), ours)


def test_restored_state_continues_exactly(fmus, reference):
    s = LoggedSlave(fmus["lstm", "step"])
    s.initialize()

    def steps(ks):
        out = []
        for k in ks:
            s.set(**{n: float(reference[n][k]) for n in REFERENCE_SIGNALS})
            out.append(s.get("Fx_ff", "Fy_ff"))
            s.slave.doStep(k * 1e-3, 1e-3)
        return out

    steps(range(123))
    saved = s.slave.getFMUstate()
    straight = steps(range(123, 300))
    s.slave.setFMUstate(saved)
    assert steps(range(123, 300)) == straight
    s.slave.freeFMUstate(saved)
    s.free()


def test_closed_loop_with_the_learned_feedforward(models, tmp_path):
    text = config_examples()["thesis-eval-pid"].replace(
        'kind = "none"', f'kind = "learned"\nmodel = "{models / "pgnn.onnx"}"').replace(
        "stop = 15.0", "stop = 4.0")  # into the circle
    config = parse_config(text, name="pgnn")
    with pytest.warns(FutureWarning, match="kind = 'onnx' is deprecated, write kind = 'learned'"):
        old = parse_config(text.replace('kind = "learned"', 'kind = "onnx"'), name="pgnn")
    assert old.fmus == config.fmus and config.fmus[0].builtin == "learned-feedforward"
    metrics = run_config(config, tmp_path / "run")
    assert (tmp_path / "run" / "forces.png").is_file()
    assert np.isfinite(metrics["x"]["e2"]) and metrics["real_time_factor"] > 1
    # the synthetic set's random motion covers the reference: nothing to warn of
    assert metrics["feedforward_range"] == {"margin": MARGIN, "outside": []}
    assert range_warning(metrics) is None
    # every call of the network was timed: at points 0, 10, ..., 4000 (one per 10 ms model
    # period), plus the one at initialization
    calls = metrics["realtime"]["network_call_us"]["feedforward"]
    assert calls["calls"] == (4000 // 10 + 1) + 1
    assert 0 < calls["p50"] <= calls["p99"] <= calls["max"]


def test_the_network_logs_its_call_times_at_terminate(fmus, reference):
    s = LoggedSlave(fmus["lstm", "step"])
    s.initialize()
    for k in range(100):
        s.set(**{n: float(reference[n][k]) for n in REFERENCE_SIGNALS})
        s.slave.doStep(k * 1e-3, 1e-3)
    s.slave.terminate()
    line = next(line for line in s.log().splitlines() if "network calls" in line)
    assert re.search(r"network calls: \d+, p50 [\d.]+ us, p99 [\d.]+ us, max [\d.]+ us", line)
    s.free()


def test_a_run_outside_the_training_range_is_warned_of():
    excess = RangeExcess("theta_s1_ddot", "rad/s2", -0.25, 0.24, -6.2, 6.9, 14.0, 0.52)
    metrics = {"feedforward_range": {"margin": MARGIN, "outside": [dataclasses.asdict(excess)]}}
    assert "1 features (worst: theta_s1_ddot, 14 spans beyond)" in range_warning(metrics)


def test_models_that_do_not_fit_are_refused(models, tmp_path):
    with pytest.raises(ValueError, match="not a flexff feedforward model"):
        learned_feedforward_system(running_sum_graph(tmp_path / "toy.onnx"))
    with pytest.raises(ValueError, match="must divide its period"):
        learned_feedforward_system(models / "lstm.onnx", step=3e-3)
    with pytest.raises(ValueError, match="does not exist"):
        learned_feedforward_system(tmp_path / "none.onnx")
    graph = onnx.load(str(models / "pgnn.onnx"))
    for bad in ('{"tau_coulomb9": 0.01}', '{"tau_coulomb1": -0.01}', '[0.01]', 'friction'):
        onnx.helper.set_model_props(graph, {**metadata(models / "pgnn.onnx"),
                                            "prior_parameters": bad})
        onnx.save(graph, str(tmp_path / "bad.onnx"))
        with pytest.raises(ValueError, match=r"metadata prior_parameters .*export the model"):
            learned_feedforward_system(tmp_path / "bad.onnx")
    graph = onnx.load(str(models / "tcn-force.onnx"))
    for key, value in (("force_input", '{"m_ee9": 1.0}'), ("force_input", "null")):
        onnx.helper.set_model_props(graph, {**metadata(models / "tcn-force.onnx"), key: value})
        onnx.save(graph, str(tmp_path / "bad.onnx"))
        with pytest.raises(ValueError, match=r"metadata force_input .*export the model|"
                                             r"Fx_id.*are not the features signals"):
            learned_feedforward_system(tmp_path / "bad.onnx")


def _named_feature(message: str, model) -> str:
    """The feature a non-finite-input message names, checked against the model's features."""
    found = re.search(r"The network's input '(\w+)' \((\d+) of (\d+)\) is -?nan at t = ",
                      message)
    assert found, message
    names = feature_names(metadata(model)["feature_set"])
    assert (found[1], int(found[3])) == (names[int(found[2]) - 1], len(names))
    return found[1]


def test_a_reference_outside_the_workspace_is_named(models, fmus, reference, tmp_path):
    """Inverse kinematics of an unreachable reference: the feature that is not finite and the
    inputs are named (it was "the network returned -nan"), in both modes."""
    s = LoggedSlave(fmus["lstm", "step"])
    s.initialize()
    s.set(x_ref=0.5, y_ref=0.01)
    assert status_of(lambda: s.get("Fx_ff")) == fmi2Error
    _named_feature(s.log(), models / "lstm.onnx")
    assert "for the inputs x_ref = 0.5, y_ref = 0.01, vx_ref = 0" in s.log()
    assert "returned" not in s.log()
    s.free()
    away = {n: np.append(reference[n][:STEPS], reference[n][STEPS - 1]) for n in reference}
    away["x_ref"][20:] = 0.5
    fmu = build_fmu(learned_feedforward_system(models / "lstm.onnx", 1e-3, away),
                    tmp_path / "away.fmu")
    s = LoggedSlave(fmu)
    with pytest.raises(FMICallException):
        s.initialize()  # the precomputation runs over the whole table
    _named_feature(s.log(), models / "lstm.onnx")
    assert "at t = 0.02: it is not defined for the inputs x_ref = 0.5" in s.log()
    s.free()
