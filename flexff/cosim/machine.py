"""A machine description: the axes a feedforward is learned for, as plain data checked once.

Given in a run configuration as `[machine]` (or `machine = "FILE.toml"`), read by
`parse_machine`, checked against the loop's FMUs by `check_signals`. Each `[[machine.axis]]`
names the axis (its references `<axis>_ref`, `v<axis>_ref`, `a<axis>_ref`, `j<axis>_ref`), the
measured position (`instance.variable` or an expression of outputs; `true`, optional, only for
the metrics), the feedforward input and the commanded effort (the labels; these three only
where a loop runs), units and the excitation limits (`range`, `velocity`, `acceleration`,
optional `jerk`); datasets name them `<axis>_measured`, `<axis>_effort`. `[machine.prior]`
chooses the prior's terms per axis (PRIOR_TERMS and user expressions), `[machine.log]` how
logs name the signals (LogMap), `exact` the start values that measure exactly,
`[machine.ilc]` ILC's settings (IlcSettings), `[machine.learning]` the preprocessing otherwise
derived from the data (Learning). Every key is in KEYS; every error a ConfigError naming it.
"""

from __future__ import annotations

import math
import re
import tomllib
from collections.abc import Iterable, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, TypeVar

from flexff.cosim.config_error import ConfigError
from flexff.fmu.errors import InputError
from flexff.fmu.expressions import (
    CONSTANTS,
    FUNCTIONS,
    Expression,
    ExpressionError,
    parse_expression,
)

T = TypeVar("T")


class MissingLoopSignal(InputError):
    """A loop signal asked of an axis whose description (of logs alone) does not give it."""


AXIS_NAME = re.compile(r"[A-Za-z][A-Za-z0-9]*\Z")
SCALAR_NAME = re.compile(r"[A-Za-z_][A-Za-z0-9_]*\Z")
PRIOR_TERMS = ("inertia", "viscous", "coulomb", "coulomb_asymmetric", "offset")
DEFAULT_PRIOR_TERMS = ("inertia", "viscous", "coulomb", "offset")
KEYS = {
    "machine": ("name", "axis", "prior", "log", "exact", "ilc", "learning"),
    "axis": ("name", "unit", "measured", "true", "feedforward", "effort", "effort_unit",
             "range", "velocity", "acceleration", "jerk"),
    "prior": ("terms", "extra", "coulomb_width"),
    "log": ("time", "scalars", "columns"),
    "ilc": ("iterations", "cutoff_hz", "gain", "model", "seed"),
    "learning": ("cutoff_hz", "filter_order", "lead_s", "model_rate_hz"),
}


@dataclass(frozen=True)
class Limits:
    """The excitation's bounds on one axis: position range, |velocity|, |acceleration| and
    (optional) |jerk|, in the axis's unit per second to the power."""

    low: float
    high: float
    velocity: float
    acceleration: float
    jerk: float | None = None


LOOP_SIGNALS = ("measured", "feedforward", "effort")  # an axis's signals in a loop
LOOP_SIGNALS_HELP = {"measured": "measured position (\"instance.variable\", or an expression "
                                 "of outputs)",
                     "feedforward": "input the feedforward drives (\"instance.variable\")",
                     "effort": "commanded effort, the labels (\"instance.variable\")"}


