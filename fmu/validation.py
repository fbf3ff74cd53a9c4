"""validate_fmu: fmpy's static checks of an FMU plus a short run of our own.

Our checks: the binary exports every FMI 2.0 co-simulation function; with default values the
FMU initializes, steps and gives finite outputs; restoring a saved FMU state (directly and
through serialization) reproduces the outputs of the uninterrupted run exactly.
"""

from __future__ import annotations

import ctypes
import math
import zipfile
from pathlib import Path

import fmpy.validation

from fmu.runner import Slave

FMI2_CS_FUNCTIONS = (
    "fmi2GetTypesPlatform", "fmi2GetVersion", "fmi2SetDebugLogging", "fmi2Instantiate",
    "fmi2FreeInstance", "fmi2SetupExperiment", "fmi2EnterInitializationMode",
    "fmi2ExitInitializationMode", "fmi2Terminate", "fmi2Reset", "fmi2GetReal", "fmi2GetInteger",
    "fmi2GetBoolean", "fmi2GetString", "fmi2SetReal", "fmi2SetInteger", "fmi2SetBoolean",
    "fmi2SetString", "fmi2GetFMUstate", "fmi2SetFMUstate", "fmi2FreeFMUstate",
    "fmi2SerializedFMUstateSize", "fmi2SerializeFMUstate", "fmi2DeSerializeFMUstate",
    "fmi2GetDirectionalDerivative", "fmi2SetRealInputDerivatives",
    "fmi2GetRealOutputDerivatives", "fmi2DoStep", "fmi2CancelStep", "fmi2GetStatus",
    "fmi2GetRealStatus", "fmi2GetIntegerStatus", "fmi2GetBooleanStatus", "fmi2GetStringStatus",
)


def _missing_exports(path: Path) -> list[str]:
    with Slave(path) as s:
        dll = ctypes.CDLL(str(s.library))
        return [f"the binary does not export {name}" for name in FMI2_CS_FUNCTIONS
                if not hasattr(dll, name)]


def _run_problems(path: Path, steps: int = 20) -> list[str]:
    """Initialize with defaults, step, check finite outputs and the FMU-state round trip."""
    with Slave(path) as s:
        step = float(s.model_description.defaultExperiment.stepSize)
        outputs = s.names("output")
        s.initialize()
        for k in range(steps // 2):
            s.fmu.doStep(k * step, step)
        saved = s.fmu.getFMUstate()
        restored = s.fmu.deSerializeFMUstate(s.fmu.serializeFMUstate(saved))
        runs = []
        for state in (None, saved, restored):
            if state is not None:
                s.fmu.setFMUstate(state)
            values = []
            for k in range(steps // 2, steps):
                s.fmu.doStep(k * step, step)
                values += s.get(outputs)
            runs.append(values)
        for state in (saved, restored):
            s.fmu.freeFMUstate(state)
        s.fmu.terminate()
    problems = []
    if not all(math.isfinite(v) for v in runs[0]):
        problems.append("outputs are not finite after a few steps with default values")
    if runs[1] != runs[0]:
        problems.append("restoring a saved FMU state does not reproduce the outputs")
    if runs[2] != runs[0]:
        problems.append("restoring a serialized FMU state does not reproduce the outputs")
    return problems


def validate_fmu(path: str | Path) -> list[str]:
    """Problems found in the FMU at `path`; an empty list means it passed every check."""
    path = Path(path)
    if not path.is_file():
        return [f"{path} does not exist or is not a file"]
    if not zipfile.is_zipfile(path):
        return [f"{path} is not an FMU: an FMU is a zip archive, this file is not one"]
    problems = fmpy.validation.validate_fmu(str(path))
    if problems:
        return problems
    try:
        return _missing_exports(path) or _run_problems(path)
    except Exception as exc:  # a load failure or an FMI error status is a finding, not a crash
        return [f"running the FMU failed: {exc}"]
