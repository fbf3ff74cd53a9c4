"""Run configurations: a TOML file parsed and checked into cosim.schema's plain data before
anything is built or run, and written back out in the general form (`flexff config expand`).

Short forms, built-in FMUs and reference kinds that machine packages register (cosim.plugins,
cosim.builtins) are expanded and checked here too. Any problem (unknown table or key, wrong
type, missing file, an FMU variable that does not exist or has another type, a reference
its kind refuses, ...) raises ConfigError naming `table.key`; the wiring (cosim.wiring)
is checked when the FMUs are resolved, before anything runs.

Every key and reference kind: "Run configuration" (docs/reference/configuration.md, generated
from cosim.config_keys).
"""

from __future__ import annotations

import math
import tomllib
from collections.abc import Mapping, Sequence
from dataclasses import replace
from pathlib import Path
from typing import Any

import tomli_w

from flexff.cosim.axis_references import AXIS_KINDS, AXIS_OPTIONS, REST, SHARE
from flexff.cosim.builtins import checked_options, registered
from flexff.cosim.checks import TableChecker
from flexff.cosim.config_error import ConfigError
from flexff.cosim.example_configs import config_examples as config_examples  # public API
from flexff.cosim.machine import Machine, machine_table, parse_machine
from flexff.cosim.memory import MemoryNeeded
from flexff.cosim.plugins import ShortForm, short_forms
from flexff.cosim.references import (
    ReferenceKeyError,
    Sampled,
    build_reference,
    reference_kind_names,
    reference_kinds,
)
from flexff.cosim.sandbox import KEYS as SANDBOX_KEYS
from flexff.cosim.sandbox import MEMORY_MB, SCRATCH_MB, Sandbox
from flexff.cosim.schema import (
    ALGORITHMS,
    SOURCE_KINDS,
    UNCONNECTED,
    ConnectionConfig,
    FmuConfig,
    RecordConfig,
    ReferenceConfig,
    RunConfig,
    SourceConfig,
    whole_steps,
)
from flexff.fmu.defaults import DEFAULT_STEP
from flexff.fmu.description_faults import warn
from flexff.fmu.errors import not_a_file
from flexff.fmu.fmi_version import FMI_VERSIONS
from flexff.fmu.importer import FmuError, FmuInfo, read_fmu, typed_value
from flexff.fmu.model_exchange import SOLVERS

TABLES = ("run", "reference", "source", "fmu", "connection", "record", "machine")
RECORDED = "recorded"  # what a run's record holds, in its run.json: read back, it is ignored
FAULTS = "description_faults"  # its FMUs' description warnings, in its run.json: likewise
MAX_STEPS = 2**53  # a run's steps: point k's time start + k * step needs k exact in a float
FLOAT32_MAX = 3.4028234663852886e38


def load_config(path: str | Path) -> RunConfig:
    """Read and check a TOML run configuration (relative paths against its folder)."""
    path = Path(path)
    return parse_config(read_tables(path), name=path.stem, base=path.resolve().parent,
                        origin=str(path))


def checked(config: RunConfig) -> RunConfig:
    """`config` as the parser makes it (itself, if the parser made it): after a change in
    code (dataclasses.replace) the same rules hold as for TOML and SSP; a ConfigError names the
    key at fault. Connections keep their keys (an SSP file's `ssd:Connection[k]`) for later
    errors.

    >>> import dataclasses
    >>> api.check(dataclasses.replace(config, stop=2.0)).stop
    2.0"""
    if config.checked:
        return config
    again = parse_config(expanded(config), name=config.name, origin=config.origin)
    keys = tuple(replace(c, key=old.key) for c, old in zip(again.connections, config.connections))
    object.__setattr__(again, "connections", keys)  # still the parser's own, checked object
    return again


def with_isolation(config: RunConfig, isolate: bool, step_timeout: float | None,
                   sandbox: bool = True) -> RunConfig:
    """`config` with every FMU in its own process (`isolate`, as `flexff run --isolate`), its
    calls bounded by `step_timeout` (s; None: as configured) and, unless `sandbox` is false
    (`--no-sandbox`), in its sandbox; checked again."""
    fmus = tuple(replace(f, isolate=f.isolate or isolate, sandbox=f.sandbox if sandbox else None)
                 for f in config.fmus)
    timeout = config.step_timeout if step_timeout is None else step_timeout
    return checked(replace(config, fmus=fmus, step_timeout=timeout))


