"""The run configuration as plain data: what cosim.config parses a TOML file (or cosim.ssp an SSP
file) into, before anything is built or run.

RunConfig holds the general form's tables ([run], [reference], [[source]], [fmu.NAME],
[[connection]], [record], [machine]) as frozen dataclasses; `point_time` gives point k's time.
Every key, its type, default and unit is in the generated reference "Run configuration"
(docs/reference/configuration.md, from cosim.config_keys).
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

from flexff.cosim.sandbox import DEFAULT, Sandbox

if TYPE_CHECKING:
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
    sandbox: Sandbox | None = DEFAULT  # an isolated FMU's sandbox (None: none; cosim.sandbox)
    solver: str | None = None  # model exchange with this solver (None: co-simulation)
    scheduled: bool = False  # through the FMU's scheduled-execution interface (fmu.scheduled)
    allow_nonfinite: bool = False  # NaN and infinite values allowed in and out (cosim.finite)
    fmi: int = 2  # the FMI version a built-in is built in (2 or 3)
    strict: bool = False  # its description's warnings refused too (fmu.description_faults)
    feedthrough: bool = True  # False: no output depends directly on an input (cosim.wiring)


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
    plot: bool | None = None  # None: where the run tracks an axis (cosim.run)
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
