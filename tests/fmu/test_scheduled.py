"""FMI 3.0 scheduled execution: the learned feedforward's network task as clocks (fmu/c/
fmi3Functions.c, fmu.model_description3) and flexff's scheduler for such FMUs (fmu.scheduled).

- the FMI 3.0 feedforward with its network in its own task declares scheduled execution with
  two periodic input clocks (1 ms, priority 0; the network's period, priority 1) and passes
  `fmpy validate`;
- run scheduled, by flexff's master (`scheduled = true`) and by a scheduler written here over
  FMPy's FMU3ScheduledExecution, it gives its co-simulation twin's outputs bit for bit; a
  scheduler that never runs the network's partition gets the same outputs, each result then
  computed when due and counted as an overrun;
- a clock flexff cannot schedule (triggered, or off the run's steps) and a wrong key are refused,
  naming them.
"""

from __future__ import annotations

import ctypes
import zipfile

import fmpy.validation
import numpy as np
import pytest
from fmpy import extract, read_model_description
from fmpy.fmi3 import FMU3ScheduledExecution

from flexff.controllers.learned_feedforward import learned_feedforward_system
from flexff.cosim.config import ConfigError, parse_config
from flexff.cosim.master import CosimError, Master, ResolvedFmu
from flexff.cosim.run import simulate_config
from flexff.fmu.build import build_fmu
from flexff.fmu.importer import read_fmu
from flexff.fmu.scheduled import periodic_clocks
from tests.helpers import thesis_reference_window, train_tiny_models

STEPS = 200
STEP = 1e-3
PERIOD = 10  # the tiny model's network period in steps at 1 kHz (its card's 100 Hz)


@pytest.fixture(scope="module")
def fmus(tmp_path_factory):
    """The FMI 3.0 feedforward with its network in a task, and its FMI 2.0 twin."""
    folder = tmp_path_factory.mktemp("scheduled")
    models = train_tiny_models(folder, {"pgnn": {"channels": 8, "levels": 2}}, seed=5)
    system = learned_feedforward_system(models / "pgnn.onnx", STEP, task=True)
    return {v: build_fmu(system, folder / f"ff{v}.fmu", fmi_version=v) for v in (2, 3)}


@pytest.fixture(scope="module")
def reference():
    return thesis_reference_window(STEPS)


def _master_run(fmu, reference, scheduled):
    names = list(read_fmu(fmu).inputs)
    with Master([ResolvedFmu("ff", fmu, scheduled=scheduled)], names, STEP) as master:
        return master.run({n: np.asarray(reference[n], float) for n in names}, STEPS)


def test_the_task_is_described_as_clocks_and_validates(fmus):
    assert fmpy.validation.validate_fmu(str(fmus[3])) == []
    md = read_model_description(fmus[3])
    assert md.scheduledExecution.modelIdentifier == md.coSimulation.modelIdentifier
    clocks = periodic_clocks(fmus[3])
    assert [(c.name, c.priority) for c in clocks] == [("step_clock", 0), ("network_clock", 1)]
    assert [c.interval for c in clocks] == pytest.approx([STEP, PERIOD * STEP])
    assert "Clock" not in {read_fmu(fmus[3]).variables[n].type for n in read_fmu(fmus[3]).inputs}


def test_flexff_runs_it_scheduled_as_its_co_simulation_twins(fmus, reference):
    scheduled = _master_run(fmus[3], reference, True)
    for twin in (_master_run(fmus[3], reference, False), _master_run(fmus[2], reference, False)):
        for name in ("ff.Fx_ff", "ff.Fy_ff"):
            assert np.array_equal(scheduled[name], twin[name]), name
    assert np.abs(scheduled["ff.Fx_ff"]).max() > 0


def _fmpy_scheduled(fmu, reference, network_partition):
    """FMPy's scheduled-execution binding driven by a loop of this test, as a master steps a
    co-simulation FMU: at each point the inputs set and the forces read, then the step clock's
    partition and (if `network_partition`) the network clock's where it ticks. The forces, and
    the task's counts (flexff_network_counts: calls handed over, results not ready when due,
    results the step computed itself)."""
    md = read_model_description(fmu)
    clocks = {c.name: c.value_reference for c in periodic_clocks(fmu)}
    vrs = {v.name: v.valueReference for v in md.modelVariables}
    inputs = [v.name for v in md.modelVariables if v.causality == "input" and v.type != "Clock"]
    instance = FMU3ScheduledExecution(guid=md.instantiationToken, unzipDirectory=extract(fmu),
                                      modelIdentifier=md.scheduledExecution.modelIdentifier,
                                      instanceName="ff")
    instance.instantiate()
    instance.enterInitializationMode(startTime=0.0)
    instance.exitInitializationMode()
    forces = []
    for k in range(STEPS):
        instance.setFloat64([vrs[n] for n in inputs], [float(reference[n][k]) for n in inputs])
        forces.append(instance.getFloat64([vrs["Fx_ff"], vrs["Fy_ff"]]))
        instance.activateModelPartition(clocks["step_clock"], k * STEP)
        if network_partition and k % PERIOD == 0:
            instance.activateModelPartition(clocks["network_clock"], k * STEP)
    counts = (ctypes.c_long * 3)()
    assert instance.dll.flexff_network_counts(ctypes.c_void_p(instance.component), counts) == 0
    instance.terminate()
    instance.freeInstance()
    return np.array(forces), list(counts)


