"""The probe FMU (tests/probe_fmu.c): a tiny FMI 2.0 co-simulation FMU, compiled in the tests,
that records the start time and tolerance it was given and crashes or hangs in fmi2DoStep on
request (parameters crash_at, hang_at)."""

from __future__ import annotations

import subprocess
import zipfile
from pathlib import Path

import fmpy

from flexff.fmu.compile import compiler, fmi_headers

SOURCE = Path(__file__).with_suffix(".c")
VARIABLES = (  # name, value reference, causality, variability, start (None: none)
    ("start_seen", 0, "output", "discrete", None),
    ("tolerance_seen", 1, "output", "discrete", None),
    ("clock", 2, "output", "discrete", None), ("u", 3, "input", "continuous", 0.0),
    ("y", 4, "output", "continuous", None), ("crash_at", 5, "parameter", "fixed", -1.0),
    ("hang_at", 6, "parameter", "fixed", -1.0))


def _library(folder: Path) -> Path:
    for name, text in fmi_headers().items():
        (folder / name).write_text(text)
    library = folder / f"probe{fmpy.sharedLibraryExtension}"
    subprocess.run([compiler(), "-O2", "-std=c99", "-D_POSIX_C_SOURCE=200809L", "-shared",
                    "-fPIC", f"-I{folder}", str(SOURCE), "-o", str(library)], check=True)
    return library


def _model_description(experiment: dict[str, float]) -> str:
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
    attributes = " ".join(f'{key}="{value!r}"' for key, value in experiment.items())
    return (f'<?xml version="1.0" encoding="UTF-8"?>\n<fmiModelDescription fmiVersion="2.0" '
            f'modelName="probe" guid="{{probe}}" variableNamingConvention="flat">'
            f'<CoSimulation modelIdentifier="probe"/>'
            f'<DefaultExperiment {attributes}/>'
            f'<ModelVariables>{"".join(rows)}</ModelVariables>'
            f'<ModelStructure><Outputs>{outputs}</Outputs></ModelStructure>'
            f'</fmiModelDescription>\n')


def build_probe(folder: Path, **experiment: float) -> Path:
    """The probe FMU in `folder`, with a DefaultExperiment of the given attributes (startTime,
    stopTime, stepSize, tolerance)."""
    folder.mkdir(parents=True, exist_ok=True)
    library = _library(folder)
    path = folder / "probe.fmu"
    with zipfile.ZipFile(path, "w") as zf:
        zf.writestr("modelDescription.xml", _model_description(experiment))
        zf.write(library, f"binaries/{fmpy.platform}/{library.name}")
    return path
