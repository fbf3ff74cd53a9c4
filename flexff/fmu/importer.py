"""The FMU importer: any FMI 2.0 or 3.0 FMU read into its ports and typed start values, and
instantiated with a log of its own: as a co-simulation FMU, through its model-exchange
interface with a solver (fmu.model_exchange), which an FMU without co-simulation needs, or
through its scheduled-execution interface (fmu.scheduled).

One layer for everything that loads FMUs (the co-simulation master, the libcosim runner,
validation, the bench), in FMPy's way: each FMI call is declared once (by fmpy), values of every
type are set and read through one pair of functions (`FmuInstance.set` / `get`), and problems
are FmuError messages that name the file, never tracebacks.

Types: FMI 2.0 has Real, Integer, Boolean, String and Enumeration; FMI 3.0 Float32/64, (U)Int8 to
(U)Int64, Boolean, String, Binary, Enumeration and Clock. `TYPE_KINDS` maps each to the kind
of value it carries, so that an FMI 2.0 Real and an FMI 3.0 Float64 agree (both "float64").
The hot path of a run, float64 values, is called from compiled code (cosim/c/engine.c) with
the instance's own function pointers.
"""

from __future__ import annotations

import os
import shutil
import zipfile
from collections.abc import Callable, Mapping, Sequence
from ctypes import byref, c_double, c_long, c_void_p
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import fmpy
from fmpy import read_model_description
from fmpy.fmi2 import (
    FMU2Model,
    FMU2Slave,
    fmi2CallbackAllocateMemoryTYPE,
    fmi2CallbackFreeMemoryTYPE,
    fmi2CallbackFunctions,
    fmi2CallbackLoggerTYPE,
)
from fmpy.fmi3 import FMU3Model, FMU3ScheduledExecution, FMU3Slave
from fmpy.logging import addLoggerProxy
from fmpy.model_description import ValidationError

from flexff.fmu.archive import extract_archive
from flexff.fmu.description_faults import Fault, description_faults, summary
from flexff.fmu.errors import InputError, not_a_file
from flexff.fmu.messages import MessageLog
from flexff.fmu.model_exchange import ModelExchangeStepper
from flexff.fmu.printable import printable
from flexff.fmu.scheduled import ScheduledStepper, periodic_clocks
from flexff.fmu.stepper import Stepper

TYPE_KINDS = {
    "Real": "float64", "Float64": "float64", "Float32": "float32",
    "Integer": "int32", "Int32": "int32", "Int8": "int8", "UInt8": "uint8", "Int16": "int16",
    "UInt16": "uint16", "UInt32": "uint32", "Int64": "int64", "UInt64": "uint64",
    "Enumeration": "enumeration", "Boolean": "boolean", "String": "string",
    "Binary": "binary", "Clock": "clock",
}
INTEGER_RANGES = {"int8": (-2**7, 2**7), "uint8": (0, 2**8), "int16": (-2**15, 2**15),
                  "uint16": (0, 2**16), "int32": (-2**31, 2**31), "uint32": (0, 2**32),
                  "int64": (-2**63, 2**63), "uint64": (0, 2**64),
                  "enumeration": (-2**63, 2**63)}
STATUS_LABELS = ("OK", "Warning", "Discard", "Error", "Fatal", "Pending")
MESSAGE_CHARS = 2000  # the most of one FMU log message kept


class FmuError(InputError):
    """An FMU that cannot be read, loaded or used as asked; the message names the file."""


SETTABLE = ("parameter", "structuralParameter", "input")  # causalities a run may set


@dataclass(frozen=True)
class Variable:
    """One scalar variable of an FMU, with its start value in its Python type."""

    name: str
    value_reference: int
    type: str  # the FMI type name (Real, Float64, Int32, Boolean, ...)
    causality: str
    variability: str
    unit: str | None = None
    start: Any = None
    description: str = ""
    scalar: bool = True  # False for an FMI 3.0 array variable (not connectable here)

    @property
    def kind(self) -> str:
        """The kind of value it carries (TYPE_KINDS); equal kinds can be connected."""
        return TYPE_KINDS[self.type]

    @property
    def settable(self) -> bool:
        """Whether a run may give it a start value: the one rule, for TOML, SSP and the
        master alike."""
        return self.causality in SETTABLE


