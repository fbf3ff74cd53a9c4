"""The run configuration as plain data: what cosim.config parses a TOML file (or cosim.ssp an SSP
file) into, before anything is built or run.

General form (SI units):

  [run]            step (s, default 0.001), start (s; default: the first FMU's default
                   experiment, else 0), stop (s, the end time as in FMI: the run lasts
                   stop - start; default: start plus the reference's duration, else the first
                   FMU's default experiment), tolerance (relative, of each FMU's own solver;
                   default: each FMU's default experiment), algorithm = "gauss-seidel"
                   (default) | "jacobi", order = [FMU names] (default: the order of the
                   [fmu.*] tables), allow_nonfinite = true (every FMU's, below). Point k
                   is at t = start + k * step; the reference plays from the run's start, CSV
                   series are read at the run's times.
  [reference]      a reference trajectory, a source of x_ref .. ay_ref (cosim.references;
                   the kinds are listed in cosim.config)
  [[source]]       kind = "constant", values = {name = number, ...}: constant source signals
                   kind = "csv", path = "file.csv": a header `time,<name>,...`, one source
                   signal per column, linearly interpolated onto the step (held after its end)
  [fmu.NAME]       path = "file.fmu" (any FMI 2.0 or 3.0 co-simulation FMU, relative to the
                   configuration) or builtin = a registered built-in's name with its options
                   (cosim.builtins; the manipulator's plant, controller,
                   rigid-body-feedforward and learned-feedforward are documented in
                   controllers.manipulator); parameters = {variable =
                   value} (start values of parameters or inputs, checked against the FMU's
                   variables and types);
                   unconnected = "error" (default) | "start" (inputs left unconnected keep
                   their start values); tolerance (relative: given to the FMU's
                   fmi2SetupExperiment / fmi3EnterInitializationMode; default: [run]
                   tolerance, else the FMU's default experiment, else none); isolate = true
                   runs it in its own process (cosim.isolation): a crash or a hang ends the
                   run with an error, and [run] step_timeout (s) bounds each of its calls;
                   solver = "cvode" runs it as model exchange (fmu.model_exchange, with the
                   FMU's tolerance as CVODE's relative one; the default for an FMU with no
                   co-simulation interface); allow_nonfinite = true lets its
                   parameters and outputs be NaN or infinite (by default a non-finite
                   parameter is refused and a non-finite output stops the run)
  [[connection]]   from = "fmu.output" or a source signal, to = "fmu.input", optional gain and
                   offset (SSP's LinearTransformation: to = gain * from + offset)
  [record]         signals = [names] (default: all), csv (bool, default false),
                   plot (bool, default: in a manipulator run), every (int, default 1)
  [machine]        the machine's description (cosim.machine), or machine = "FILE.toml": its
                   axes' signals are checked against the loop, and the tracking metrics are
                   its axes'

Inputs without a [[connection]] take, by name, the output of the same name of another FMU or
the source signal of that name (cosim.wiring). A machine package may register a short form
(cosim.plugins): the manipulator's ([plant], [controller], [feedforward],
controllers.short_form) is shorthand for the FMUs feedforward -> controller -> plant.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

from flexff.fmu.errors import InputError

if TYPE_CHECKING:  # cosim.machine reads ConfigError from here
    from flexff.cosim.machine import Machine

ALGORITHMS = ("gauss-seidel", "jacobi")
STEP_TOLERANCE = 1e-9  # relative: stop / step must be this close to a whole number
UNCONNECTED = ("error", "start")
SOURCE_KINDS = ("constant", "csv")


def whole_steps(length: float, step: float) -> bool:
    """Whether a run's `length` (stop - start) is a whole number of steps of `step` (within
    STEP_TOLERANCE): the one rule for a run's length, in TOML and SSP alike."""
    return abs(length / step - round(length / step)) <= STEP_TOLERANCE * max(1.0, length / step)


def point_time(start: float, step: float, k: Any) -> Any:
    """The time of communication point(s) k [s]: start + k * step, the one rule for every
    point (master, engine, recording, sources, libcosim)."""
    return start + k * step


class ConfigError(InputError):
    """A configuration problem, naming the file and the `table.key` at fault."""

    def __init__(self, origin: str, key: str, message: str) -> None:
        super().__init__(f"{origin}: {key}: {message}")
        self.key = key


@dataclass(frozen=True)
class ReferenceConfig:
    """The reference's kind and its checked keys (paths absolute)."""

    kind: str
    options: Mapping[str, Any] = field(default_factory=dict)


@dataclass(frozen=True)
class SourceConfig:
    """Constant source signals (`values`) or a CSV table of them (`path`)."""

    kind: str
    values: Mapping[str, float] = field(default_factory=dict)
    path: Path | None = None


@dataclass(frozen=True)
class FmuConfig:
    """One FMU of the run: a file or a built-in, its start values, how unconnected inputs go."""

    name: str
    path: Path | None = None
    builtin: str | None = None
    options: Mapping[str, Any] = field(default_factory=dict)
    parameters: Mapping[str, Any] = field(default_factory=dict)
    unconnected: str = "error"
    tolerance: float | None = None  # None: the FMU's default experiment's, if any
    isolate: bool = False  # run it in its own process (cosim.isolation)
    solver: str | None = None  # model exchange with this solver (None: co-simulation)
    allow_nonfinite: bool = False  # NaN and infinite values allowed in and out (cosim.finite)


@dataclass(frozen=True)
class ConnectionConfig:
    """An explicit connection; `key` names its table in errors (`connection[k]`)."""

    from_name: str  # TOML `from`: "fmu.output" or a source signal
    to_name: str  # TOML `to`: "fmu.input"
    gain: float = 1.0
    offset: float = 0.0
    key: str = "connection"


@dataclass(frozen=True)
class RecordConfig:
    signals: tuple[str, ...] | None = None  # None: every signal
    csv: bool = False
    plot: bool | None = None  # None: in a manipulator run (cosim.run)
    every: int = 1  # keep every N-th point in the record (metrics and plots see them all)


@dataclass(frozen=True)
class RunConfig:
    """A run configuration in the general form. `checked` is true only on the object
    cosim.config's parser made: a copy changed in code (dataclasses.replace) starts unchecked,
    and cosim.scenario.resolve checks it (cosim.config.checked) before anything is built."""

    name: str
    step: float
    stop: float  # the end time [s]
    fmus: tuple[FmuConfig, ...]  # in stepping order
    reference: ReferenceConfig | None = None
    sources: tuple[SourceConfig, ...] = ()
    connections: tuple[ConnectionConfig, ...] = ()
    algorithm: str = "gauss-seidel"
    record: RecordConfig = RecordConfig()
    origin: str = "<config>"  # where it was read from, for errors
    start: float = 0.0  # the start time [s]
    tolerance: float | None = None  # [run] tolerance as given (None: each FMU's own)
    step_timeout: float | None = None  # [s] per call of an isolated FMU (None: none)
    machine: Machine | None = None  # the machine description, if given
    checked: bool = field(default=False, init=False, compare=False, repr=False)

    @property
    def steps(self) -> int:
        return round((self.stop - self.start) / self.step)

    def builtin(self, kind: str) -> FmuConfig | None:
        """The first FMU that is the built-in `kind`, or None."""
        return next((f for f in self.fmus if f.builtin == kind), None)
