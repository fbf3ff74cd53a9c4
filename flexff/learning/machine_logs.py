"""`flexff data import --machine`: logs of any machine (CSV or MATLAB v4-v7.3 .mat) as a
machine dataset (learning.machine_dataset), read through the description's log map.

Each file is one trajectory, named after its file. The map (`[machine.log]`, LogMap) names the
time column and gives a dataset signal as an expression of the log's columns and scalars
(`x_effort = "gain * vir"`); a signal it leaves out is the column of its own name. Every
measured position and effort must be there, and every column a mapped expression reads.
Reading, checks, rate, resampling and splits are learning.log_files's, as for the
manipulator's logs: an error names the file, the column (and the key of the expression that
read it) and the row. What a log lacks is derived and marked so in its entry's `derived`: an
axis's reference position is its measured position, a reference derivative the cubic
Savitzky-Golay derivative of the reference (log_files.reference_derivative). The folder is
written whole or not at all.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from flexff.cosim.csv_text import TIME
from flexff.cosim.machine import Machine
from flexff.fmu.expressions import Expression, evaluate, parse_expression
from flexff.learning.log_files import (
    Log,
    LogError,
    check_length,
    check_log,
    check_output,
    common_rate,
    log_entry,
    read_log,
    reference_derivative,
    resampled,
    split_by_file,
)
from flexff.learning.machine_dataset import MachineDataset, write_machine_dataset

SOURCE = "flexff data import --machine"


@dataclass(frozen=True)
class _Source:
    """Where a dataset signal comes from in a log: an expression, the key that gave it (None:
    the column of the signal's own name) and whether a log must hold it."""

    signal: str
    expression: Expression
    key: str | None
    required: bool


def import_machine_logs(files: Sequence[str | Path], out: str | Path, machine: Machine,
                        rate_hz: float | None = None, test: Sequence[str] | None = None
                        ) -> MachineDataset:
    """Import the log `files` of `machine` into the new dataset folder `out` at `rate_hz`
    (default: the logs' own), the logs named in `test` (default: the last one) forming the
    test split; return the dataset. Raises LogError (an InputError) naming file, column, row."""
    out = Path(out)
    check_output(out, rate_hz)
    paths = [Path(f) for f in files]
    splits = split_by_file(paths, test)
    sources = _sources(machine)
    logs = [_mapped(check_log(_read(p, machine, sources)), machine, sources) for p in paths]
    rate_hz = rate_hz or common_rate(logs)
    trajectories, details = {}, {}
    for log in logs:
        signals, how = resampled(log, rate_hz)
        check_length(log, len(signals[TIME]), rate_hz)
        derived = _derive(machine, signals, rate_hz)
        read = {s.signal: s.expression.text for s in sources if s.signal in log.columns}
        trajectories[log.path.stem] = signals
        details[log.path.stem] = {"derived": derived, "log": {**log_entry(log, how),
                                                               "signals": read}}
    return write_machine_dataset(out, machine, trajectories, rate_hz, splits, SOURCE, details)


def _sources(machine: Machine) -> list[_Source]:
    """Every dataset signal's source: its mapped expression, else its own column."""
    measured = {n for a in machine.axes for n in (a.measured_signal, a.effort_signal)}
    sources = []
    for signal in machine.signals:
        mapped = machine.log.columns.get(signal)
        if mapped is not None:
            sources.append(_Source(signal, mapped, f"machine.log.columns.{signal}", True))
        else:
            own = parse_expression(signal, signal)
            sources.append(_Source(signal, own, None, signal in measured))
    return sources


def _read(path: Path, machine: Machine, sources: list[_Source]) -> Log:
    """The log's time and every column a source reads, each required one there."""
    scalars = set(machine.log.scalars)
    wanted = sorted({n for s in sources for n in s.expression.names - scalars})
    log = read_log(path, (), wanted, machine.log.time)
    for source in sources:
        missing = sorted(source.expression.names - scalars - set(log.columns))
        if missing and source.required:
            if source.key is None:
                raise LogError(f"{path}: missing column {missing[0]}: a log holds each "
                               f"measured position and effort as the column of its name, or "
                               f"[machine.log.columns] maps it ({source.signal} = "
                               f"\"expression of the log's columns\")")
            raise LogError(f"{path}: missing column {missing[0]}, which {source.key} = "
                           f"{source.expression.text!r} reads")
    return log


def _mapped(log: Log, machine: Machine, sources: list[_Source]) -> Log:
    """The log as dataset signals: each source's expression evaluated on its columns."""
    scope: Mapping[str, Any] = {**log.columns, **machine.log.scalars}
    signals = {TIME: log.columns[TIME]}
    for source in sources:
        if not source.expression.names <= set(scope):
            continue  # an optional reference the log does not hold: derived
        with np.errstate(all="ignore"):
            value = evaluate(source.expression, scope, source.key or source.signal)
        values = np.broadcast_to(np.asarray(value, dtype=np.float64), log.columns[TIME].shape)
        bad = np.flatnonzero(~np.isfinite(values))
        if bad.size:  # a mapped expression's: a column's own values are checked when read
            raise LogError(f"{log.path}: {source.key} = {source.expression.text!r}, "
                           f"{log.row(int(bad[0]))}: NaN or Inf")
        signals[source.signal] = np.array(values)
    return Log(log.path, log.format, signals, log.row)


def _derive(machine: Machine, signals: dict[str, np.ndarray], rate_hz: float) -> dict[str, str]:
    """Add the references the log lacks to `signals`; return how each was derived."""
    derived = {}
    for axis in machine.axes:
        reference = axis.reference
        if reference not in signals:
            signals[reference] = signals[axis.measured_signal]
            derived[reference] = (f"the measured position {axis.measured_signal} (the log has "
                                  f"no {reference})")
        of = f"{'the derived ' if reference in derived else ''}{reference}"
        for order, name in enumerate(axis.derivatives, start=1):
            if name not in signals:
                signals[name], derived[name] = reference_derivative(signals[reference], rate_hz,
                                                                    order, of)
    return derived