def with_strict(config: RunConfig) -> RunConfig:
    """`config` with every FMU file's description warnings refused (`flexff run --strict`),
    checked again."""
    return checked(replace(config, fmus=tuple(replace(f, strict=f.path is not None)
                                              for f in config.fmus)))


def _sandbox_keys(sandbox: Sandbox | None) -> dict[str, Any]:
    """An isolated FMU's sandbox keys, where they differ from the defaults."""
    if sandbox is None:
        return {"sandbox": False}
    return {**({"sandbox_memory": sandbox.memory_mb} if sandbox.memory_mb != MEMORY_MB else {}),
            **({"sandbox_cpu": sandbox.cpu_s} if sandbox.cpu_s is not None else {}),
            **({"sandbox_scratch": sandbox.scratch_mb} if sandbox.scratch_mb != SCRATCH_MB
               else {}),
            **({"sandbox_read": [str(p) for p in sandbox.read]} if sandbox.read is not None
               else {})}


def read_tables(path: Path) -> dict[str, Any]:
    """The tables of the TOML file at `path`, unchecked; ConfigError naming the file when it
    is missing or not TOML."""
    why = not_a_file(path, "configuration file")
    if why is not None:
        raise ConfigError(str(path), "file", why)
    try:
        return tomllib.loads(path.read_text())
    except (tomllib.TOMLDecodeError, UnicodeDecodeError) as error:
        raise ConfigError(str(path), "file", f"not valid TOML: {error}") from None


def parse_config(data: Mapping[str, Any] | str, name: str = "config",
                 base: str | Path = ".", origin: str = "<config>") -> RunConfig:
    """Check a configuration given as TOML text or as its parsed tables."""
    if isinstance(data, str):
        try:
            data = tomllib.loads(data)
        except tomllib.TOMLDecodeError as error:
            raise ConfigError(origin, "file", f"not valid TOML: {error}") from None
    return _Parser(origin, Path(base)).parse(data, name)


def expanded(config: RunConfig) -> dict[str, Any]:
    """The configuration in the general form, as TOML tables (paths absolute)."""
    run = {"step": config.step, "start": config.start, "stop": config.stop,
           **({"tolerance": config.tolerance} if config.tolerance is not None else {}),
           **({"step_timeout": config.step_timeout} if config.step_timeout is not None else {}),
           "algorithm": config.algorithm, "order": [f.name for f in config.fmus]}
    data: dict[str, Any] = {"run": run}
    if config.reference is not None:
        data["reference"] = {"kind": config.reference.kind, **_plain(config.reference.options)}
    if config.sources:
        data["source"] = [{"kind": s.kind, **({"path": str(s.path)} if s.path else {}),
                           **({"values": dict(s.values)} if s.values else {})}
                          for s in config.sources]
    data["fmu"] = {f.name: {**({"path": str(f.path)} if f.path else {}),
                            **({"builtin": f.builtin} if f.builtin else {}),
                            **_plain(f.options),
                            **({"parameters": dict(f.parameters)} if f.parameters else {}),
                            **({"unconnected": f.unconnected}
                               if f.unconnected != "error" else {}),
                            **({"tolerance": f.tolerance} if f.tolerance is not None else {}),
                            **({"isolate": True} if f.isolate else {}),
                            **(_sandbox_keys(f.sandbox) if f.isolate else {}),
                            **({"allow_nonfinite": True} if f.allow_nonfinite else {}),
                            **({"fmi": f.fmi} if f.fmi != FMI_VERSIONS[0] else {}),
                            **({"solver": f.solver} if f.solver else {}),
                            **({"scheduled": True} if f.scheduled else {}),
                            **({"strict": True} if f.strict else {}),
                            **({"feedthrough": False} if not f.feedthrough else {})}
                   for f in config.fmus}
    if config.connections:
        data["connection"] = [{"from": c.from_name, "to": c.to_name,
                               **({"gain": c.gain} if c.gain != 1.0 else {}),
                               **({"offset": c.offset} if c.offset != 0.0 else {})}
                              for c in config.connections]
    data["record"] = {**({"signals": list(config.record.signals)}
                         if config.record.signals is not None else {}),
                      "csv": config.record.csv,
                      **({"plot": config.record.plot} if config.record.plot is not None else {}),
                      **({"every": config.record.every} if config.record.every != 1 else {})}
    if config.machine is not None:
        data["machine"] = machine_table(config.machine)
    return data