@dataclass(frozen=True)
class Axis:
    """One axis: what the loop measures and commands on it, in which units. A description of
    logs alone gives no loop signals (None); `measured`, `feedforward` and `effort` are asked
    of a loop only, and check_signals refuses a loop's description that lacks one."""

    name: str
    loop_measured: Expression | None  # of "instance.variable" outputs; a bare name is the
    # signal itself
    loop_feedforward: str | None  # "instance.variable": the FMU input the learned model drives
    loop_effort: str | None  # "instance.variable": the commanded effort, the model's label
    limits: Limits
    unit: str = "m"
    effort_unit: str = "N"
    true: Expression | None = None  # the true position, for evaluation only (a simulation's)

    @property
    def measured(self) -> Expression:
        """The measured position in the loop (MissingLoopSignal in a logs-only description)."""
        return self._given(self.loop_measured, "measured")

    @property
    def feedforward(self) -> str:
        """The FMU input the learned model drives (MissingLoopSignal where not given)."""
        return self._given(self.loop_feedforward, "feedforward")

    @property
    def effort(self) -> str:
        """The loop's commanded effort (MissingLoopSignal where not given)."""
        return self._given(self.loop_effort, "effort")

    def _given(self, value: T | None, part: str) -> T:
        if value is None:
            raise MissingLoopSignal(f"machine axis {self.name!r}: no {part} given; a loop's "
                                    f"description names {', '.join(LOOP_SIGNALS)} per axis")
        return value

    @property
    def evaluated(self) -> Expression:
        """The position the tracking metrics compare with the reference: the true one where
        the loop gives it, else the measured one."""
        return self.true or self.measured

    @property
    def reference(self) -> str:
        return f"{self.name}_ref"

    @property
    def derivatives(self) -> tuple[str, str, str]:
        """The reference's velocity, acceleration and jerk signals, derived by flexff."""
        return tuple(f"{d}{self.name}_ref" for d in "vaj")  # type: ignore[return-value]

    @property
    def measured_signal(self) -> str:
        """The measured position's name in records and datasets."""
        return f"{self.name}_measured"

    @property
    def effort_signal(self) -> str:
        """The commanded effort's name in records and datasets (the labels)."""
        return f"{self.name}_effort"

    @property
    def motion(self) -> tuple[str, str, str]:
        """The names of position, velocity and acceleration in prior terms' expressions."""
        return self.name, f"v{self.name}", f"a{self.name}"


@dataclass(frozen=True)
class Prior:
    """The physics prior: per axis, the linear-in-parameters terms of PRIOR_TERMS and user
    terms (`extra[axis][term]`, expressions of the axes' motion names); `coulomb_width` is the
    tanh width of Coulomb friction in the axis's velocity unit (None: derived from the data)."""

    terms: tuple[str, ...] = DEFAULT_PRIOR_TERMS
    extra: Mapping[str, Mapping[str, Expression]] = field(default_factory=dict)
    coulomb_width: float | None = None


@dataclass(frozen=True)
class LogMap:
    """How the machine's logs hold its dataset signals: the time column's name, named numbers
    (`scalars`, e.g. a drive's gain) and, per signal of Machine.signals, an expression of the
    log's column names and the scalars (`x_effort = "gain * vir"`; a scalar hides a column
    of its name). A signal not mapped is the log's column of its own name (a reference only
    where the log holds it)."""

    time: str = "time"
    scalars: Mapping[str, float] = field(default_factory=dict)
    columns: Mapping[str, Expression] = field(default_factory=dict)


@dataclass(frozen=True)
class IlcSettings:
    """Iterative learning control on this machine's loop (learning.ilc): learning trials after
    PID alone, the corner of its zero-phase low-pass Q [Hz], the gain on the model's
    correction, the learning filter's model (a name registered by a machine package,
    cosim.inverse_models) and the "instance.name" option or parameter that seeds the loop's
    noise, drawn anew each trial; None: ILC's own default (the model identified on trial 0,
    the noise as the loop has it)."""

    iterations: int | None = None
    cutoff_hz: float | None = None
    gain: float | None = None
    model: str | None = None
    seed: str | None = None

    def table(self) -> dict[str, float | str]:
        """The settings given, as the TOML table `[machine.ilc]`."""
        return {k: v for k, v in vars(self).items() if v is not None}


@dataclass(frozen=True)
class Learning:
    """The preprocessing of features and labels, each None: derived from the training data
    (learning.machine_features.MachineFeatures, which these settings start): the labels'
    zero-phase low-pass corner [Hz] and order, the efforts' lead over the motion [s] (None:
    half a sample, the zero-order hold's), the model rate [Hz]."""

    cutoff_hz: float | None = None
    filter_order: int | None = None
    lead_s: float | None = None
    model_rate_hz: float | None = None

    def given(self) -> dict[str, float | int]:
        """The settings given, by name."""
        return {k: v for k, v in vars(self).items() if v is not None}