def test_fmpy_driven_by_its_own_scheduler_gets_the_same_forces(fmus, reference):
    twin = _master_run(fmus[3], reference, False)
    expected = np.column_stack([twin["ff.Fx_ff"][:STEPS], twin["ff.Fy_ff"][:STEPS]])
    calls = len(range(0, STEPS, PERIOD))
    forces, counts = _fmpy_scheduled(fmus[3], reference, True)
    assert np.array_equal(forces, expected)
    assert counts == [calls, 0, 0]  # every result was ready: the step computed none
    # the network's partition never run: each result is computed when due (an overrun)
    forces, counts = _fmpy_scheduled(fmus[3], reference, False)
    assert np.array_equal(forces, expected)
    assert counts == [calls, calls - 1, calls - 1]  # the last call is never due


def test_a_clock_flexff_cannot_schedule_is_refused(fmus, tmp_path):
    triggered = tmp_path / "triggered.fmu"
    with zipfile.ZipFile(fmus[3]) as source, zipfile.ZipFile(triggered, "w") as target:
        for item in source.infolist():
            data = source.read(item)
            if item.filename == "modelDescription.xml":
                data = data.replace(b'intervalVariability="constant" intervalDecimal="0.01"',
                                    b'intervalVariability="triggered"')
            target.writestr(item, data)
    config = parse_config({"run": {"step": STEP, "stop": 0.01},
                           "fmu": {"ff": {"path": str(triggered), "scheduled": True,
                                          "unconnected": "start"}}})
    with pytest.raises(CosimError, match="clock 'network_clock' is an input clock of triggered "
                                         "interval: flexff schedules input clocks of a "
                                         "constant interval"):
        simulate_config(config)


@pytest.mark.parametrize("extra, message", [
    ({"scheduled": 1}, r"fmu\.ff\.scheduled: expected true or false"),
    ({"scheduled": True, "solver": "cvode"}, r"fmu\.ff\.solver"),
])
def test_bad_keys_name_themselves(fmus, extra, message):
    with pytest.raises(ConfigError, match=message):
        parse_config({"run": {"step": STEP, "stop": 0.01},
                      "fmu": {"ff": {"path": str(fmus[3]), "unconnected": "start", **extra}}})


def test_scheduled_needs_the_interface(fmus):
    with pytest.raises(ConfigError, match=r"fmu\.ff\.scheduled: ff2\.fmu has no "
                                          r"scheduled-execution interface"):
        parse_config({"run": {"step": STEP, "stop": 0.01},
                      "fmu": {"ff": {"path": str(fmus[2]), "unconnected": "start",
                                     "scheduled": True}}})


def test_isolated_and_scheduled_equals_in_process(fmus, reference, tmp_path):
    """The scheduler runs in the FMU's own (sandboxed) process too."""
    csv = tmp_path / "reference.csv"
    names = list(read_fmu(fmus[3]).inputs)
    rows = np.column_stack([np.arange(STEPS + 1) * STEP, *(reference[n] for n in names)])
    np.savetxt(csv, rows, delimiter=",", header=",".join(["time", *names]), comments="")

    def run(isolate):
        return simulate_config(parse_config({
            "run": {"step": STEP, "stop": STEPS * STEP},
            "source": [{"kind": "csv", "path": str(csv)}],
            "fmu": {"ff": {"path": str(fmus[3]), "scheduled": True, "isolate": isolate}}}))

    inside, alone = run(False), run(True)
    assert np.array_equal(inside["ff.Fx_ff"], alone["ff.Fx_ff"])
    assert np.abs(alone["ff.Fx_ff"]).max() > 0


def test_a_clock_off_the_run_s_steps_is_refused(fmus, reference):
    names = list(read_fmu(fmus[3]).inputs)
    with Master([ResolvedFmu("ff", fmus[3], scheduled=True)], names, 3 * STEP) as master:
        with pytest.raises(CosimError, match=r"clock 'step_clock' ticks every 0\.001 s, not a "
                                             r"whole number of the run's 0\.003 s steps"):
            master.run({n: np.asarray(reference[n][:11], float) for n in names}, 10)
