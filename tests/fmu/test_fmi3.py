"""FMI 3.0 builds (build_fmu fmi_version=3, `flexff fmu build --fmi 3`, `fmi = 3` on a built-in):
each validates under FMPy and computes bit for bit what its FMI 2.0 twin does, under FMPy and
in flexff's closed loop of plant, controller and learned feedforward."""

import subprocess
import sys
import zipfile

import fmpy
import fmpy.validation
import numpy as np
import pytest
from fmpy import read_model_description
from fmpy.fmi3 import FMU3Slave

from flexff.controllers.learned_feedforward import learned_feedforward_system
from flexff.cosim.config import ConfigError, config_examples, parse_config
from flexff.cosim.run import simulate_config
from flexff.fmu.build import build_fmu
from flexff.fmu.errors import InputError
from flexff.fmu.validation import validate_fmu
from flexff.plant.system import plant_system
from tests.fmu_toys import discrete_pi, duffing, extract
from tests.helpers import REPOSITORY, thesis_reference_window, train_tiny_models

STEPS = 300
TINY = {"pgnn": {"channels": 8, "levels": 2}}


@pytest.fixture(scope="module")
def models(tmp_path_factory):
    return train_tiny_models(tmp_path_factory.mktemp("learned"), TINY, seed=5)


@pytest.fixture(scope="module")
def reference():
    return thesis_reference_window(STEPS)


def twins(system, folder):
    """The FMI 2.0 and 3.0 FMUs of `system`, by version."""
    return {v: build_fmu(system, folder / f"{system.name}-{v}.fmu", fmi_version=v)
            for v in (2, 3)}


def fmpy_run(fmu, inputs=None):
    """FMPy's simulate_fmu over STEPS default steps, `inputs` (name -> STEPS + 1 values) or
    sines on every input, seed 3."""
    md = read_model_description(fmu)
    step = float(md.defaultExperiment.stepSize)
    time = np.arange(STEPS + 1) * step
    names = [v.name for v in md.modelVariables if v.causality == "input" and v.type != "Clock"]
    signals = np.zeros(STEPS + 1, dtype=[("time", float)] + [(n, float) for n in names])
    signals["time"] = time
    for i, name in enumerate(names):
        signals[name] = inputs[name] if inputs else 0.1 * np.sin(7 * time + i)
    return fmpy.simulate_fmu(fmu, stop_time=STEPS * step, step_size=step, output_interval=step,
                             input=signals, start_values={"seed": 3})


def assert_bit_equal(a, b):
    assert a.dtype.names == b.dtype.names and len(a) == len(b) == STEPS + 1
    assert all(np.array_equal(a[n], b[n]) for n in a.dtype.names)


@pytest.mark.parametrize("toy", [duffing, discrete_pi])
def test_a_toy_validates_and_equals_its_fmi2_twin_under_fmpy(toy, tmp_path):
    fmus = twins(toy(), tmp_path)
    assert fmpy.validation.validate_fmu(str(fmus[3])) == []
    assert validate_fmu(fmus[3], strict=True) == []  # flexff's checks: states restore exactly
    assert_bit_equal(fmpy_run(fmus[2]), fmpy_run(fmus[3]))


def test_the_plant_validates_and_equals_its_fmi2_twin_under_fmpy(tmp_path):
    fmus = twins(plant_system(), tmp_path)
    assert fmpy.validation.validate_fmu(str(fmus[3])) == []
    assert_bit_equal(fmpy_run(fmus[2]), fmpy_run(fmus[3]))


@pytest.mark.parametrize("mode", ["step", "task", "precomputed"])
def test_the_learned_feedforward_validates_and_equals_its_fmi2_twin_under_fmpy(
        models, reference, mode, tmp_path):
    """In its own task, and precomputed from a table in resources/ (where the FMI 3.0 FMU
    finds it from its resource path)."""
    table = reference if mode == "precomputed" else None
    fmus = twins(learned_feedforward_system(models / "pgnn.onnx", 1e-3, table,
                                            task=mode == "task"), tmp_path)
    assert fmpy.validation.validate_fmu(str(fmus[3])) == []
    a, b = (fmpy_run(fmus[v], reference) for v in (2, 3))
    assert_bit_equal(a, b)
    assert np.abs(a["Fx_ff"]).max() > 0


def closed_loop(models, fmi):
    """The thesis evaluation's PID loop with the tiny learned feedforward for 0.5 s, every
    built-in (plant, controller, feedforward) built as FMI `fmi` (the short form's `fmi`)."""
    text = config_examples()["thesis-eval-pid"].replace(
        'kind = "none"', f'kind = "learned"\nmodel = "{models / "pgnn.onnx"}"\nmode = "task"'
    ).replace("stop = 15.0", "stop = 0.5")
    for table in ("[plant]", "[controller]", "[feedforward]"):
        text = text.replace(table, f"{table}\nfmi = {fmi}")
    config = parse_config(text, name="fmi3")
    assert {f.builtin: f.fmi for f in config.fmus} == {
        "plant": fmi, "controller": fmi, "learned-feedforward": fmi}
    return simulate_config(config)