@dataclass(frozen=True)
class FmuInfo:
    """What a master needs to know of an FMU before loading it."""

    path: Path
    fmi_version: str  # "2.0" or "3.0"
    model_name: str
    identifier: str  # the model identifier (name of the binary): co-simulation's, if it has it
    token: str  # FMI 2.0 guid or FMI 3.0 instantiationToken
    variables: Mapping[str, Variable]
    inputs: tuple[str, ...]
    outputs: tuple[str, ...]
    parameters: tuple[str, ...]  # causality parameter (and structuralParameter)
    dependencies: Mapping[str, frozenset[str]]  # output -> the inputs it depends on directly
    default_step: float | None = None
    default_stop: float | None = None
    default_start: float | None = None  # DefaultExperiment startTime [s]
    default_tolerance: float | None = None  # DefaultExperiment tolerance (relative)
    co_simulation: bool = True  # whether it has the co-simulation interface
    me_identifier: str | None = None  # the model-exchange interface's identifier, if it has one
    se_identifier: str | None = None  # the scheduled-execution interface's, if it has one
    faults: tuple[Fault, ...] = ()  # its description's warnings (fmu.description_faults)
    model_description: Any = field(default=None, compare=False, repr=False)
    declared: frozenset[str] = frozenset()  # outputs whose model structure lists dependencies
    states: frozenset[str] = frozenset()  # outputs that are continuous states (of Derivatives)

    @property
    def undeclared(self) -> frozenset[str]:
        """Outputs without a dependency list that are no states: by FMI, each depends on
        every input."""
        return frozenset(self.outputs) - self.declared - self.states

    @property
    def scheduled_only(self) -> bool:
        """Whether scheduled execution is its only interface (it runs no other way)."""
        return not self.co_simulation and self.me_identifier is None

    @property
    def feedthrough(self) -> frozenset[str]:
        """Outputs that depend directly on an input."""
        return frozenset(n for n, deps in self.dependencies.items() if deps)

    def variable(self, name: str) -> Variable:
        return self.variables[name]


def _start_value(v: Any) -> Any:
    """A model variable's start value in its Python type (None if it has none)."""
    if v.start is None:
        return None
    try:
        return typed_value(TYPE_KINDS.get(v.type, "string"), v.start)
    except ValueError:
        return v.start


def _experiment_value(path: Path, experiment: Any, name: str) -> float | None:
    """The DefaultExperiment's attribute `name` as a number, None where it is not given;
    FmuError where it is no number (a description read unchecked keeps fmpy's text)."""
    text = getattr(experiment, name, None) if experiment else None
    if not text:
        return None
    try:
        return float(text)
    except ValueError:
        raise FmuError(f"{path}: modelDescription.xml: DefaultExperiment {name} = {text!r} is "
                       f"not a number") from None


