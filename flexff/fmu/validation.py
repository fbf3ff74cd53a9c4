"""validate_fmu: the faults of an FMU's description plus a short run of our own, graded.

The description's faults are fmpy's checks and flexff's own (fmu.description_faults), each
said to stop a run or only to be warned of. Our run's checks, on any FMI 2.0 or 3.0
co-simulation FMU: the binary loads, instantiates and exports its functions; with default
values it initializes, steps and gives finite outputs; restoring a saved state (directly and
serialized) reproduces the uninterrupted run. Every call into the FMU runs in a child process
(fmu.child), so a crash or hang becomes a problem naming the call; given a `confine` (flexff
fmu validate gives cosim's sandbox unless --no-sandbox), that process confines itself after
unpacking the FMU and before loading its binary, so that an FMU's code runs no freer than in
an isolated run. Each problem is a sentence with a severity; a state restore that differs by
at most the FMU's tolerance is a warning. Problems are returned, never raised.

Docs: "Validate and compare third-party FMUs" (docs/how-to/validate-compare.md).
"""

from __future__ import annotations

import csv
import functools
import io
import math
import os
import tempfile
import zipfile
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

from flexff.fmu.child import report_path, run_in_child, under_way
from flexff.fmu.codegen import NET_TABLE_FILE
from flexff.fmu.defaults import DEFAULT_STEP
from flexff.fmu.description_faults import Fault, description_faults
from flexff.fmu.importer import FmuError, FmuInfo, FmuInstance, read_fmu

TOLERANCE = 1e-6  # relative: for a state restore, where the FMU's default experiment gives none
TIMEOUT = 60.0  # seconds the checks of one FMU may take before it counts as hung
SEVERITIES = ("error", "warning")

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
    internal step (FMI 3.0), else a hundredth of the stop time, else DEFAULT_STEP."""
    md = info.model_description
    start = md.defaultExperiment.startTime if md.defaultExperiment else None
    fixed = getattr(md.coSimulation, "fixedInternalStepSize", None)
    step = (info.default_step or (float(fixed) if fixed else None)
            or (info.default_stop / 100 if info.default_stop else DEFAULT_STEP))
    return float(start or 0.0), step


Emit = Callable[[tuple[str, str, float | None]], None]  # sends one finding to the parent
# Confines the checks' process for good: (its folder, holding the FMU in fmu/ and its scratch
# folder work/, the file descriptor for the sandbox's line); importable by name.
Confine = Callable[[Path, int], None]


class Problem(str):
    """One finding: the sentence, its severity ("error" or "warning"), where the finding is a
    number (a difference) its size, and for a fault of the description what it does to a run
    (`in_run`: RUN_STOPS or RUN_WARNS; None for the checks that run the FMU)."""

    severity: str
    size: float | None
    in_run: str | None

    def __new__(cls, text: str, severity: str = "error", size: float | None = None,
                in_run: str | None = None) -> Problem:
        if severity not in SEVERITIES:
            raise ValueError(f"severity {severity!r}: expected one of {SEVERITIES}")
        problem = super().__new__(cls, text)
        problem.severity, problem.size, problem.in_run = severity, size, in_run
        return problem


RUN_STOPS, RUN_WARNS = "stops a run", "a run warns, or with strict = true stops"


def _description_problem(fault: Fault, strict: bool) -> Problem:
    """A description's fault as a finding: an error where it stops a run (fatal, or any with
    `strict`), else a warning."""
    stops = fault.fatal or strict
    return Problem(str(fault), "error" if stops else "warning",
                   in_run=RUN_STOPS if fault.fatal else RUN_WARNS)


def _is_finding(message: Any) -> bool:
    """Whether a message from the checks' process is a finding: [text, severity, size]."""
    return (isinstance(message, list) and len(message) == 3 and isinstance(message[0], str)
            and message[1] in SEVERITIES and isinstance(message[2], (int, float, type(None))))


def _tolerance(info: FmuInfo) -> float:
    """The FMU's default-experiment tolerance, else TOLERANCE."""
    experiment = info.model_description.defaultExperiment
    given = experiment.tolerance if experiment is not None else None
    return float(given) if given else TOLERANCE


def relative_difference(run: Sequence[Sequence[Any]], reference: Sequence[Sequence[Any]],
                        floats: Sequence[int]) -> float:
    """The largest difference between two runs' rows of outputs, each output's relative to
    its largest finite magnitude in either run; inf where an output that is no float differs,
    or where a value is NaN or infinite in one run only."""
    worst = 0.0
    for i in range(len(reference[0]) if reference else 0):
        pairs = [(row[i], ref[i]) for row, ref in zip(run, reference)
                 if repr(row[i]) != repr(ref[i])]
        if not pairs:
            continue
        if i not in floats or any(not (math.isfinite(a) and math.isfinite(b))
                                  for a, b in pairs):
            return math.inf
        scale = max(abs(v) for row, ref in zip(run, reference) for v in (row[i], ref[i])
                    if math.isfinite(v))
        worst = max(worst, max(abs(a - b) for a, b in pairs) / scale)
    return worst


