"""validate_fmu: fmpy's static checks of an FMU plus a short run of our own.

Our checks: the binary exports every FMI 2.0 co-simulation function; with default values the
FMU initializes, steps and gives finite outputs; restoring a saved FMU state (directly and
through serialization) reproduces the outputs of the uninterrupted run exactly. An FMU built
for one input table (a network in the precomputed mode) runs on the inputs of that table.
"""

from __future__ import annotations

import ctypes
import csv
import io
import math
import zipfile
from pathlib import Path

import fmpy.validation

from fmu.codegen import NET_TABLE_FILE
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


def _table_inputs(path: Path) -> list[dict[str, float]]:
    """The input rows of the FMU's precomputation table, or none."""
    name = f"resources/{NET_TABLE_FILE}"
    with zipfile.ZipFile(path) as zf:
        if name not in zf.namelist():
            return []
        rows = csv.DictReader(io.StringIO(zf.read(name).decode()))
        return [{k: float(v) for k, v in row.items() if k != "time"} for row in rows]


def _run_problems(path: Path, steps: int = 20) -> list[str]:
    """Initialize with defaults, step, check finite outputs and the FMU-state round trip."""
    table = _table_inputs(path)

    def do_step(k: int) -> None:
        """Step from t_k, then apply the inputs of t_k+1 (a Gauss-Seidel master's order)."""
        s.fmu.doStep(k * step, step)
        if table:
            s.set(table[min(k + 1, len(table) - 1)])

    with Slave(path) as s:
        step = float(s.model_description.defaultExperiment.stepSize)
        outputs = s.names("output")
        s.initialize()
        s.set(table[0] if table else {})
        for k in range(steps // 2):
            do_step(k)
        saved = s.fmu.getFMUstate()
        restored = s.fmu.deSerializeFMUstate(s.fmu.serializeFMUstate(saved))
        runs = []
        for state in (None, saved, restored):
            if state is not None:
                s.fmu.setFMUstate(state)
            values = []
            for k in range(steps // 2, steps):
                do_step(k)
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
