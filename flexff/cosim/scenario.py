"""The resolved scenario: a checked RunConfig turned into what the master runs, once, for run,
collection, bench and evaluation alike.

resolve() samples every source signal once (the reference, constants, CSV series), builds the
built-in FMUs (through fmu.build's cache: a run rebuilds only what changed; a learned
feedforward in the precomputed mode is built for the run's own reference), reads every FMU's
model description, and wires them (cosim.wiring). Wiring problems become ConfigErrors naming
`table.key`, raised before any FMU is loaded.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from flexff.cosim.builtins import OptionError, registered
from flexff.cosim.config import checked
from flexff.cosim.config_error import ConfigError
from flexff.cosim.csv_text import TIME, read_time_table
from flexff.cosim.machine import check_signals
from flexff.cosim.master import Master, ResolvedFmu
from flexff.cosim.references import Sampled, build_reference
from flexff.cosim.schema import FmuConfig, RunConfig, SourceConfig, point_time
from flexff.cosim.wiring import Link, Port, WiringError, wire
from flexff.fmu.errors import InputError
from flexff.fmu.importer import FmuError, read_fmu

if TYPE_CHECKING:
    from flexff.fmu.system import System


@dataclass(frozen=True, eq=False)
class Scenario:
    """Everything a run needs, resolved: FMU files in order, wiring, sampled sources."""

    config: RunConfig
    fmus: tuple[ResolvedFmu, ...]
    links: tuple[Link, ...]
    sources: Mapping[str, np.ndarray | float]

    @property
    def step(self) -> float:
        return self.config.step

    @property
    def steps(self) -> int:
        return self.config.steps

    def master(self, log: Callable[[str], None] | None = None) -> Master:
        """The FMUs loaded and wired, ready to run (a context manager); `log` takes their
        messages (Master)."""
        return Master(self.fmus, list(self.sources), self.step, self.links,
                      self.config.algorithm, self.config.start, self.config.step_timeout, log)

    def reference(self) -> dict[str, np.ndarray]:
        """The sampled reference signals (empty without a [reference])."""
        reference = sampled_reference(self.config)
        return {} if reference is None else {n: np.asarray(self.sources[n])
                                             for n in reference.signals()}


def resolve(config: RunConfig, folder: str | Path) -> Scenario:
    """Build the built-in FMUs into `folder`, sample the sources, wire everything; a
    configuration the parser did not make is checked first (cosim.config.checked)."""
    config = checked(config)
    folder = Path(folder)
    sources = source_signals(config)
    fmus, ports = [], []
    for f in config.fmus:
        path = _fmu_file(f, config, sources, folder)
        try:
            info = read_fmu(path)
        except FmuError as error:
            raise ConfigError(config.origin, f"fmu.{f.name}", str(error)) from None
        tolerance = f.tolerance if f.tolerance is not None else info.default_tolerance
        fmus.append(ResolvedFmu(f.name, path, _start_values(f), info, tolerance, f.isolate,
                                f.solver, f.allow_nonfinite, f.sandbox, f.scheduled))
        ports.append(Port(f.name, info, f.unconnected,
                          frozenset(n for n in f.parameters if n in info.inputs),
                          f.feedthrough))
    try:
        links = wire(ports, list(sources), config.connections, config.algorithm)
    except WiringError as error:
        raise ConfigError(config.origin, error.key, error.message) from None
    if config.machine is not None:
        check_signals(config.machine, [*sources, *(f"{p.name}.{n}" for p in ports
                                                   for n in p.info.outputs)],
                      [f"{p.name}.{n}" for p in ports for n in p.info.inputs], config.origin)
    return Scenario(config, tuple(fmus), tuple(links), sources)


def source_signals(config: RunConfig) -> dict[str, np.ndarray | float]:
    """Every external signal of the run, sampled at points 0 .. steps."""
    out: dict[str, np.ndarray | float] = dict(reference_signals(config))
    for k, source in enumerate(config.sources):
        values = (dict(source.values) if source.kind == "constant" else
                  _csv_series(source, config, f"source[{k}].path"))
        for name, value in values.items():
            if name in out:
                raise ConfigError(config.origin, f"source[{k}]",
                                  f"source signal {name!r} is given twice")
            out[name] = value
    return out


def sampled_reference(config: RunConfig) -> Sampled | None:
    """The run's [reference] sampled every step from t = 0 (None without one)."""
    if config.reference is None:
        return None
    return build_reference(config.reference.kind, config.reference.options, config.step,
                           config.machine)