@dataclass(frozen=True)
class Machine:
    """A machine's axes, prior and log map, checked."""

    name: str
    axes: tuple[Axis, ...]
    prior: Prior = Prior()
    log: LogMap = LogMap()
    exact: Mapping[str, float] = field(default_factory=dict)  # "instance.parameter" -> value
    ilc: IlcSettings = IlcSettings()
    learning: Learning = Learning()

    def axis(self, name: str) -> Axis:
        return next(a for a in self.axes if a.name == name)

    @property
    def reference_signals(self) -> tuple[str, ...]:
        """Every axis's position, velocity, acceleration and jerk reference, axis by axis."""
        return tuple(n for a in self.axes for n in (a.reference, *a.derivatives))

    @property
    def signals(self) -> tuple[str, ...]:
        """A dataset's columns beside `time`: references, measured positions, efforts."""
        return (*self.reference_signals, *(a.measured_signal for a in self.axes),
                *(a.effort_signal for a in self.axes))


def load_machine(path: str | Path, origin: str | None = None) -> Machine:
    """The `[machine]` table of the TOML file at `path`."""
    path = Path(path)
    where = origin or str(path)
    if not path.is_file():
        raise ConfigError(where, "machine", f"no such machine description file: {path}")
    try:
        data = tomllib.loads(path.read_text())
    except (tomllib.TOMLDecodeError, UnicodeDecodeError) as error:
        raise ConfigError(str(path), "file", f"not valid TOML: {error}") from None
    if not isinstance(data.get("machine"), dict):
        raise ConfigError(str(path), "machine", "the file holds no [machine] table")
    return parse_machine(data["machine"], str(path), path.resolve().parent)


def parse_machine(table: Any, origin: str, base: Path = Path(".")) -> Machine:
    """A `[machine]` table, or the name of a file holding one (relative to `base`), checked."""
    if isinstance(table, str):
        return load_machine(base / table, origin)
    _Check(origin).table(table, "machine", "machine")
    check = _Check(origin)
    axes_tables = table.get("axis")
    if not isinstance(axes_tables, list) or not axes_tables:
        raise check.error("machine.axis", "give at least one axis as [[machine.axis]]")
    axes = tuple(check.axis(t, f"machine.axis[{k}]") for k, t in enumerate(axes_tables))
    names = [a.name for a in axes]
    taken = {n for a in axes for n in (*a.motion[1:], *a.derivatives)}
    for k, axis in enumerate(axes):
        if names.index(axis.name) != k:
            raise check.error(f"machine.axis[{k}].name", f"the axis {axis.name!r} is named twice")
        if axis.name in taken:
            raise check.error(f"machine.axis[{k}].name", f"{axis.name!r} is also a derived "
                              "name of another axis (v<axis>, a<axis>): rename one")
    name = table.get("name", "machine")
    if not isinstance(name, str) or not name:
        raise check.error("machine.name", f"expected a non-empty string, got {name!r}")
    prior = check.prior(table.get("prior", {}), axes)
    log = check.log(table.get("log", {}), Machine(name, axes).signals)
    return Machine(name, axes, prior, log, check.exact(table.get("exact", {})),
                   check.ilc(table.get("ilc", {})), check.learning(table.get("learning", {})))


def machine_table(machine: Machine) -> dict[str, Any]:
    """The description as the TOML table `parse_machine` reads (cosim.config.expanded)."""
    axes = [{"name": a.name, "unit": a.unit,
             **({"measured": a.loop_measured.text} if a.loop_measured else {}),
             **({"true": a.true.text} if a.true else {}),
             **({"feedforward": a.loop_feedforward} if a.loop_feedforward else {}),
             **({"effort": a.loop_effort} if a.loop_effort else {}), "effort_unit": a.effort_unit,
             "range": [a.limits.low, a.limits.high], "velocity": a.limits.velocity,
             "acceleration": a.limits.acceleration,
             **({"jerk": a.limits.jerk} if a.limits.jerk is not None else {})}
            for a in machine.axes]
    prior = {"terms": list(machine.prior.terms),
             **({"extra": {axis: {term: e.text for term, e in terms.items()}
                           for axis, terms in machine.prior.extra.items()}}
                if machine.prior.extra else {}),
             **({"coulomb_width": machine.prior.coulomb_width}
                if machine.prior.coulomb_width is not None else {})}
    log = {"time": machine.log.time, "scalars": dict(machine.log.scalars),
           "columns": {n: e.text for n, e in machine.log.columns.items()}}
    return {"name": machine.name, "axis": axes, "prior": prior, "log": log,
            **({"exact": dict(machine.exact)} if machine.exact else {}),
            **({"ilc": machine.ilc.table()} if machine.ilc.table() else {}),
            **({"learning": machine.learning.given()} if machine.learning.given() else {})}