def restore_finding(label: str, size: float, tolerance: float, strict: bool
                    ) -> tuple[str, str, float | None] | None:
    """The finding for a restore of `label` whose outputs differ by `size` (relative_difference)
    from the uninterrupted run's: none at 0, a warning within `tolerance` (not `strict`), else an
    error."""
    if size == 0.0:
        return None
    text = f"restoring {label} does not reproduce the outputs of the uninterrupted run"
    if math.isinf(size):
        return (f"{text} (an output differs in kind: NaN, infinite, or not a float)", "error",
                size)
    if strict:
        return f"{text} bit for bit (largest relative difference {size:.2g})", "error", size
    if size <= tolerance:
        return (f"{text} exactly: they differ by {size:.2g} (relative), within the FMU's "
                f"tolerance {tolerance:g} (bit for bit with --strict)", "warning", size)
    return (f"{text}: they differ by {size:.2g} (relative), beyond the FMU's tolerance "
            f"{tolerance:g}", "error", size)


def _run_checks(instance: FmuInstance, emit: Emit, strict: bool, steps: int = 20) -> None:
    """Initialize with defaults, step, check finite outputs and the FMU-state round trips:
    the state saved halfway, restored directly and then through serialization, must give
    the outputs of the uninterrupted second half. Each finding is emitted when made."""
    info, cs = instance.info, instance.info.model_description.coSimulation
    start, step = _experiment(info)
    table = _table_inputs(info.path)
    outputs = [n for n in info.outputs
               if info.variables[n].scalar and info.variables[n].kind != "clock"]
    floats = [i for i, n in enumerate(outputs) if info.variables[n].kind.startswith("float")]
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
    saved = (instance.call("getting the FMU state", get_state) if cs.canGetAndSetFMUstate
             else None)
    uninterrupted = [advance(k) for k in range(steps // 2, steps)]
    bad = [outputs[i] for i in floats
           if not all(math.isfinite(row[i]) for row in rows + uninterrupted)]
    if bad:
        emit((f"outputs not finite within {steps} steps of {step:g} s with default values: "
              f"{', '.join(bad)}", "error", None))
    if saved is None:
        return
    restores: dict[str, Callable[[], Any]] = {"a saved FMU state": lambda: saved}
    if cs.canSerializeFMUstate:
        restores["a serialized FMU state"] = lambda: instance.call(
            "serializing and restoring the FMU state", lambda: deserialize(serialize(saved)))
    for label, state_of in restores.items():
        state = state_of()
        instance.call(f"restoring {label}", lambda state=state: set_state(state))
        run = [advance(k) for k in range(steps // 2, steps)]
        finding = restore_finding(label, relative_difference(run, uninterrupted, floats),
                                  _tolerance(info), strict)
        if finding is not None:
            emit(finding)
        if state is not saved:
            instance.call(f"freeing {label}", lambda state=state: free_state(state))
    instance.call("freeing the FMU state", lambda: free_state(saved))


def _confine(confine: Confine, folder: Path) -> None:
    """Work in `folder`'s scratch folder, then `confine` this process."""
    os.chdir(folder / "work")
    report = os.open(report_path(), os.O_WRONLY | os.O_CREAT | os.O_APPEND | os.O_CLOEXEC, 0o600)
    confine(folder, report)


def _checks(emit: Emit, path: str, strict: bool, confine: Confine | None) -> None:
    """Every check that calls into the FMU at `path`: run in a child process (validate_fmu),
    confined by `confine` where given."""
    try:
        info = read_fmu(path, checked=False)  # its description's faults: validate_fmu's
        under_way("loading the FMU's binary")
        folder = Path(tempfile.mkdtemp(prefix="flexff-validated-"))
        (folder / "work").mkdir()
        hook = None if confine is None else functools.partial(_confine, confine, folder)
        with FmuInstance(info, "validation", folder=folder / "fmu", confine=hook) as instance:
            missing = _missing_exports(instance)
            for problem in missing:
                emit((problem, "error", None))
            if not missing:
                _run_checks(instance, emit, strict)
    except Exception as error:  # a load failure or an FMI error status is a finding
        emit((f"running the FMU failed: {error}", "error", None))


def validate_fmu(path: str | Path, strict: bool = False, timeout: float = TIMEOUT,
                 confine: Confine | None = None) -> list[Problem]:
    """Problems found in the FMU at `path` (module doc); an empty list means it passed every
    check. `strict`: the description's warnings are errors, as a strict run refuses them, and
    a state restore must reproduce the outputs bit for bit. `timeout`: seconds the checks that
    run the FMU may take. `confine`: how their process confines itself (None: not)."""
    path = Path(path)
    if not path.is_file():
        return [Problem(f"{path} does not exist or is not a file")]
    if not zipfile.is_zipfile(path):
        return [Problem(f"{path} is not an FMU: an FMU is a zip archive, this file is not one")]
    try:  # an unreadable description or one without an interface: nothing more to check
        info = read_fmu(path, checked=False)
    except FmuError as error:
        return [Problem(str(error), in_run=RUN_STOPS)]
    problems = [_description_problem(fault, strict)
                for fault in description_faults(info.path, info.model_description)]
    end = run_in_child(_checks, (str(path.absolute()), strict, confine), timeout,
                       fresh=confine is not None)
    problems += [Problem(*finding) for finding in end.messages if _is_finding(finding)]
    failure = end.failure(timeout)
    if failure is not None:
        problems.append(Problem(failure))
    return problems
