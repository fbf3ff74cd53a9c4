"""validate_fmu: fmpy's static checks of an FMU plus a short run of our own.

Our checks, on any FMI 2.0 or 3.0 co-simulation FMU read through fmu.importer: the binary
loads, instantiates and exports every co-simulation function of its FMI version; with default
values the FMU initializes, steps and gives finite float outputs; restoring a saved FMU state
(directly, and through serialization) reproduces the outputs of the uninterrupted run exactly,
where the model description says the FMU can do so. An FMU built for one input table (a
network in the precomputed mode) runs on the inputs of that table. Every problem is returned
as a sentence, never raised: `flexff fmu validate` prints them.
"""

from __future__ import annotations

import csv
import io
import math
import zipfile
from pathlib import Path
from typing import Any

import fmpy.validation

from flexff.fmu.codegen import NET_TABLE_FILE
from flexff.fmu.importer import FmuError, FmuInfo, FmuInstance, read_fmu

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
# fmi3Functions.h: the common functions, fmi3InstantiateCoSimulation and the co-simulation ones.
_FMI3_TYPES = ("Float32", "Float64", "Int8", "UInt8", "Int16", "UInt16", "Int32", "UInt32",
               "Int64", "UInt64", "Boolean", "String", "Binary", "Clock")
FMI3_CS_FUNCTIONS = (
    "fmi3GetVersion", "fmi3SetDebugLogging", "fmi3InstantiateCoSimulation", "fmi3FreeInstance",
    "fmi3EnterInitializationMode", "fmi3ExitInitializationMode", "fmi3EnterEventMode",
    "fmi3Terminate", "fmi3Reset",
    *(f"fmi3{op}{t}" for op in ("Get", "Set") for t in _FMI3_TYPES),
    "fmi3GetNumberOfVariableDependencies", "fmi3GetVariableDependencies",
    "fmi3GetFMUState", "fmi3SetFMUState", "fmi3FreeFMUState", "fmi3SerializedFMUStateSize",
    "fmi3SerializeFMUState", "fmi3DeserializeFMUState",
    "fmi3GetDirectionalDerivative", "fmi3GetAdjointDerivative",
    "fmi3EnterConfigurationMode", "fmi3ExitConfigurationMode",
    "fmi3GetIntervalDecimal", "fmi3GetIntervalFraction", "fmi3GetShiftDecimal",
    "fmi3GetShiftFraction", "fmi3SetIntervalDecimal", "fmi3SetIntervalFraction",
    "fmi3SetShiftDecimal", "fmi3SetShiftFraction", "fmi3EvaluateDiscreteStates",
    "fmi3UpdateDiscreteStates",
    "fmi3EnterStepMode", "fmi3GetOutputDerivatives", "fmi3DoStep",
)
# fmpy's FMU-state methods per FMI version: get, set, free, serialize, deserialize.
_STATE_METHODS = {
    "2.0": ("getFMUstate", "setFMUstate", "freeFMUstate", "serializeFMUstate",
            "deSerializeFMUstate"),
    "3.0": ("getFMUState", "setFMUState", "freeFMUState", "serializeFMUState",
            "deserializeFMUState"),
}


def _missing_exports(instance: FmuInstance) -> list[str]:
    """The FMI functions of the FMU's version that its loaded binary lacks, as problems."""
    functions = FMI2_CS_FUNCTIONS if instance.info.fmi_version == "2.0" else FMI3_CS_FUNCTIONS
    return [f"the binary does not export {name}" for name in functions
            if not hasattr(instance.fmu.dll, name)]


def _table_inputs(path: Path) -> list[dict[str, float]]:
    """The input rows of the FMU's precomputation table, or none."""
    name = f"resources/{NET_TABLE_FILE}"
    with zipfile.ZipFile(path) as zf:
        if name not in zf.namelist():
            return []
        rows = csv.DictReader(io.StringIO(zf.read(name).decode()))
        return [{k: float(v) for k, v in row.items() if k != "time"} for row in rows]