def read_fmu(path: str | Path, checked: bool = True, strict: bool = False) -> FmuInfo:
    """Read the model description of a co-simulation FMU; FmuError if it is none. `checked`:
    its faults are classified (fmu.description_faults): a fatal one (two variables of one
    name, say) is an FmuError naming it, so that no run records one variable's values under
    another's name; the warnings are kept in `faults`, or with `strict` are an FmuError too."""
    path = Path(path)
    why = not_a_file(path, "FMU file")
    if why is not None:
        raise FmuError(f"{path}: {why}")
    if not zipfile.is_zipfile(path):
        raise FmuError(f"{path}: not an FMU (an FMU is a zip archive; this file is not one)")
    try:
        md = read_model_description(str(path), validate=False)
    except ValidationError as error:  # a fault that leaves nothing to read (fmpy's parser)
        raise FmuError(f"{path}: modelDescription.xml: {error.problems[0]}") from None
    except Exception as error:  # fmpy raises plain Exceptions and XML errors
        raise FmuError(f"{path}: cannot read modelDescription.xml: {error}") from None
    if md.fmiVersion not in ("2.0", "3.0"):
        raise FmuError(f"{path}: FMI {md.fmiVersion} is not supported (FMI 2.0 and 3.0 are)")
    scheduled: Any = getattr(md, "scheduledExecution", None)
    if md.coSimulation is None and md.modelExchange is None and scheduled is None:
        raise FmuError(f"{path}: the FMU has no co-simulation, model-exchange or "
                       f"scheduled-execution interface")
    interface = md.coSimulation or md.modelExchange or scheduled
    variables = {}
    for v in md.modelVariables:
        if v.type not in TYPE_KINDS:
            continue
        unit = v.unit or (v.declaredType.unit if v.declaredType is not None
                          and hasattr(v.declaredType, "unit") else None)
        variables[v.name] = Variable(
            v.name, int(v.valueReference), v.type, v.causality or "local",
            v.variability or "continuous", unit or None, _start_value(v), v.description or "",
            not v.dimensions)
    data = {n: v for n, v in variables.items() if v.type != "Clock"}  # clocks: its schedule
    inputs = tuple(n for n, v in data.items() if v.causality == "input")
    outputs = tuple(n for n, v in data.items() if v.causality == "output")
    parameters = tuple(n for n, v in variables.items()
                       if v.causality in ("parameter", "structuralParameter"))
    # absent: depends on every input (FMI), but for an output that is a continuous state,
    # which only integration changes
    states = _state_outputs(md, outputs)
    dependencies = {n: frozenset() if n in states else frozenset(inputs) for n in outputs}
    declared = set()
    for unknown in md.outputs:
        if unknown.variable is not None and unknown.dependencies is not None:
            dependencies[unknown.variable.name] = frozenset(
                d.name for d in unknown.dependencies if d.name in inputs)
            declared.add(unknown.variable.name)
    step, stop, start, tolerance = (_experiment_value(path, md.defaultExperiment, name)
                                    for name in ("stepSize", "stopTime", "startTime",
                                                 "tolerance"))
    token = md.guid if md.fmiVersion == "2.0" else md.instantiationToken
    faults = _refused(path, md, strict) if checked else ()
    return FmuInfo(path, md.fmiVersion, md.modelName or path.stem,
                   interface.modelIdentifier, token or "", variables, inputs, outputs,
                   parameters, dependencies, step, stop, start, tolerance,
                   md.coSimulation is not None,
                   md.modelExchange.modelIdentifier if md.modelExchange else None,
                   scheduled.modelIdentifier if scheduled else None, faults, md,
                   frozenset(declared), frozenset(states - declared))


def _refused(path: Path, md: Any, strict: bool) -> tuple[Fault, ...]:
    """The description's faults, all warnings: FmuError naming the first fatal one (with
    `strict`, the first of any)."""
    faults = description_faults(path, md)
    stopping = [f for f in faults if f.fatal or strict]
    if stopping:
        why = ("a run would be wrong" if stopping[0].fatal else
               "strict = true refuses what would only be a warning")
        raise FmuError(f"{path}: modelDescription.xml: {summary(stopping)}; {why} (flexff fmu "
                       f"validate lists every fault)")
    return tuple(faults)


def _state_outputs(md: Any, outputs: Sequence[str]) -> set[str]:
    """The outputs that are continuous states: the `derivative` of a variable the model
    structure lists among its derivatives, or an alias of one (its value reference)."""
    states = {(d.variable.derivative.valueReference, d.variable.derivative.type)
              for d in md.derivatives
              if d.variable is not None and d.variable.derivative is not None}
    by_name = {v.name: v for v in md.modelVariables}
    return {n for n in outputs if (by_name[n].valueReference, by_name[n].type) in states}


def typed_value(kind: str, value: Any) -> Any:
    """`value` (a TOML value, or a start value as written in XML) as a value of `kind`
    (TYPE_KINDS); InputError saying what was expected."""
    if kind in ("float64", "float32"):
        if isinstance(value, str):
            try:
                return float(value)
            except ValueError:
                pass
        elif isinstance(value, (int, float)) and not isinstance(value, bool):
            return float(value)
        raise InputError(f"expected a number, got {value!r}")
    if kind in INTEGER_RANGES:
        if isinstance(value, str):
            try:
                value = int(value)
            except ValueError:
                raise InputError(f"expected an integer, got {value!r}") from None
        if isinstance(value, bool) or not isinstance(value, int):
            raise InputError(f"expected an integer, got {value!r}")
        low, high = INTEGER_RANGES[kind]
        if not low <= value < high:
            raise InputError(f"{value} is outside the range of {kind} [{low}, {high - 1}]")
        return value
    if kind in ("boolean", "clock"):
        if isinstance(value, str) and value in ("true", "false", "1", "0"):
            return value in ("true", "1")
        if not isinstance(value, bool):
            raise InputError(f"expected true or false, got {value!r}")
        return value
    if kind == "string":
        if not isinstance(value, str):
            raise InputError(f"expected a string, got {value!r}")
        return value
    if kind == "binary":
        if isinstance(value, bytes):
            return value
        if isinstance(value, str):
            try:
                return bytes.fromhex(value)
            except ValueError:
                pass
        raise InputError(f"expected bytes as a hexadecimal string, got {value!r}")
    raise InputError(f"values of kind {kind!r} cannot be set")


