"""FMUs for several platforms from one build (fmu.platforms), each platform's library run here.

The plant, the feedback controller and a network FMU (the toy running sum as generated C, also
in its own task, a thread of the FMU; the learned feedforward of a tiny trained TCN in the slow
run) are built for every platform whose cross-compiler is installed. The same small importer
(tests/fmu/fmu_runner.c) runs each platform's library natively (linux64), under qemu-user
(aarch64-linux) and under Wine (win64) on the same inputs: their outputs must equal the linux64
library's. A source-only FMU, compiled by FMPy itself, must give the outputs of flexff's own
build under fmpy.simulate_fmu.
"""

import shutil
import zipfile
from dataclasses import replace
from pathlib import Path

import fmpy
import numpy as np
import pytest

from flexff.cli import main
from flexff.controllers.feedback import controller_system
from flexff.fmu.build import build_fmu, fmu_key
from flexff.fmu.errors import InputError
from flexff.fmu.platforms import PLATFORMS, host, resolve
from flexff.plant.system import plant_system
from tests.fmu.platform_runs import available_platforms, compile_runner, run_library
from tests.fmu.test_network import network_system, running_sum_graph
from tests.helpers import NETWORK_RTOL, train_tiny_models

STEPS = 300  # communication points of each run
AMPLITUDE = 0.01  # of every input's sine, in its own unit
# against linux64, relative to each output's largest magnitude. The libraries' own arithmetic is
# the same everywhere (no fused multiply-add: -ffp-contract=off); aarch64's glibc computes sin,
# exp, tanh ... as x86_64's does: bit-equal outputs, measured on every FMU here. mingw's C
# library rounds some of them otherwise: 6e-15 on the controller, and on a float32 network's
# tanh and sigmoid a float32 rounding (1.2e-7 measured on an LSTM: NETWORK_RTOL)
RTOL = {"aarch64-linux": 0.0, "win64": 1e-12}
OTHERS = tuple(RTOL)

pytestmark = pytest.mark.skipif(host() != "linux64", reason="compared with linux64 run natively")


@pytest.fixture(scope="module")
def folder(tmp_path_factory) -> Path:
    """One folder for the module's runs (a Wine prefix is made once, in it)."""
    return tmp_path_factory.mktemp("platforms")


@pytest.fixture(scope="module")
def fmus(folder) -> dict[str, Path]:
    """The plant, the controller and the toy network FMU, for every platform available."""
    toy = network_system(running_sum_graph(folder / "sum.onnx"))
    systems = {"plant": plant_system(), "controller": controller_system("nominal", step=1e-3),
               "network": toy,
               "network_task": replace(toy, network=replace(toy.network, task=True))}
    return {name: build_fmu(system, folder / f"{name}.fmu", platforms=available_platforms())
            for name, system in systems.items()}


@pytest.fixture(scope="module")
def runners(folder):
    """runners(platform) -> fmu_runner built for it, once per module."""
    built: dict[str, Path] = {}

    def runner(platform: str) -> Path:
        if platform not in built:
            built[platform] = compile_runner(platform, folder / f"runner-{platform}")
        return built[platform]

    return runner


def sine_inputs(fmu: Path, steps: int = STEPS) -> np.ndarray:
    """A sine of its own frequency about its start value on each of the FMU's Real inputs
    (steps x inputs)."""
    description = fmpy.read_model_description(str(fmu))
    start = np.array([float(v.start or 0.0) for v in description.modelVariables
                      if v.causality == "input" and v.type == "Real"])
    n = np.arange(len(start))
    t = np.arange(steps)[:, None] * float(description.defaultExperiment.stepSize)
    return start + AMPLITUDE * np.sin(2 * np.pi * (1.0 + n) * t + 0.3 * n)


def assert_same_outputs(fmu: Path, platform: str, runners, folder: Path, rtol: float) -> None:
    """The platform's library gives the linux64 library's outputs: bit-equal for rtol 0, else
    within rtol of each output's largest magnitude."""
    if platform not in available_platforms():
        pytest.skip(f"no {PLATFORMS[platform].compiler()} here "
                    f"(Debian: {PLATFORMS[platform].package})")
    inputs = sine_inputs(fmu)
    native = run_library(runners("linux64"), "linux64", fmu, folder, inputs)
    other = run_library(runners(platform), platform, fmu, folder, inputs)
    assert native.shape == other.shape == (STEPS, native.shape[1])
    if rtol == 0.0:
        np.testing.assert_array_equal(other, native)
    else:
        scale = np.maximum(np.abs(native).max(axis=0), 1e-300)
        np.testing.assert_array_less(np.abs(other - native) / scale, rtol)


@pytest.mark.parametrize("platform", OTHERS)
@pytest.mark.parametrize("name", ["plant", "controller", "network", "network_task"])
def test_each_platform_gives_the_linux64_outputs(fmus, runners, folder, name, platform):
    assert_same_outputs(fmus[name], platform, runners, folder, RTOL[platform])


