"""Tiny FMI 2.0 FMUs compiled in the tests: the probe (tests/probe_fmu.c), a co-simulation FMU
that records the start time and tolerance it was given and crashes or hangs in fmi2DoStep on
request (parameters crash_at, hang_at), or tries what a sandbox must stop (attempt, ATTEMPTS);
the bouncing ball (tests/bouncing_ball.c), a
model-exchange FMU with state and time events."""

from __future__ import annotations

import subprocess
import zipfile
from pathlib import Path

import fmpy

from flexff.fmu.compile import compiler, fmi_headers

SOURCE = Path(__file__).with_suffix(".c")
BALL_SOURCE = Path(__file__).with_name("bouncing_ball.c")
UNSUPPORTED = Path(__file__).with_name("fmi2_unsupported.c")  # the calls both FMUs share
BALL_DESCRIPTION = """<?xml version="1.0" encoding="UTF-8"?>
<fmiModelDescription fmiVersion="2.0" modelName="ball" guid="{ball}" numberOfEventIndicators="1">
<ModelExchange modelIdentifier="ball"/>
<DefaultExperiment startTime="0.0" stopTime="3.0" stepSize="0.01"/>
<ModelVariables>
<ScalarVariable name="h" valueReference="0" causality="output" variability="continuous"
 initial="exact"><Real start="1.0"/></ScalarVariable>
<ScalarVariable name="v" valueReference="1" causality="output" variability="continuous"
 initial="exact"><Real start="0.0"/></ScalarVariable>
<ScalarVariable name="der(h)" valueReference="2" causality="local" variability="continuous">
 <Real derivative="1"/></ScalarVariable>
<ScalarVariable name="der(v)" valueReference="3" causality="local" variability="continuous">
 <Real derivative="2"/></ScalarVariable>
<ScalarVariable name="g" valueReference="4" causality="parameter" variability="fixed">
 <Real start="9.81"/></ScalarVariable>
<ScalarVariable name="e" valueReference="5" causality="parameter" variability="tunable">
 <Real start="0.7"/></ScalarVariable>
</ModelVariables>
<ModelStructure><Outputs><Unknown index="1"/><Unknown index="2"/></Outputs>
<Derivatives><Unknown index="3"/><Unknown index="4"/></Derivatives>
<InitialUnknowns><Unknown index="3"/><Unknown index="4"/></InitialUnknowns></ModelStructure>
</fmiModelDescription>
"""
VARIABLES = (  # name, value reference, causality, variability, start (None: none)
    ("start_seen", 0, "output", "discrete", None),
    ("tolerance_seen", 1, "output", "discrete", None),
    ("clock", 2, "output", "discrete", None), ("u", 3, "input", "continuous", 0.0),
    ("y", 4, "output", "continuous", None), ("crash_at", 5, "parameter", "fixed", -1.0),
    ("hang_at", 6, "parameter", "fixed", -1.0), ("attempt", 7, "parameter", "fixed", 0.0),
    ("attempt_at", 8, "parameter", "fixed", 0.0))
ATTEMPTS = {"socket": 1, "escape": 2, "allocate": 3, "processes": 4, "program": 5,
            "scratch": 6, "terminal": 7, "shrink": 8, "chmod": 9, "times": 10, "xattr": 11,
            "orphan": 12, "flood": 13, "threads": 14, "shared": 15, "fill": 16, "spin": 17,
            "stop": 18, "log": 19, "read": 20, "limit_parent": 21,
            "environment": 22,
            "hang_terminate": 23}  # the probe's `attempt` values (tests/probe_fmu.c)
ESCAPE = "/tmp/flexff-probe-escape.txt"  # where attempt "escape" writes
OUTSIDE = "/tmp/flexff-probe-outside.txt"  # whose metadata attempts chmod, times, xattr change
INJECTED = "echo flexff-probe-injected"  # what attempt "terminal" types
HANG_INSTANTIATE = "hang_instantiate"  # an instance of this name hangs in fmi2Instantiate


def _library(folder: Path, source: Path = SOURCE, name: str = "probe") -> Path:
    for header, text in fmi_headers().items():
        (folder / header).write_text(text)
    library = folder / f"{name}{fmpy.sharedLibraryExtension}"
    subprocess.run([compiler(), "-O2", "-std=c99", "-D_GNU_SOURCE", "-shared", "-fPIC",
                    "-pthread", f"-I{folder}", str(source), str(UNSUPPORTED), "-o",
                    str(library)], check=True)
    return library


def _model_description(experiment: dict[str, float], guid: str = "{probe}") -> str:
    rows = []
    for name, vr, causality, variability, start in VARIABLES:
        initial = ' initial="calculated"' if causality == "output" else ""
        real = f'<Real start="{start!r}"/>' if start is not None else "<Real/>"
        rows.append(f'<ScalarVariable name="{name}" valueReference="{vr}" '
                    f'causality="{causality}" variability="{variability}"{initial}>{real}'
                    f'</ScalarVariable>')
    outputs = "".join(
        f'<Unknown index="{k + 1}" dependencies="{"4" if name == "y" else ""}"/>'
        for k, (name, _, causality, _, _) in enumerate(VARIABLES) if causality == "output")
    initials = "".join(f'<Unknown index="{k + 1}"/>' for k, (_, _, causality, _, _)
                      in enumerate(VARIABLES) if causality == "output")
    attributes = " ".join(f'{key}="{value!r}"' for key, value in experiment.items())
    return (f'<?xml version="1.0" encoding="UTF-8"?>\n<fmiModelDescription fmiVersion="2.0" '
            f'modelName="probe" guid="{guid}" variableNamingConvention="flat">'
            f'<CoSimulation modelIdentifier="probe"/>'
            f'<DefaultExperiment {attributes}/>'
            f'<ModelVariables>{"".join(rows)}</ModelVariables>'
            f'<ModelStructure><Outputs>{outputs}</Outputs>'
            f'<InitialUnknowns>{initials}</InitialUnknowns></ModelStructure>'
            f'</fmiModelDescription>\n')


def build_probe(folder: Path, hostile: bool = False, **experiment: float) -> Path:
    """The probe FMU in `folder`, with a DefaultExperiment of the given attributes (startTime,
    stopTime, stepSize, tolerance); `hostile`: one that tries to write to ESCAPE when it is
    instantiated."""
    guid = "{probe-hostile}" if hostile else "{probe}"
    return packaged_fmu(folder, _model_description(experiment, guid))


def packaged_fmu(folder: Path, description: str, source: Path = SOURCE,
                 name: str = "probe") -> Path:
    """The FMU `name`.fmu in `folder`: `source` compiled for this platform beside
    `description` (its modelDescription.xml)."""
    folder.mkdir(parents=True, exist_ok=True)
    library = _library(folder, source, name)
    path = folder / f"{name}.fmu"
    with zipfile.ZipFile(path, "w") as zf:
        zf.writestr("modelDescription.xml", description)
        zf.write(library, f"binaries/{fmpy.platform}/{library.name}")
    return path


def build_ball(folder: Path) -> Path:
    """The bouncing ball, a model-exchange FMU only, in `folder`."""
    return packaged_fmu(folder, BALL_DESCRIPTION, BALL_SOURCE, "ball")