def reference_signals(config: RunConfig) -> dict[str, np.ndarray]:
    """The run's reference signals at points 0 .. steps (none without a [reference]): the
    reference plays from the run's start."""
    reference = sampled_reference(config)
    return {} if reference is None else reference_samples(reference, config.steps)


def reference_samples(reference: Sampled, steps: int) -> dict[str, np.ndarray]:
    """The reference signals at points 0 .. steps: cut (views of the sampled reference, no
    copy), or held at rest after its end."""
    signals = reference.signals()
    n = min(steps + 1, reference.t.size)
    if n == steps + 1:
        return {name: _read_only(values[:n]) for name, values in signals.items()}
    out = {}
    for name, values in signals.items():
        column = np.empty(steps + 1)
        column[:n] = values[:n]
        column[n:] = values[n - 1] if name in reference.positions else 0.0
        out[name] = column
    return out


def _read_only(view: np.ndarray) -> np.ndarray:
    """A view that no consumer may change (it is the cached sampled reference's)."""
    view.flags.writeable = False
    return view


def _csv_series(source: SourceConfig, config: RunConfig, key: str) -> dict[str, np.ndarray]:
    """The columns of a CSV source (cosim.csv_text's time table, in the run's time), linearly
    interpolated onto the run's points and held after the table's end."""
    if source.path is None:
        raise ConfigError(config.origin, key, "a CSV source needs a path")
    try:
        table = read_time_table(source.path)
    except InputError as error:
        raise ConfigError(config.origin, key, str(error)) from None
    names = [n for n in table.columns if n != TIME]
    if not names:
        raise ConfigError(config.origin, key, f"{source.path}: no signal column beside time")
    for name in names:
        if "." in name or not name:
            raise ConfigError(config.origin, key, (
                f"{source.path}: column {name!r}: a source signal's name is plain (no dot); "
                f"connect it with a [[connection]]"))
    grid = point_time(config.start, config.step, np.arange(config.steps + 1))
    return {name: np.interp(grid, table.time, table.columns[name]) for name in names}


def _start_values(f: FmuConfig) -> dict[str, Any]:
    """The FMU's parameters, and the options of a built-in that are start values too."""
    values = dict(f.parameters)
    if f.builtin is not None:
        options = f.options
        values |= {k: options[k] for k in registered()[f.builtin].start_options if k in options}
    return values


def _fmu_file(f: FmuConfig, config: RunConfig, sources: Mapping[str, Any], folder: Path
              ) -> Path:
    """The FMU file of `f`: its path, or the built-in built through the cache."""
    if f.path is not None:
        return f.path
    from flexff.fmu.build import build_fmu  # the builder and CasADi: built-in FMUs only

    return build_fmu(_builtin_system(f, config, sources), folder / f"{f.name}.fmu", f.fmi)


def _builtin_system(f: FmuConfig, config: RunConfig, sources: Mapping[str, Any]) -> System:
    """The System of a built-in (cosim.builtins); its factory's InputError becomes a
    ConfigError naming `fmu.NAME` (`fmu.NAME.option` for an OptionError)."""
    assert f.builtin is not None
    builtin = registered()[f.builtin]
    try:
        return builtin.system(f.options, config.step, sources)
    except OptionError as error:
        raise ConfigError(config.origin, f"fmu.{f.name}.{error.option}", str(error)) from None
    except InputError as error:
        raise ConfigError(config.origin, f"fmu.{f.name}", str(error)) from None