@pytest.fixture(scope="module")
def learned_fmu(folder) -> Path:
    """The learned feedforward of a tiny trained LSTM (its network as generated C), for every
    platform available."""
    from flexff.controllers.learned_feedforward import learned_feedforward_system

    models = train_tiny_models(folder / "models", {"lstm": {"hidden": 12, "layers": 2}}, seed=3)
    return build_fmu(learned_feedforward_system(models / "lstm.onnx"), folder / "learned.fmu",
                     platforms=available_platforms())


@pytest.mark.slow
@pytest.mark.parametrize("platform", OTHERS)
def test_the_learned_feedforward_gives_the_linux64_outputs(learned_fmu, runners, folder,
                                                           platform):
    assert_same_outputs(learned_fmu, platform, runners, folder,
                        NETWORK_RTOL if platform == "win64" else RTOL[platform])


def fmpy_compiled(source_only: Path, folder: Path) -> Path:
    """The source-only FMU compiled by FMPy and unpacked into `folder`: by
    fmpy.build.build_platform_binary (CMake) on the unpacked FMU, or by an older FMPy's
    fmpy.util.compile_platform_binary into the .fmu itself."""
    try:
        from fmpy.build import build_platform_binary
    except ImportError:
        from fmpy.util import compile_platform_binary

        compile_platform_binary(str(source_only))
        return Path(fmpy.extract(str(source_only), str(folder)))
    if shutil.which("cmake") is None:
        pytest.skip("FMPy compiles sources with CMake, not installed here")
    unpacked = Path(fmpy.extract(str(source_only), str(folder)))
    build_platform_binary(str(unpacked))
    return unpacked


@pytest.mark.parametrize("name", ["plant", "network"])
def test_fmpy_compiles_the_source_only_fmu_with_equal_results(fmus, folder, name):
    description = fmpy.read_model_description(str(fmus[name]))
    source_only = folder / f"{name}-sources.fmu"
    build_fmu(_system(name, folder), source_only, platforms=())
    with zipfile.ZipFile(source_only) as zf:
        assert not [n for n in zf.namelist() if n.startswith("binaries/")]
    unpacked = fmpy_compiled(source_only, folder / f"{name}-fmpy")
    inputs = sine_inputs(fmus[name])
    names = [v.name for v in description.modelVariables
             if v.causality == "input" and v.type == "Real"]
    step = float(description.defaultExperiment.stepSize)
    signal = np.zeros(STEPS, dtype=[("time", float), *((n, float) for n in names)])
    signal["time"] = np.arange(STEPS) * step
    for i, n in enumerate(names):
        signal[n] = inputs[:, i]
    runs = [fmpy.simulate_fmu(str(f), stop_time=(STEPS - 1) * step, output_interval=step,
                              input=signal) for f in (unpacked, fmus[name])]
    assert runs[0].dtype.names == runs[1].dtype.names
    for column in runs[0].dtype.names:
        np.testing.assert_array_equal(runs[0][column], runs[1][column], err_msg=column)


def _system(name: str, folder: Path):
    """The System of the FMU `name` of the fmus fixture (its graph already written)."""
    if name == "plant":
        return plant_system()
    return network_system(str(folder / "sum.onnx"))


def test_platforms_resolve_and_name_a_missing_compiler(monkeypatch):
    monkeypatch.setattr(shutil, "which", lambda command: f"/usr/bin/{command}")
    assert resolve(None) == (host(),)
    assert resolve(["win64", "linux64"]) == ("linux64", "win64")  # PLATFORMS' order
    assert resolve(["all"]) == tuple(PLATFORMS)
    assert resolve(()) == ()
    with pytest.raises(InputError, match="unknown platform sparc"):
        resolve(["sparc"])
    monkeypatch.setattr(shutil, "which", lambda command: None)
    with pytest.raises(InputError, match=r"x86_64-w64-mingw32-gcc.*gcc-mingw-w64-x86-64"):
        resolve(["win64"])


def test_platforms_the_network_cannot_run_on_are_refused(tmp_path, monkeypatch):
    monkeypatch.setattr(shutil, "which", lambda command: f"/usr/bin/{command}")
    toy = network_system(running_sum_graph(tmp_path / "sum.onnx"))
    runtime = replace(toy, network=replace(toy.network, runtime="onnxruntime"))
    for platforms in (["aarch64-linux"], ()):
        with pytest.raises(InputError, match="onnxruntime runs on linux64 alone"):
            build_fmu(runtime, tmp_path / "ort.fmu", platforms=platforms)


def test_the_host_build_keeps_its_key_and_others_have_their_own():
    plant = plant_system()
    assert fmu_key(plant) == fmu_key(plant, platforms=[host()])
    assert fmu_key(plant, platforms=()) != fmu_key(plant)


def test_the_command_line_builds_sources_alone(tmp_path, capsys):
    assert main(["fmu", "build", "plant", "--source-only", "-o", str(tmp_path / "p.fmu")]) == 0
    with zipfile.ZipFile(tmp_path / "p.fmu") as zf:
        names = zf.namelist()
    assert "sources/model.c" in names and not [n for n in names if n.startswith("binaries/")]
    assert main(["fmu", "build", "plant", "--source-only", "--platform", "win64",
                 "-o", str(tmp_path / "q.fmu")]) == 2
    assert "takes no --platform" in capsys.readouterr().err