def check_signals(machine: Machine, outputs: Iterable[str], inputs: Iterable[str],
                  origin: str) -> None:
    """Refuse a description whose signals the loop lacks: measured signals and efforts must
    be outputs (`instance.variable` or source signals), feedforwards inputs."""
    outputs, inputs = set(outputs), set(inputs)
    for k, axis in enumerate(machine.axes):
        key = f"machine.axis[{k}]"
        for part, value in zip(LOOP_SIGNALS, (axis.loop_measured, axis.loop_feedforward,
                                              axis.loop_effort), strict=True):
            if value is None:
                raise ConfigError(origin, f"{key}.{part}", "required where a loop is run: "
                                  f"name the loop's {LOOP_SIGNALS_HELP[part]}")
        for part, position in (("measured", axis.measured), ("true", axis.true)):
            for name in sorted(position.names if position else ()):
                if name not in outputs:
                    raise ConfigError(origin, f"{key}.{part}", f"{name!r} is not an output of "
                                      f"the loop{_nearest(name, outputs)}")
        if axis.feedforward not in inputs:
            raise ConfigError(origin, f"{key}.feedforward", f"{axis.feedforward!r} is not an "
                              f"input of the loop{_nearest(axis.feedforward, inputs)}")
        if axis.effort not in outputs:
            raise ConfigError(origin, f"{key}.effort", f"{axis.effort!r} is not an output of "
                              f"the loop{_nearest(axis.effort, outputs)}")
        if axis.effort in axis.measured.names:
            raise ConfigError(origin, f"{key}.effort", f"{axis.effort!r} is the measured "
                              "position, not an effort: name the output the controller commands")


def _instance_variable(text: str) -> bool:
    """Whether `text` is an FMU's instance name, a dot and a variable's name (any, as FMI's
    flat names may be; the loop's check finds one its FMU lacks)."""
    instance, dot, variable = text.partition(".")
    return bool(dot and instance and variable.strip() and not re.search(r"\s", instance))


def _nearest(name: str, names: set[str]) -> str:
    import difflib

    close = difflib.get_close_matches(name, sorted(names), n=1)
    return f" (did you mean {close[0]!r}?)" if close else ""


