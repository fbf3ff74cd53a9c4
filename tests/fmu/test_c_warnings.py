"""Every C file flexff ships compiles without a warning under -Wall -Wextra -pedantic -Werror,
with the build's own flags (so -O2: gcc's flow-sensitive warnings such as -Warray-bounds only
run when optimizing, which -fsyntax-only skips).

The FMU's generic wrapper is compiled against the config.h of the toy FMUs (continuous,
discrete without states, with an embedded network in each runtime and in its own task; the
continuous one and the task one as FMI 3.0 too), since its code paths depend on the sizes
there; the network generated as C too; the engine, the floor and the proxy as they are built.
CasADi's generated model.c (the toys' and the plant's) is held to the same flags but
-Wunused-parameter: its functions take CasADi's fixed calling convention (arg, res, iw, w,
mem), used or not.
"""

import os
import subprocess
import zipfile
from dataclasses import replace
from pathlib import Path

import pytest

from flexff.fmu.build import (
    FMI3_C_FILES,
    NETWORK_C_FILES,
    RUNTIME_C_FILES,
    TASK_C_FILES,
    WRAPPER_C_FILES,
)
from flexff.fmu.codegen import generate_model_c
from flexff.fmu.compile import CFLAGS, HOST_HEADER, compiler, fmi_headers
from flexff.fmu.network_c import FMU_PREFIX
from flexff.plant.system import plant_system
from tests.fmu.test_network import network_system, running_sum_graph
from tests.fmu_toys import build_toy, discrete_pi, duffing
from tests.helpers import REPOSITORY

WARNINGS = ("-Wall", "-Wextra", "-pedantic", "-Werror")
GENERATED = ("-Wno-unused-parameter",)  # CasADi's calling convention, see above
FMU_C = REPOSITORY / "flexff" / "fmu" / "c"
# the engine, the floor and the proxy (cosim.isolation)
ENGINE_C = REPOSITORY / "flexff" / "cosim" / "c"


def compile_warnings(source: Path, include_dirs: list[Path], extra: tuple[str, ...] = ()) -> str:
    """gcc's messages for `source` compiled with the build's flags and WARNINGS ("": none)."""
    result = subprocess.run([compiler(), *CFLAGS, *WARNINGS, *extra, "-c", "-o", os.devnull,
                             *(f"-I{d}" for d in include_dirs), str(source)],
                            capture_output=True, text=True)
    return "" if result.returncode == 0 else result.stderr


@pytest.fixture(scope="module")
def toy_sources(tmp_path_factory) -> dict[str, Path]:
    """The sources/ folder of each toy FMU, by toy."""
    graph = running_sum_graph(tmp_path_factory.mktemp("graph") / "sum.onnx")
    folders = {}
    net = network_system(graph)
    task = replace(net, name="toy_task", network=replace(net.network, task=True))
    runtime = replace(net, name="toy_ort", network=replace(net.network, runtime="onnxruntime"))
    builds = [(s, 2) for s in (duffing(), discrete_pi(), net, task, runtime)]
    for system, fmi_version in [*builds, (duffing(), 3), (task, 3)]:
        name = system.name if fmi_version == 2 else f"{system.name}-fmi3"
        folder = tmp_path_factory.mktemp(name)
        with zipfile.ZipFile(build_toy(system, tmp_path_factory, fmi_version)) as zf:
            zf.extractall(folder)
        folders[name] = folder / "sources"
    return folders


def test_every_fmu_source_is_shipped():
    """The toys below compile what an FMU ships: every C file of fmu/c is one of those."""
    shipped = WRAPPER_C_FILES + FMI3_C_FILES + NETWORK_C_FILES + TASK_C_FILES + tuple(
        name for files in RUNTIME_C_FILES.values() for name in files)
    assert sorted(p.name for p in FMU_C.glob("*.c")) == sorted(shipped)


def test_the_fmu_sources_compile_without_warnings(toy_sources):
    found = {}
    for toy, sources in toy_sources.items():
        for name in sorted(p.name for p in sources.glob("*.c")):
            generated = name == "model.c"  # CasADi's; the others are fmu/c's own files
            source = (sources / name if generated or name == f"{FMU_PREFIX}.c"  # the network's
                      else FMU_C / name)
            found[f"{toy}: {name}"] = compile_warnings(source, [sources],
                                                       GENERATED if generated else ())
    assert {f: w for f, w in found.items() if w} == {}


def test_the_plant_model_compiles_without_warnings(tmp_path):
    for name, text in generate_model_c(plant_system(), "plant").items():
        (tmp_path / name).write_text(text)
    assert compile_warnings(tmp_path / "model.c", [tmp_path], GENERATED) == ""


def test_the_engine_floor_proxy_and_sandbox_compile_without_warnings(tmp_path):
    for name, text in fmi_headers().items():
        (tmp_path / name).write_text(text)
    sources = sorted(ENGINE_C.glob("*.c"))
    assert [p.name for p in sources] == ["engine.c", "floor.c", "proxy.c", "sandbox.c"]
    found = {str(p.relative_to(REPOSITORY)): compile_warnings(p, [tmp_path, HOST_HEADER.parent])
             for p in sources}
    assert {f: w for f, w in found.items() if w} == {}
