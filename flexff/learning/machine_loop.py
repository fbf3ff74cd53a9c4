"""Any machine's closed loop: a checked run configuration with a [machine] description (the
user's plant and controller FMUs, flexff's or their own), put on a table of references, its
feedforward inputs fed from a table (or zero), and a dataset's signals read from its record.

A loop is changed with dataclasses.replace and checked again as a file is (cosim.config.
checked). The references come as a CSV time table with the machine's reference signals
(`<axis>_ref` and its derivatives, learning.excitation writes them); the loop's own sources of
those signals and its [reference] of them (an axis kind, cosim.axis_references) go. Each
axis's feedforward input is fed by a connection from the source signal `<axis>_ff`: a column
of a CSV table (`feedforward`, as ILC writes), else a constant zero (PID alone); whatever fed
it before goes.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import replace
from pathlib import Path

import numpy as np

from flexff.cosim.config import checked
from flexff.cosim.config_error import ConfigError
from flexff.cosim.csv_text import TIME, read_time_table
from flexff.cosim.machine import Machine
from flexff.cosim.recording import Recording
from flexff.cosim.scenario import sampled_reference
from flexff.cosim.schema import ConnectionConfig, FmuConfig, RunConfig, SourceConfig
from flexff.fmu.expressions import evaluate


def loop_machine(loop: RunConfig) -> Machine:
    """The loop's machine description; a ConfigError saying what to add where it has none."""
    if loop.machine is None:
        raise ConfigError(loop.origin, "machine", "the loop has no machine description: add a "
                          "[machine] table (its axes' measured position, feedforward input and "
                          "effort) or machine = \"FILE.toml\"")
    return loop.machine


def feedforward_signal(axis_name: str) -> str:
    """The source signal that feeds an axis's feedforward input."""
    return f"{axis_name}_ff"


def on_references(loop: RunConfig, table: Path, stop: float, name: str,
                  feedforward: Path | None = None) -> RunConfig:
    """`loop` run for `stop` seconds on the references of the CSV time `table`, with each
    axis's feedforward from the CSV table `feedforward` (columns `<axis>_ff`) or zero."""
    machine = loop_machine(loop)
    given = set(machine.reference_signals)
    own = sampled_reference(loop)  # kept where it gives none of the table's signals
    reference = loop.reference if own is not None and given.isdisjoint(own.signals()) \
        else None
    sources = (*_other_sources(loop, given), SourceConfig("csv", path=Path(table)))
    return with_feedforward(replace(loop, name=name, start=0.0, stop=stop, reference=reference,
                                    sources=sources), feedforward)


def with_feedforward(loop: RunConfig, feedforward: Path | None = None) -> RunConfig:
    """`loop` with each axis's feedforward input fed from the CSV table `feedforward`
    (columns `<axis>_ff`), or zero for None; whatever fed those inputs before goes."""
    machine = loop_machine(loop)
    fed = {feedforward_signal(a.name) for a in machine.axes}
    # a source signal named as an input feeds it by name: it goes too
    sources = _other_sources(loop, fed | {a.feedforward.split(".", 1)[1] for a in machine.axes})
    if feedforward is not None:
        sources.append(SourceConfig("csv", path=Path(feedforward)))
    else:
        sources.append(SourceConfig("constant", dict.fromkeys(sorted(fed), 0.0)))
    inputs = {a.feedforward for a in machine.axes}
    connections = (*(c for c in loop.connections if c.to_name not in inputs),
                   *(ConnectionConfig(feedforward_signal(a.name), a.feedforward,
                                      key=f"machine.axis[{k}].feedforward")
                     for k, a in enumerate(machine.axes)))
    return checked(replace(loop, sources=tuple(sources), connections=connections))


def with_start_values(loop: RunConfig, values: Mapping[str, float], key: str) -> RunConfig:
    """`loop` with the start values `values` ("instance.parameter" -> value) over its FMUs'
    own; a ConfigError naming `key`.NAME for an instance the loop lacks."""
    names = {f.name for f in loop.fmus}
    given: dict[str, dict[str, float]] = {}
    for name, value in values.items():
        instance, parameter = name.split(".", 1)
        if instance not in names:
            raise ConfigError(loop.origin, f"{key}.{name}", f"the loop has no FMU {instance!r} "
                              f"(it has {', '.join(sorted(names))})")
        given.setdefault(instance, {})[parameter] = value
    return checked(replace(loop, fmus=tuple(
        replace(f, parameters={**f.parameters, **given[f.name]}) if f.name in given else f
        for f in loop.fmus)))


def with_feedforward_fmu(loop: RunConfig, fmu: Path, name: str = "feedforward") -> RunConfig:
    """`loop` with the FMU `fmu` (inputs: the reference signals, by name; outputs `<axis>_ff`)
    feeding each axis's feedforward input, stepped first; whatever fed those inputs before
    goes."""
    machine = loop_machine(loop)
    fed = {feedforward_signal(a.name) for a in machine.axes}
    inputs = {a.feedforward for a in machine.axes}
    connections = (*(c for c in loop.connections if c.to_name not in inputs),
                   *(ConnectionConfig(f"{name}.{feedforward_signal(a.name)}", a.feedforward,
                                      key=f"machine.axis[{k}].feedforward")
                     for k, a in enumerate(machine.axes)))
    fmus = (FmuConfig(name, path=Path(fmu)), *(f for f in loop.fmus if f.name != name))
    return checked(replace(loop, fmus=fmus, sources=tuple(_other_sources(loop, fed)),
                           connections=connections))


def _other_sources(loop: RunConfig, replaced: set[str]) -> list[SourceConfig]:
    """The loop's sources less the signals that `replaced` names; a CSV table that holds one
    of them beside others is refused (it cannot be cut)."""
    kept = []
    for k, source in enumerate(loop.sources):
        if source.kind == "constant":
            values = {n: v for n, v in source.values.items() if n not in replaced}
            if values:
                kept.append(replace(source, values=values))
            continue
        assert source.path is not None  # the parser's
        columns = set(read_time_table(source.path).columns) - {TIME}
        if columns.isdisjoint(replaced):
            kept.append(source)
        elif not columns <= replaced:
            raise ConfigError(loop.origin, f"source[{k}].path", (
                f"{source.path} gives {', '.join(sorted(columns & replaced))} beside other "
                f"signals; flexff replaces the references and feedforwards: give those in a "
                f"table of their own"))
    return kept


def record_signals(recording: Recording, machine: Machine) -> dict[str, np.ndarray]:
    """A dataset's columns (machine.signals) from a run's record: the references as the loop
    received them, each axis's measured position (its expression) and its effort."""
    columns = {n: recording[n] for n in machine.reference_signals}
    for k, axis in enumerate(machine.axes):
        values: Mapping[str, np.ndarray] = {n: recording[n] for n in axis.measured.names}
        columns[axis.measured_signal] = np.broadcast_to(evaluate(
            axis.measured, values, f"machine.axis[{k}].measured"), recording.time.shape).copy()
        columns[axis.effort_signal] = np.asarray(recording[axis.effort], dtype=float)
    return columns