def expanded_text(config: RunConfig) -> str:
    """`expanded` as TOML text, with a comment naming where it came from."""
    return f"# {config.origin}, in the general form\n" + tomli_w.dumps(expanded(config))


def _start(reference: Sampled) -> tuple[float, ...]:
    """A machine package's reference's first point, handed to its short form and built-ins
    (the point their plant starts at)."""
    signals = reference.signals()
    return tuple(float(signals[p][0]) for p in reference.positions)


def _plain(value: Any) -> Any:
    """Tuples as lists and paths as strings, for TOML."""
    if isinstance(value, Mapping):
        return {k: _plain(v) for k, v in value.items() if v is not None}
    if isinstance(value, (tuple, list)):
        return [_plain(v) for v in value]
    return str(value) if isinstance(value, Path) else value


class _Parser(TableChecker):
    """Checks one configuration; every error names the file and `table.key`."""

    allow_nonfinite = False  # [run] allow_nonfinite, once read

    def parse(self, data: Mapping[str, Any], name: str) -> RunConfig:
        others = [t for t in data if t not in (*TABLES, RECORDED, FAULTS)]
        # a plain general form loads no machine package (cosim.plugins)
        forms = short_forms() if others or "fmu" not in data else ()
        tables = (*TABLES, *(t for form in forms for t in form.tables))
        for table in others:
            if table not in tables:
                raise self.error(table, f"unknown table [{table}] (known: {', '.join(tables)})")
        short = self.short_form(data, forms)
        run = self.table(data, "run")
        self.keys(run, "run", ("step", "start", "stop", "tolerance", "step_timeout", "algorithm",
                               "order", "allow_nonfinite"))
        self.allow_nonfinite = self.flag(run, "run", "allow_nonfinite")
        step = self.number(run, "run", "step", DEFAULT_STEP, positive=True)
        machine = self.machine(data, short)  # an axis reference's axes and limits
        reference, signal = None, None
        if "reference" in data:
            reference = self.reference(self.table(data, "reference"))
            signal = self.sampled(reference, self.table(data, "reference"), step, machine)
        fmus: list[FmuConfig] = []
        sources: list[SourceConfig] = []
        start = _start(signal) if signal is not None and reference is not None \
            and reference.kind not in AXIS_KINDS else None
        if short is not None:
            fmus, sources = short.expand(self, data, start)
        for fmu_name, table in self.table(data, "fmu").items():
            if any(f.name == fmu_name for f in fmus):
                raise self.error(f"fmu.{fmu_name}", f"the FMU {fmu_name!r} is also given by the "
                                                    f"short form [{fmu_name}]: give it once")
            fmus.append(self.fmu(fmu_name, table, start))
        if not fmus:
            raise self.error("fmu", "no FMU to run: add an [fmu.NAME] table")
        start_time = self.number(run, "run", "start", next(
            (read_fmu(f.path, checked=False).default_start or 0.0 for f in fmus if f.path),
            0.0))
        stop = self.stop(run, signal, fmus, step, start_time)
        tolerance = self.tolerance(run, "run")
        fmus = [replace(f, tolerance=self.fmu_tolerance(f, tolerance),
                        allow_nonfinite=f.allow_nonfinite or self.allow_nonfinite)
                for f in fmus]  # a short form's FMUs too
        sources += self.sources(data.get("source", []))
        step_timeout = self.step_timeout(run, fmus)
        config = RunConfig(
            name=name, step=step, stop=stop, start=start_time, tolerance=tolerance,
            step_timeout=step_timeout,
            fmus=self.order(run, fmus), reference=reference,
            sources=tuple(sources), connections=self.connections(data.get("connection", []),
                                                                 fmus),
            algorithm=self.choice(run, "run", "algorithm", ALGORITHMS, "gauss-seidel"),
            record=self.record(self.table(data, "record")), origin=self.origin,
            machine=machine)
        object.__setattr__(config, "checked", True)  # frozen; see RunConfig
        return config

    # -- run ----------------------------------------------------------------------------
    def sampled(self, reference: ReferenceConfig, table: Mapping[str, Any], step: float,
                machine: Machine | None) -> Sampled:
        try:
            return build_reference(reference.kind, reference.options, step, machine)
        except ReferenceKeyError as error:
            raise self.error(f"reference.{error.key}", str(error)) from None
        except MemoryNeeded as error:
            raise self.error("run.step", f"{error}: a larger run.step or a shorter "
                                         f"reference") from None
        except (ValueError, OSError) as error:
            given = [f"reference.{k}" for k in table if k != "kind"]
            raise self.error(", ".join(given) or "reference.kind", str(error)) from None

    def stop(self, run: Mapping[str, Any], signal: Sampled | None, fmus: Sequence[FmuConfig],
             step: float, start: float) -> float:
        """run.stop, the end time; default the start plus the reference's duration, else the
        first FMU's experiment."""
        default = start + signal.duration if signal is not None else None
        if default is None:
            default = next((read_fmu(f.path, checked=False).default_stop for f in fmus
                            if f.path), None)
        stop = self.number(run, "run", "stop", default)
        if not stop > start:
            raise self.error("run.stop", f"the end time {stop!r} s must come after the start "
                                         f"time {start!r} s (run.start)")
        steps = (stop - start) / step
        if not steps <= MAX_STEPS:  # inf as well
            raise self.error("run.stop", f"the run's length {stop - start!r} s is {steps:.3g} "
                                         f"steps of {step!r} s, more than the {MAX_STEPS:.3g} "
                                         f"a run can count: shorten run.stop or enlarge "
                                         f"run.step")
        if not whole_steps(stop - start, step):
            raise self.error("run.stop", f"the run's length {stop - start!r} s (run.stop - "
                                         f"run.start) is not a whole number of steps of "
                                         f"{step!r} s (run.step)")
        return stop

    def tolerance(self, t: Mapping[str, Any], where: str) -> float | None:
        """A relative tolerance for the FMUs' own solvers (None: not given)."""
        return self.number(t, where, "tolerance", None, positive=True) if "tolerance" in t \
            else None

    def step_timeout(self, run: Mapping[str, Any], fmus: Sequence[FmuConfig]) -> float | None:
        """run.step_timeout, for the FMUs in their own process."""
        if "step_timeout" not in run:
            return None
        if not any(f.isolate for f in fmus):
            raise self.error("run.step_timeout", "bounds the calls of FMUs in their own "
                                                 "process: set isolate = true on an [fmu.NAME] "
                                                 "(or run with --isolate)")
        return self.number(run, "run", "step_timeout", None, positive=True)

    def fmu_info(self, path: Path, where: str, strict: bool) -> FmuInfo:
        """The FMU's model description, read once for all of its table's keys; its faults
        that change no run said once (refused if `strict`: fmu.description_faults)."""
        try:
            info = read_fmu(path, strict=strict)
        except FmuError as error:
            raise self.error(f"{where}.path", str(error)) from None
        warn(where, path, info.faults)
        return info

    def solver(self, t: Mapping[str, Any], where: str, info: FmuInfo) -> str | None:
        """fmu.NAME.solver: model exchange with a solver; "cvode" for an FMU that has no
        co-simulation interface, None (co-simulation) for one that has."""
        if "solver" not in t:
            return None if info.co_simulation or info.scheduled_only else SOLVERS[0]
        solver = self.choice(t, where, "solver", SOLVERS, None)
        if info.me_identifier is None:
            raise self.error(f"{where}.solver", f"{info.path.name} has no model-exchange "
                                                f"interface to solve: remove the key to "
                                                f"co-simulate it")
        return solver

    def scheduled(self, t: Mapping[str, Any], where: str, info: FmuInfo) -> bool:
        """fmu.NAME.scheduled: through the FMU's scheduled-execution interface (fmu.scheduled);
        an FMU with that interface alone is run so without the key."""
        if not self.flag(t, where, "scheduled"):
            return info.scheduled_only
        if info.se_identifier is None:
            raise self.error(f"{where}.scheduled", f"{info.path.name} has no "
                                                   f"scheduled-execution interface: remove the "
                                                   f"key to co-simulate it")
        if "solver" in t:
            raise self.error(f"{where}.scheduled", "an FMU runs either with a solver (model "
                                                   "exchange) or scheduled: give one of the keys")
        return True

    def flag(self, t: Mapping[str, Any], where: str, key: str) -> bool:
        """A true-or-false key, false where it is not given."""
        value = t.get(key, False)
        if not isinstance(value, bool):
            raise self.error(f"{where}.{key}", f"expected true or false, got {value!r}")
        return value

    def isolate(self, t: Mapping[str, Any], where: str) -> bool:
        return self.flag(t, where, "isolate")

    def feedthrough(self, t: Mapping[str, Any], where: str, info: FmuInfo) -> bool:
        """False where the table says its FMU's outputs depend on no input directly (its
        model structure declares no dependencies, which FMI reads as every input); refused
        where the FMU declares an output that does."""
        value = t.get("feedthrough", True)
        if not isinstance(value, bool):
            raise self.error(f"{where}.feedthrough", f"expected true or false, got {value!r}")
        direct = sorted(n for n in info.declared if info.dependencies[n])
        if not value and direct:
            raise self.error(f"{where}.feedthrough", f"{info.path.name} declares that "
                             f"{', '.join(direct)} depend{'s' if len(direct) == 1 else ''} "
                             "directly on its inputs: feedthrough = false is for an FMU that "
                             "declares no dependencies; leave it out (or reorder the FMUs)")
        return value

    def sandbox(self, t: Mapping[str, Any], where: str) -> Sandbox | None:
        """The sandbox of an isolated FMU (None: sandbox = false), with its limits."""
        given = [k for k in SANDBOX_KEYS if k in t]
        if given and not self.isolate(t, where):
            raise self.error(f"{where}.{given[0]}", "applies to an FMU in its own process: set "
                                                   "isolate = true (or run with --isolate)")
        if not self.flag({"sandbox": True, **t}, where, "sandbox"):
            if len(given) > 1:
                raise self.error(f"{where}.{given[-1]}", "is a limit of the sandbox, which "
                                                         "sandbox = false turns off")
            return None
        cpu = (self.number(t, where, "sandbox_cpu", None, positive=True) if "sandbox_cpu" in t
               else None)
        return Sandbox(self.number(t, where, "sandbox_memory", MEMORY_MB, positive=True), cpu,
                       self.number(t, where, "sandbox_scratch", SCRATCH_MB, positive=True),
                       read=self.sandbox_read(t, where))

    def sandbox_read(self, t: Mapping[str, Any], where: str) -> tuple[Path, ...] | None:
        """The paths a sandboxed FMU may read besides its own folder and the system's (None:
        reads not confined)."""
        if "sandbox_read" not in t:
            return None
        value = t["sandbox_read"]
        if not (isinstance(value, list) and all(isinstance(v, str) and v for v in value)):
            raise self.error(f"{where}.sandbox_read", f"expected a list of paths, got {value!r}")
        paths = tuple((self.base / v).resolve() for v in value)
        for given, path in zip(value, paths):
            if not path.exists():
                raise self.error(f"{where}.sandbox_read", f"no such file or folder: {given}")
        return paths

    def nonfinite(self, t: Mapping[str, Any], where: str) -> bool:
        """Whether the FMU may take and give NaN and infinite values: its own
        allow_nonfinite, else [run] allow_nonfinite."""
        return self.flag(t, where, "allow_nonfinite") or self.allow_nonfinite

    def finite_parameters(self, values: Mapping[str, Any], where: str, allowed: bool) -> None:
        """Refuse a NaN or infinite start value (unless `allowed`), naming its key."""
        for key, value in values.items():
            if isinstance(value, float) and not math.isfinite(value) and not allowed:
                raise self.error(f"{where}.parameters.{key}", f"{value!r} is not a finite "
                                 f"number: give a finite one, or allow_nonfinite = true in "
                                 f"[{where}] where it is meant")

    def fmu_tolerance(self, f: FmuConfig, run: float | None) -> float | None:
        """An FMU's tolerance: its own key, else [run] tolerance, else its default experiment's
        (a built-in's is read when it is built, cosim.scenario)."""
        if f.tolerance is not None:
            return f.tolerance
        if run is not None or f.path is None:
            return run
        return read_fmu(f.path, checked=False).default_tolerance  # checked by fmu_info

    def order(self, run: Mapping[str, Any], fmus: list[FmuConfig]) -> tuple[FmuConfig, ...]:
        if "order" not in run:
            return tuple(fmus)
        order, names = run["order"], [f.name for f in fmus]
        if (not isinstance(order, list) or sorted(map(str, order)) != sorted(names)
                or len(set(order)) != len(order)):
            raise self.error("run.order", f"expected every FMU name once, in stepping order "
                                          f"(the FMUs: {', '.join(names)}), got {order!r}")
        return tuple(next(f for f in fmus if f.name == n) for n in order)

    def machine(self, data: Mapping[str, Any], short: ShortForm | None) -> Machine | None:
        """The [machine] table's description, else the short form's, else None."""
        table = data.get("machine")
        if table is None and short is not None and short.describe is not None:
            table = short.describe()
        return None if table is None else parse_machine(table, self.origin, self.base)

    # -- a machine's short form ----------------------------------------------------------
    def short_form(self, data: Mapping[str, Any], forms: tuple[ShortForm, ...]
                   ) -> ShortForm | None:
        """The short form whose tables `data` has (cosim.plugins), else, without [fmu.*]
        tables, the default one; None: the general form alone."""
        given = [f for f in forms if any(t in data for t in f.tables)]
        if len(given) > 1:
            raise self.error(", ".join(t for f in given[1:] for t in f.tables if t in data),
                             f"tables of two machines' short forms ({given[0].name}, "
                             f"{given[1].name}): write one of them in the general form")
        if given or "fmu" in data:
            return given[0] if given else None
        return next((f for f in forms if f.default), None)

    # -- [fmu.NAME] ---------------------------------------------------------------------
    def fmu(self, name: str, t: Any, start: tuple[float, ...] | None) -> FmuConfig:
        where = f"fmu.{name}"
        if not isinstance(t, dict):
            raise self.error(where, f"expected a table [fmu.{name}], got {t!r}")
        if "." in name or not name:
            raise self.error(where, "an FMU name must not be empty or contain a dot")
        if ("path" in t) == ("builtin" in t):
            raise self.error(where, "give either path = \"file.fmu\" or builtin = one of "
                                    f"{', '.join(registered())}")
        unconnected = self.choice(t, where, "unconnected", UNCONNECTED, "error")
        parameters = t.get("parameters", {})
        if not isinstance(parameters, dict):
            raise self.error(f"{where}.parameters", f"expected a table {{name = value}}, got "
                                                    f"{parameters!r}")
        allowed = self.nonfinite(t, where)
        if "path" in t:
            self.keys(t, where, ("path", "parameters", "unconnected", "tolerance", "isolate",
                                 "solver", "scheduled", "allow_nonfinite", "strict",
                                 "feedthrough",
                                 *SANDBOX_KEYS))
            path = self.path(t, where, "path")
            strict = self.flag(t, where, "strict")
            info = self.fmu_info(path, where, strict)
            return FmuConfig(name, path=path, parameters=self.fmu_parameters(info, parameters,
                                                                             where, allowed),
                             unconnected=unconnected, tolerance=self.tolerance(t, where),
                             isolate=self.isolate(t, where), sandbox=self.sandbox(t, where),
                             solver=self.solver(t, where, info),
                             scheduled=self.scheduled(t, where, info), allow_nonfinite=allowed,
                             strict=strict, feedthrough=self.feedthrough(t, where, info))
        builtins = registered()
        builtin = builtins[self.choice(t, where, "builtin", tuple(builtins), None)]
        self.keys(t, where, ("builtin", "parameters", "unconnected", "tolerance", "isolate",
                             "allow_nonfinite", "fmi", *SANDBOX_KEYS, *builtin.keys))
        options = checked_options(self, builtin, t, where)
        if builtin.parameters is not None:
            parameters = builtin.parameters(self, options, parameters, where, start)
        self.finite_parameters(parameters, where, allowed)
        return FmuConfig(name, builtin=builtin.name, options=options,
                         parameters=dict(parameters), unconnected=unconnected,
                         tolerance=self.tolerance(t, where), isolate=self.isolate(t, where),
                         sandbox=self.sandbox(t, where), allow_nonfinite=allowed,
                         fmi=self.fmi_version(t, where))

    def fmu_parameters(self, info: FmuInfo, values: Mapping[str, Any], where: str,
                       allowed: bool) -> dict[str, Any]:
        """Start values checked against the FMU's own variables and their types, and finite
        (a Float32 one within its range) unless non-finite values are `allowed`."""
        checked = {}
        for key, value in values.items():
            v = info.variables.get(key)
            if v is None or not v.settable:
                settable = [n for n, w in info.variables.items() if w.settable]
                raise self.error(f"{where}.parameters.{key}", f"{info.path.name} has no "
                                 f"parameter or input {key!r} (known: "
                                 f"{', '.join(settable) or 'none'})")
            try:
                checked[key] = typed_value(v.kind, value)
            except ValueError as error:
                raise self.error(f"{where}.parameters.{key}", f"{v.type} variable: {error}"
                                 ) from None
            if v.kind == "float32" and abs(checked[key]) > FLOAT32_MAX and not allowed:
                raise self.error(f"{where}.parameters.{key}", f"{value!r} overflows the "
                                 f"{v.type} variable (at most {FLOAT32_MAX:.7g} in magnitude)")
        self.finite_parameters(checked, where, allowed)
        return checked

    # -- connections, sources, record ---------------------------------------------------
    def connections(self, specs: Any, fmus: Sequence[FmuConfig]
                    ) -> tuple[ConnectionConfig, ...]:
        if not isinstance(specs, list):
            raise self.error("connection", "expected [[connection]] tables")
        names = {f.name for f in fmus}
        out: list[ConnectionConfig] = []
        targets: dict[str, str] = {}  # connected input -> the connection's table
        for k, spec in enumerate(specs):
            where = f"connection[{k}]"
            if not isinstance(spec, dict):
                raise self.error(where, f"expected a table {{from = ..., to = ...}}, got {spec!r}")
            self.keys(spec, where, ("from", "to", "gain", "offset"))
            for key in ("from", "to"):
                value = spec.get(key)
                if not isinstance(value, str) or not value:
                    raise self.error(f"{where}.{key}", f"expected \"fmu.variable\""
                                     f"{' or a source signal' if key == 'from' else ''}, got "
                                     f"{value!r}")
            target, source = spec["to"], spec["from"]
            instance = target.partition(".")[0]
            if "." not in target or instance not in names:
                raise self.error(f"{where}.to", f"{target!r} is not \"fmu.input\" of an FMU of "
                                                f"this run ({', '.join(sorted(names))})")
            if "." in source and source.partition(".")[0] not in names:
                raise self.error(f"{where}.from", f"no FMU {source.partition('.')[0]!r} in "
                                                  f"this run ({', '.join(sorted(names))})")
            if target in targets:
                raise self.error(f"{where}.to", f"{target} is already connected by "
                                                f"{targets[target]}: an input takes one signal")
            targets[target] = where
            out.append(ConnectionConfig(source, target, self.number(spec, where, "gain", 1.0),
                                        self.number(spec, where, "offset", 0.0), where))
        return tuple(out)

    def sources(self, specs: Any) -> list[SourceConfig]:
        if not isinstance(specs, list):
            raise self.error("source", "expected [[source]] tables")
        out = []
        for k, spec in enumerate(specs):
            where = f"source[{k}]"
            if not isinstance(spec, dict):
                raise self.error(where, f"expected a table {{kind = ..., ...}}, got {spec!r}")
            kind = self.choice(spec, where, "kind", SOURCE_KINDS, None)
            if kind == "csv":
                self.keys(spec, where, ("kind", "path"))
                out.append(SourceConfig(kind, path=self.path(spec, where, "path")))
                continue
            self.keys(spec, where, ("kind", "values"))
            values = spec.get("values")
            if not isinstance(values, dict) or not values:
                raise self.error(f"{where}.values", f"expected a table {{name = number}}, got "
                                                    f"{values!r}")
            for name in values:
                if "." in name:
                    raise self.error(f"{where}.values.{name}", "a source signal's name has no "
                                     "dot: name it plainly and add a [[connection]]")
            out.append(SourceConfig(kind, {n: self.number(values, f"{where}.values", n, None)
                                           for n in values}))
        return out

    def record(self, t: Mapping[str, Any]) -> RecordConfig:
        self.keys(t, "record", ("signals", "csv", "plot", "every"))
        csv, plot = t.get("csv", False), t.get("plot")
        for key, value in (("csv", csv), ("plot", plot)):
            if value is not None and not isinstance(value, bool):
                raise self.error(f"record.{key}", f"expected true or false, got {value!r}")
        every = self.integer(t, "record", "every", 1)
        if every < 1:
            raise self.error("record.every", f"keeps every N-th point: N >= 1, got {every}")
        if "signals" not in t:
            return RecordConfig(None, csv, plot, every)
        names = t["signals"]
        if not isinstance(names, list) or not all(isinstance(n, str) for n in names):
            raise self.error("record.signals", f"expected a list of signal names, got {names!r}")
        if len(set(names)) != len(names):
            raise self.error("record.signals", "a signal is listed twice")
        return RecordConfig(tuple(names), csv, plot, every)

    # -- [reference] ----------------------------------------------------------------------
    def reference(self, t: Mapping[str, Any]) -> ReferenceConfig:
        kind = self.choice(t, "reference", "kind", reference_kind_names(), None)
        machine_kind = reference_kinds().get(kind)
        if machine_kind is None:
            return ReferenceConfig(kind, self.axis_reference(t, kind))
        if machine_kind.check is None:  # a machine package's (cosim.plugins)
            self.keys(t, "reference", ("kind",))
            return ReferenceConfig(kind)
        return ReferenceConfig(kind, machine_kind.check(self, t))

    def axis_reference(self, t: Mapping[str, Any], kind: str) -> dict[str, Any]:
        """The options of a reference of a machine's axes (cosim.axis_references); the axes
        that per-axis tables name are checked when it is built, against the [machine]."""
        r = "reference"
        self.keys(t, r, ("kind", *AXIS_OPTIONS["common"], *AXIS_OPTIONS[kind]))
        options: dict[str, Any] = {"duration": self.number(t, r, "duration", None, True)}
        seed = self.integer(t, r, "seed", 0)
        if seed < 0:
            raise self.error("reference.seed", f"expected a whole number >= 0, got {seed}")
        share = self.number(t, r, "share", SHARE, positive=True)
        if share > 1:
            raise self.error("reference.share", f"the share of the limits the reference "
                             f"reaches lies in (0, 1], got {share:g}")
        options |= {"seed": seed, "share": share}
        if "start" in t:
            options["start"] = self.per_axis(t, "start", positive=False)
        if "rest" in t:
            options["rest"] = self.number(t, r, "rest", REST)
            if options["rest"] < 0:
                raise self.error("reference.rest", f"expected s >= 0, got {options['rest']:g}")
        for key in ("frequency_hz", "bandwidth_hz"):
            if key in t:
                options[key] = (self.number(t, r, key, None, True)
                                if not isinstance(t[key], dict)
                                else self.per_axis(t, key, positive=True))
        if "points" in t:
            points = t["points"]
            if not isinstance(points, dict) or not all(
                    isinstance(v, list) and v and all(isinstance(p, int | float)
                                                      and not isinstance(p, bool)
                                                      and math.isfinite(p) for p in v)
                    for v in points.values()):
                raise self.error("reference.points", f"expected a table of axis = [position, "
                                 f"...] (the points each axis moves to), got {points!r}")
            options["points"] = {a: [float(p) for p in v] for a, v in points.items()}
        return options

    def per_axis(self, t: Mapping[str, Any], key: str, positive: bool) -> dict[str, float]:
        """A table of axis = number."""
        table = t[key]
        if not isinstance(table, dict):
            raise self.error(f"reference.{key}", f"expected a table of axis = number, got "
                             f"{table!r}")
        return {axis: self.number(table, f"reference.{key}", axis, None, positive)
                for axis in table}