def _experiment(info: FmuInfo) -> tuple[float, float]:
    """Start time and communication step: the default experiment's step, else the fixed
    internal step (FMI 3.0), else a hundredth of the stop time, else 1 ms."""
    md = info.model_description
    start = md.defaultExperiment.startTime if md.defaultExperiment else None
    fixed = getattr(md.coSimulation, "fixedInternalStepSize", None)
    step = (info.default_step or (float(fixed) if fixed else None)
            or (info.default_stop / 100 if info.default_stop else 1e-3))
    return float(start or 0.0), step


def _run_problems(instance: FmuInstance, steps: int = 20) -> list[str]:
    """Initialize with defaults, step, check finite outputs and the FMU-state round trips."""
    info, cs = instance.info, instance.info.model_description.coSimulation
    start, step = _experiment(info)
    table = _table_inputs(info.path)
    outputs = [n for n in info.outputs
               if info.variables[n].scalar and info.variables[n].kind != "clock"]
    get_state, set_state, free_state, serialize, deserialize = (
        getattr(instance.fmu, name) for name in _STATE_METHODS[info.fmi_version])

    def advance(k: int) -> list[Any]:
        """Step from t_k, then apply the inputs of t_k+1 (a Gauss-Seidel master's order)."""
        instance.do_step(start + k * step, step)
        if table:
            instance.set(table[min(k + 1, len(table) - 1)])
        return instance.get(outputs)

    instance.initialize(start_time=start)
    if table:
        instance.set(table[0])
    rows = [instance.get(outputs)] + [advance(k) for k in range(steps // 2)]
    states: dict[str | None, Any] = {}  # by label; None labels the uninterrupted run
    if cs.canGetAndSetFMUstate:
        saved = states["a saved FMU state"] = instance.call("getting the FMU state", get_state)
        if cs.canSerializeFMUstate:
            states["a serialized FMU state"] = instance.call(
                "serializing and restoring the FMU state", lambda: deserialize(serialize(saved)))
    runs: dict[str | None, list[list[Any]]] = {}
    for label, state in {None: None, **states}.items():
        if state is not None:
            instance.call(f"restoring {label}", lambda state=state: set_state(state))
        runs[label] = [advance(k) for k in range(steps // 2, steps)]
    for label, state in states.items():
        instance.call(f"freeing {label}", lambda state=state: free_state(state))

    problems = []
    floats = [i for i, n in enumerate(outputs) if info.variables[n].kind.startswith("float")]
    bad = [outputs[i] for i in floats
           if not all(math.isfinite(row[i]) for row in rows + runs[None])]
    if bad:
        problems.append(f"outputs not finite within {steps} steps of {step:g} s with default "
                        f"values: {', '.join(bad)}")
    problems += [f"restoring {label} does not reproduce the outputs of the uninterrupted run"
                 for label in states if repr(runs[label]) != repr(runs[None])]  # nan == nan
    return problems


def validate_fmu(path: str | Path) -> list[str]:
    """Problems found in the FMU at `path`; an empty list means it passed every check."""
    path = Path(path)
    if not path.is_file():
        return [f"{path} does not exist or is not a file"]
    if not zipfile.is_zipfile(path):
        return [f"{path} is not an FMU: an FMU is a zip archive, this file is not one"]
    try:  # an unreadable description or one without co-simulation: nothing more to check
        info = read_fmu(path)
    except FmuError as error:
        return [str(error)]
    problems: list[str] = fmpy.validation.validate_fmu(str(path))
    if problems:
        return problems
    try:
        with FmuInstance(info, "validation") as instance:
            return _missing_exports(instance) or _run_problems(instance)
    except Exception as error:  # a load failure or an FMI error status is a finding, not a crash
        return [f"running the FMU failed: {error}"]