# -- instances ------------------------------------------------------------------------------
class _Fmi2Log:
    """The one fmi2 logger of the process, routing each message to its instance.

    fmpy's logger proxy (which formats the variadic message in C) keeps a single Python
    callback for the whole process; every instance's callbacks carry its own
    componentEnvironment, by which the messages are sorted to the instance that sent them.
    """

    def __init__(self) -> None:
        self.sinks: dict[int, MessageLog] = {}
        self.callback = fmi2CallbackLoggerTYPE(self._log)
        self._next = 1

    def _log(self, env: int | None, instance: bytes | None, status: int,
             category: bytes | None, message: bytes | None) -> None:
        sink = self.sinks.get(env or 0)
        if sink is not None:
            sink.append(_message(status, message))

    def callbacks(self, sink: MessageLog) -> tuple[fmi2CallbackFunctions, int]:
        key, self._next = self._next, self._next + 1
        self.sinks[key] = sink
        callbacks = fmi2CallbackFunctions()
        callbacks.logger = self.callback
        callbacks.allocateMemory = fmi2CallbackAllocateMemoryTYPE(fmpy.calloc)
        callbacks.freeMemory = fmi2CallbackFreeMemoryTYPE(fmpy.free)
        callbacks.componentEnvironment = c_void_p(key)
        addLoggerProxy(byref(callbacks))
        return callbacks, key


_FMI2_LOG = _Fmi2Log()


def _message(status: int, message: bytes | None) -> str:
    """An FMU's log message as flexff keeps and shows it: its status, its text escaped."""
    label = STATUS_LABELS[status] if 0 <= status < len(STATUS_LABELS) else str(status)
    return f"[{label}] {printable((message or b'').decode('utf-8', 'replace'), MESSAGE_CHARS)}"