class _Check:
    """Reads one description; every error names `machine.key`."""

    def __init__(self, origin: str) -> None:
        self.origin = origin

    def error(self, key: str, message: str) -> ConfigError:
        return ConfigError(self.origin, key, message)

    def table(self, table: Any, key: str, kind: str) -> None:
        if not isinstance(table, Mapping):
            raise self.error(key, f"expected a table, got {table!r}")
        unknown = sorted(set(table) - set(KEYS[kind]))
        if unknown:
            raise self.error(f"{key}.{unknown[0]}", f"unknown key (known: {', '.join(KEYS[kind])})")

    def text(self, table: Mapping[str, Any], key: str, name: str, default: str | None = None
             ) -> str:
        value = table.get(name, default)
        if value is None:
            raise self.error(f"{key}.{name}", "required")
        if not isinstance(value, str) or not value:
            raise self.error(f"{key}.{name}", f"expected a non-empty string, got {value!r}")
        return value

    def number(self, table: Mapping[str, Any], key: str, name: str, positive: bool = True
               ) -> float | None:
        value = table.get(name)
        if value is None:
            return None
        if isinstance(value, bool) or not isinstance(value, int | float) \
                or not math.isfinite(value) or (positive and value <= 0):
            raise self.error(f"{key}.{name}", f"expected a {'positive ' if positive else ''}"
                             f"finite number, got {value!r}")
        return float(value)

    def signal(self, table: Mapping[str, Any], key: str, name: str) -> str:
        value = self.text(table, key, name)
        if not _instance_variable(value):
            raise self.error(f"{key}.{name}", f"expected 'instance.variable' (the variable "
                             f"as the FMU names it: pos, pos[1], der(x), 'my var'), got {value!r}")
        return value

    def axis(self, table: Any, key: str) -> Axis:
        self.table(table, key, "axis")
        name = self.text(table, key, "name")
        if not AXIS_NAME.match(name):
            raise self.error(f"{key}.name", f"{name!r}: an axis name is a letter, then letters "
                             "or digits (it names signals such as <axis>_ref)")
        measured = self.position(table, key, "measured") if "measured" in table else None
        true = self.position(table, key, "true") if "true" in table else None
        limits = self.limits(table, key)
        feedforward, effort = (self.signal(table, key, part) if part in table else None
                               for part in ("feedforward", "effort"))
        return Axis(name, measured, feedforward, effort, limits,
                    self.text(table, key, "unit", "m"), self.text(table, key, "effort_unit", "N"),
                    true)

    def position(self, table: Mapping[str, Any], key: str, name: str) -> Expression:
        """A position: one signal of the loop or an expression of several (a kinematic map)."""
        try:
            position = parse_expression(self.text(table, key, name), f"{key}.{name}")
        except ExpressionError as error:
            raise self.error(f"{key}.{name}", str(error).split(": ", 1)[1]) from None
        if not position.names:
            raise self.error(f"{key}.{name}", "names no signal of the loop")
        return position

    def limits(self, table: Mapping[str, Any], key: str) -> Limits:
        span = table.get("range")
        if not (isinstance(span, list) and len(span) == 2 and all(
                isinstance(v, int | float) and not isinstance(v, bool) and math.isfinite(v)
                for v in span) and span[0] < span[1]):
            raise self.error(f"{key}.range", f"expected [low, high] with low < high, got {span!r}")
        bounds = {n: self.number(table, key, n) for n in ("velocity", "acceleration", "jerk")}
        for name in ("velocity", "acceleration"):
            if bounds[name] is None:
                raise self.error(f"{key}.{name}", "required: the excitation's bound on |"
                                 f"{name}| in the axis's unit per second"
                                 f"{'' if name == 'velocity' else ' squared'}")
        velocity, acceleration = bounds["velocity"], bounds["acceleration"]
        assert velocity is not None and acceleration is not None
        return Limits(float(span[0]), float(span[1]), velocity, acceleration, bounds["jerk"])

    def exact(self, table: Any) -> dict[str, float]:
        if not isinstance(table, Mapping):
            raise self.error("machine.exact", "expected a table of \"instance.parameter\" = "
                             "number: the start values with which the loop measures exactly")
        for name in table:
            if not _instance_variable(name):
                raise self.error(f"machine.exact.{name}", "expected 'instance.parameter'")
            self.number(table, "machine.exact", name, positive=False)
        return {name: float(value) for name, value in table.items()}

    def ilc(self, table: Any) -> IlcSettings:
        self.table(table, "machine.ilc", "ilc")
        iterations = table.get("iterations")
        if iterations is not None and (isinstance(iterations, bool)
                                       or not isinstance(iterations, int) or iterations < 1):
            raise self.error("machine.ilc.iterations", f"expected a whole number of learning "
                             f"trials, at least 1, got {iterations!r}")
        model = table.get("model")
        if model is not None:
            from flexff.cosim.inverse_models import inverse_model_names

            known = inverse_model_names()
            if model not in known:
                raise self.error("machine.ilc.model", f"expected the name of a registered "
                                 f"inverse model ({', '.join(known) or 'none registered'}), "
                                 f"got {model!r}")
        seed = table.get("seed")
        if seed is not None and not (isinstance(seed, str) and "." in seed.strip(".")):
            raise self.error("machine.ilc.seed", f"expected 'instance.name': the option or "
                             f"parameter that seeds the loop's noise, got {seed!r}")
        return IlcSettings(iterations, self.number(table, "machine.ilc", "cutoff_hz"),
                           self.number(table, "machine.ilc", "gain"), model, seed)

    def learning(self, table: Any) -> Learning:
        self.table(table, "machine.learning", "learning")
        key = "machine.learning"
        order = table.get("filter_order")
        if order is not None and (isinstance(order, bool) or not isinstance(order, int)
                                  or not 1 <= order <= 12):
            raise self.error(f"{key}.filter_order", f"expected a whole number from 1 to 12 (the "
                             f"labels' Butterworth low-pass order), got {order!r}")
        lead = self.number(table, key, "lead_s", positive=False)
        if lead is not None and lead < 0:
            raise self.error(f"{key}.lead_s", f"expected the efforts' lead over the motion in "
                             f"seconds, at least 0, got {lead!r}")
        return Learning(self.number(table, key, "cutoff_hz"), order, lead,
                        self.number(table, key, "model_rate_hz"))

    def prior(self, table: Any, axes: tuple[Axis, ...]) -> Prior:
        self.table(table, "machine.prior", "prior")
        terms = table.get("terms", list(DEFAULT_PRIOR_TERMS))
        if not isinstance(terms, list) or any(t not in PRIOR_TERMS for t in terms):
            raise self.error("machine.prior.terms", f"expected a list of {', '.join(PRIOR_TERMS)}"
                             f", got {terms!r}")
        if "coulomb" in terms and "coulomb_asymmetric" in terms:
            raise self.error("machine.prior.terms", "coulomb and coulomb_asymmetric model the "
                             "same friction: choose one")
        motion = {n for a in axes for n in a.motion}
        extra: dict[str, dict[str, Expression]] = {}
        for axis_name, entries in table.get("extra", {}).items():
            key = f"machine.prior.extra.{axis_name}"
            if axis_name not in {a.name for a in axes}:
                raise self.error(key, f"no axis is named {axis_name!r}")
            if not isinstance(entries, Mapping):
                raise self.error(key, "expected a table of term = \"expression\"")
            extra[axis_name] = {}
            for term, text in entries.items():
                try:
                    expression = parse_expression(text, f"{key}.{term}")
                except ExpressionError as error:
                    raise self.error(f"{key}.{term}", str(error).split(": ", 1)[1]) from None
                unknown = sorted(expression.names - motion)
                if unknown:
                    raise self.error(f"{key}.{term}", f"names {', '.join(unknown)}; a term may "
                                     f"use {', '.join(sorted(motion))}")
                extra[axis_name][term] = expression
        width = self.number(table, "machine.prior", "coulomb_width")
        return Prior(tuple(terms), extra, width)

    def log(self, table: Any, signals: tuple[str, ...]) -> LogMap:
        self.table(table, "machine.log", "log")
        time = self.text(table, "machine.log", "time", "time")
        scalars = table.get("scalars", {})
        if not isinstance(scalars, Mapping):
            raise self.error("machine.log.scalars", "expected a table of name = number")
        for name in scalars:
            key = f"machine.log.scalars.{name}"
            if not SCALAR_NAME.match(name) or name in FUNCTIONS or name in CONSTANTS:
                raise self.error(key, "a scalar's name is a letter or _, then letters, digits "
                                 "or _, and no function or constant of an expression")
            if name in signals:
                raise self.error(key, f"{name} is a dataset signal, read from the log's "
                                 f"column of its name: name the scalar otherwise")
            self.number(scalars, "machine.log.scalars", name, positive=False)
        columns = table.get("columns", {})
        if not isinstance(columns, Mapping):
            raise self.error("machine.log.columns", "expected a table of signal = "
                             "\"expression of the log's columns\"")
        expressions = {}
        for signal, text in columns.items():
            key = f"machine.log.columns.{signal}"
            if signal == "time":
                raise self.error(key, "the time column is named by machine.log.time")
            if signal not in signals:
                raise self.error(key, f"{signal!r} is not a dataset signal of this machine"
                                 f"{_nearest(signal, set(signals))}; its signals: "
                                 f"{', '.join(signals)}")
            try:
                expressions[signal] = parse_expression(text, key)
            except ExpressionError as error:
                raise self.error(key, str(error).split(": ", 1)[1]) from None
            if not expressions[signal].names - set(scalars):
                raise self.error(key, f"{text!r} names no column of the log, only scalars")
        return LogMap(time, {n: float(v) for n, v in scalars.items()}, expressions)