def test_a_closed_loop_of_fmi3_builtins_equals_the_fmi2_loop_bit_for_bit(models):
    a, b = closed_loop(models, 2), closed_loop(models, 3)
    assert np.array_equal(a.time, b.time) and list(a.signals) == list(b.signals)
    assert all(np.array_equal(a.signals[n], b.signals[n]) for n in a.signals)
    assert len(a.time) == 501, list(a.signals)
    feedforward = [n for n in a.signals if n.startswith("feedforward.")]
    assert feedforward and max(np.abs(a.signals[n]).max() for n in feedforward) > 0


def test_the_archive_holds_the_fmi3_layout_and_its_sources_rebuild_it(tmp_path):
    fmu = twins(duffing(), tmp_path)[3]
    with zipfile.ZipFile(fmu) as zf:
        names = zf.namelist()
        zf.extractall(tmp_path / "unzipped")
    assert "binaries/x86_64-linux/duffing.so" in names
    assert not any(n.startswith(f"binaries/{fmpy.platform}/") for n in names)
    md = read_model_description(str(fmu))
    assert md.fmiVersion == "3.0" and md.instantiationToken.startswith("{")
    files = md.buildConfigurations[0].sourceFileSets[0].sourceFiles
    src = tmp_path / "unzipped" / "sources"
    assert sorted(files) == sorted(p.name for p in src.glob("*.c"))
    library = tmp_path / "unzipped" / "binaries" / "x86_64-linux" / "duffing.so"
    nm = subprocess.run(["nm", "-D", "--defined-only", str(library)], capture_output=True,
                        text=True, check=True).stdout
    symbols = {line.split()[-1] for line in nm.splitlines()}
    assert "fmi3DoStep" in symbols and not any(s.startswith("fmi2") for s in symbols)
    subprocess.run(["gcc", "-shared", "-fPIC", f"-I{src}", *(str(src / f) for f in files),
                    "-o", str(library), "-lm"], check=True)
    rebuilt = tmp_path / "rebuilt.fmu"
    with zipfile.ZipFile(rebuilt, "w") as zout:
        for name in names:
            zout.write(tmp_path / "unzipped" / name, name)
    assert_bit_equal(fmpy_run(fmu), fmpy_run(rebuilt))


def test_messages_name_the_fmi3_functions_and_time_is_readable(tmp_path):
    fmu = twins(duffing(), tmp_path)[3]
    md = read_model_description(str(fmu))
    vr = {v.name: v.valueReference for v in md.modelVariables}
    messages = []
    slave = FMU3Slave(guid=md.instantiationToken, unzipDirectory=extract(fmu),
                      modelIdentifier="duffing", instanceName="toy")
    slave.instantiate(logMessage=lambda env, status, category, message:
                      messages.append(message.decode()))
    slave.enterInitializationMode(startTime=0.0)
    slave.exitInitializationMode()
    slave.doStep(0.0, 1e-3)
    assert slave.getFloat64([vr["time"], vr["q_true"]])[0] == 1e-3
    with pytest.raises(Exception, match="fmi3DoStep"):
        slave.doStep(0.5, 1e-3)
    assert messages[-1].startswith("fmi3DoStep(): currentCommunicationPoint = 0.5")
    with pytest.raises(Exception, match="fmi3SetFloat64"):
        slave.setFloat64([vr["q_true"]], [1.0])
    assert messages[-1] == "fmi3SetFloat64(): 'q_true' is an output and cannot be set."
    slave.terminate()
    slave.freeInstance()


def test_an_fmi_version_other_than_2_or_3_is_refused(tmp_path):
    with pytest.raises(InputError, match=r"FMI version 4: flexff builds FMI 2\.0 and 3\.0 FMUs"):
        build_fmu(duffing(), tmp_path / "d.fmu", fmi_version=4)
    cli = subprocess.run([sys.executable, "-m", "flexff", "fmu", "build", "plant", "--fmi", "4",
                          "-o", str(tmp_path / "p.fmu")], capture_output=True, text=True,
                         cwd=REPOSITORY)
    assert cli.returncode == 2
    assert cli.stderr.splitlines()[-1].endswith("argument --fmi: invalid choice: 4 (choose from "
                                                "2, 3)")
    text = '[run]\nstep = 0.001\nstop = 0.01\n[fmu.plant]\nbuiltin = "plant"\nfmi = 4\n'
    with pytest.raises(ConfigError, match=r"fmu\.plant\.fmi.*FMI 4: built-ins are built as "
                                          r"FMI 2 or 3"):
        parse_config(text)
    short = config_examples()["thesis-eval-pid"].replace("[plant]", "[plant]\nfmi = 4")
    with pytest.raises(ConfigError, match=r"plant\.fmi: FMI 4: built-ins are built as FMI 2"):
        parse_config(short)