class FmuInstance:
    """One instantiated FMU (FMI 2.0 or 3.0) with its own message log (each message given to
    `log`, where given, as one line; the last few kept for errors): a co-simulation one, or
    a model-exchange one (`solver`, fmu.model_exchange.SOLVERS; an FMU without co-simulation
    needs one) or a scheduled-execution one (`scheduled`; an FMU with that interface alone
    needs it), the last two stepped by `stepper` once initialized. It is unpacked into
    `folder` (default: a new temporary one); `confine`, if given, is called between unpacking
    and loading the binary (cosim.sandbox)."""

    def __init__(self, info: FmuInfo, name: str, solver: str | None = None,
                 folder: Path | None = None, confine: Callable[[], None] | None = None,
                 scheduled: bool = False, log: Callable[[str], None] | None = None) -> None:
        self.info, self.name = info, name
        self.messages = MessageLog(name, log)
        self.initialized = False
        self.scheduled = scheduled or info.scheduled_only
        self.model_exchange = not self.scheduled and (solver is not None
                                                      or not info.co_simulation)
        self.stepper: Stepper | None = None
        if self.model_exchange and info.me_identifier is None:
            raise FmuError(f"{info.path}: {name}: the FMU has no model-exchange interface for "
                           f"a solver")
        if self.scheduled and info.se_identifier is None:
            raise FmuError(f"{info.path}: {name}: the FMU has no scheduled-execution interface")
        identifier = self._identifier()
        self._unzipdir = str(extract_archive(info.path, folder))
        cwd = os.getcwd()
        try:
            self.library = self._library_path()
            if confine is not None:
                confine()
            kwargs = {"guid": info.token, "unzipDirectory": self._unzipdir,
                      "modelIdentifier": identifier, "instanceName": name}
            if info.fmi_version == "2.0":
                self.fmu = (FMU2Model if self.model_exchange else FMU2Slave)(**kwargs)
                self._callbacks, self._log_key = _FMI2_LOG.callbacks(self.messages)
                self.fmu.instantiate(callbacks=self._callbacks)
            elif self.scheduled:
                self.fmu = FMU3ScheduledExecution(**kwargs)
                self.fmu.instantiate(logMessage=self._log3)
            else:
                self.fmu = (FMU3Model if self.model_exchange else FMU3Slave)(**kwargs)
                self.fmu.instantiate(logMessage=self._log3)
        except FmuError:
            self._remove()
            raise
        except Exception as error:  # fmpy: a library that does not load or instantiate
            os.chdir(cwd)  # fmpy changes to the binary's folder to load it, and stays on failure
            self._remove()
            raise FmuError(f"{info.path}: {name}: cannot instantiate: {error}"
                           f"{self._log_text()}") from None
        self.component = c_void_p(self.fmu.component)

    @property
    def scratch(self) -> Path:
        """The temporary folder the FMU is unpacked into (removed by `close`)."""
        return Path(self._unzipdir)

    def _library_path(self) -> Path:
        folder = fmpy.platform if self.info.fmi_version == "2.0" else fmpy.platform_tuple
        identifier = self._identifier()
        path = Path(self._unzipdir, "binaries", folder,
                    f"{identifier}{fmpy.sharedLibraryExtension}")
        if not path.is_file():
            raise FmuError(f"{self.info.path}: no binary for this platform "
                           f"(binaries/{folder}/{path.name} is missing)")
        return path

    def _identifier(self) -> str | None:
        """The model identifier of the interface it is instantiated through."""
        if self.scheduled:
            return self.info.se_identifier
        return self.info.me_identifier if self.model_exchange else self.info.identifier

    def _log3(self, env: int | None, status: int, category: bytes | None,
              message: bytes | None) -> None:
        self.messages.append(_message(status, message))

    def _log_text(self) -> str:
        return f" ({'; '.join(self.messages.last(5))})" if self.messages.count else ""

    def fail(self, what: str) -> FmuError:
        """The error for a failed call, with the FMU's last messages."""
        log = "; ".join(self.messages.last(5)) or "no message from the FMU"
        if self.stepper is not None and self.stepper.error is not None:
            log = f"{self.stepper.error}; {log}"
        return FmuError(f"{self.name}: {what} failed: {log}")

    def call(self, what: str, function: Callable[..., Any]) -> Any:
        """Run one fmpy call; an error status or exception becomes FmuError naming `what`.

        `function` is called without arguments (`...` admits lambdas that bind loop variables
        as defaults)."""
        try:
            return function()
        except Exception:
            raise self.fail(what) from None

    # -- values of every type ------------------------------------------------------------
    def set(self, values: Mapping[str, Any]) -> None:
        """Set variables by name, each in its own type (values checked by typed_value)."""
        for name, value in values.items():
            v = self.info.variables[name]
            value = typed_value(v.kind, value)
            self.call(f"setting {name} = {value!r}",
                      lambda v=v, value=value: self._setter(v)([v.value_reference], [value]))

    def get(self, names: Sequence[str]) -> list[Any]:
        """Values by name, each in its Python type."""
        out = []
        for name in names:
            v = self.info.variables[name]
            value = self.call(f"getting {name}",
                              lambda v=v: self._getter(v)([v.value_reference])[0])
            if v.kind == "boolean":
                value = bool(value)
            elif v.kind == "string" and isinstance(value, bytes):
                value = value.decode("utf-8", "replace")
            out.append(value)
        return out

    def _setter(self, v: Variable) -> Callable[..., Any]:
        setter: Callable[..., Any] = getattr(self.fmu, "set" + self._type_name(v))
        return setter

    def _getter(self, v: Variable) -> Callable[..., Any]:
        getter: Callable[..., Any] = getattr(self.fmu, "get" + self._type_name(v))
        return getter

    def _type_name(self, v: Variable) -> str:
        if self.info.fmi_version == "2.0":
            return "Integer" if v.type == "Enumeration" else v.type
        return "Int64" if v.type == "Enumeration" else v.type

    # -- life cycle -----------------------------------------------------------------------
    def initialize(self, values: Mapping[str, Any] | None = None, start_time: float = 0.0,
                   stop_time: float | None = None, tolerance: float | None = None) -> None:
        """Set `values` (parameters, inputs' start values) in initialization mode, leave it.
        The experiment (start, stop, and the tolerance of an FMU's own solver, None: not
        defined) goes to fmi2SetupExperiment / fmi3EnterInitializationMode."""
        fmu = self.fmu
        if self.info.fmi_version == "2.0":
            self.call("fmi2SetupExperiment", lambda: fmu.setupExperiment(
                tolerance=tolerance, startTime=start_time, stopTime=stop_time))
            self.call("fmi2EnterInitializationMode", fmu.enterInitializationMode)
        else:
            self.call("fmi3EnterInitializationMode", lambda: fmu.enterInitializationMode(
                tolerance=tolerance, startTime=start_time, stopTime=stop_time))
        self.set(values or {})
        self.call(f"fmi{self.info.fmi_version[0]}ExitInitializationMode",
                  fmu.exitInitializationMode)
        self.initialized = True
        if self.model_exchange:
            md = self.info.model_description
            self.stepper = self.call("the initial event iteration", lambda: ModelExchangeStepper(
                fmu, self.info.fmi_version == "3.0", start_time, stop_time, tolerance,
                md.numberOfContinuousStates, md.numberOfEventIndicators,
                bool(md.modelExchange.needsCompletedIntegratorStep)))
        elif self.scheduled:
            try:
                clocks = periodic_clocks(self.info.path)
            except InputError as error:
                raise FmuError(f"{self.info.path}: {self.name}: {error}") from None
            self.stepper = ScheduledStepper(fmu, clocks, start_time)

    def do_step(self, time: float, step: float) -> None:
        """One communication step through fmpy (FastCalls for the hot loop); a model-exchange
        FMU's through its solver."""
        if self.stepper is not None:
            if self.stepper.step(step) > 1:
                what = "partitions" if self.scheduled else "solver's step"
                raise self.fail(f"the {what} from t = {time:.9g} s")
            return
        self.call(f"fmi{self.info.fmi_version[0]}DoStep from t = {time:.9g} s",
                  lambda: self.fmu.doStep(currentCommunicationPoint=time,
                                          communicationStepSize=step))

    def network_times(self) -> dict[str, float] | None:
        """The call times of a flexff FMU's embedded network so far (calls; p50, p99, max in
        microseconds), its call period in steps and, where it runs in its own task, that
        task's rate-transition overruns, the calls handed over to it (`handovers`), those the
        step computed itself (`computed_in_step`) and those whose hand-over woke the task
        with a system call (`signalled`: not released by the clock); None for an FMU
        without one."""
        function = getattr(self.fmu.dll, "flexff_network_times", None)
        times = (c_double * 4)()
        if function is None or function(self.component, times) != 0:
            return None
        figures: dict[str, float] = {"calls": int(times[0]), "p50": times[1] * 1e6,
                                     "p99": times[2] * 1e6, "max": times[3] * 1e6}
        task = self.network_task()
        if task is not None:
            period, counter = task
            figures["period_steps"] = period
            if counter:
                figures["overruns"] = c_long.from_address(counter).value
        counts = (c_long * 4)()
        function = getattr(self.fmu.dll, "flexff_network_counts", None)
        if function is not None and function(self.component, counts) == 0:
            figures["handovers"], figures["computed_in_step"] = counts[0], counts[2]
            figures["signalled"] = counts[3]
        return figures

    def network_task(self) -> tuple[int, int] | None:
        """A flexff FMU's embedded network: its call period in steps and the address of its
        task's rate-transition overrun counter (a C long; 0 where it runs in the step), or
        None for an FMU without one (or built before networks ran in tasks)."""
        function = getattr(self.fmu.dll, "flexff_network_task", None)
        period, counter = c_long(), c_void_p()
        if function is None or function(self.component, byref(period), byref(counter)) != 0:
            return None
        return period.value, counter.value or 0

    def close(self) -> None:
        """Terminate (if initialized), free the instance, delete the extracted files."""
        try:
            if self.initialized:
                try:
                    self.fmu.terminate()
                except Exception:
                    pass  # the run's own error, if any, is the one to report
            self.fmu.freeInstance()
        finally:
            self._remove()

    def _remove(self) -> None:
        if getattr(self, "_log_key", None) is not None:
            _FMI2_LOG.sinks.pop(self._log_key, None)
        shutil.rmtree(self._unzipdir, ignore_errors=True)

    def __enter__(self) -> FmuInstance:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()
