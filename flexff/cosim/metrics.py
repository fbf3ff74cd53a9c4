"""Tracking metrics of a run: per axis e = reference - position.

  e2   = sqrt(sum_k e_k^2 * dt) / T   the thesis's "average 2-norm" [unit/sqrt(s)]
  einf = max_k |e_k|                  [unit]
  rms  = sqrt(mean_k e_k^2)           [unit]

over every communication point k = 0 .. N of a run of length T = N dt. The axes are a machine
description's (`machine_axes`: `<axis>_ref` against the true position where the loop gives
one, else the measured one, each an expression of recorded signals) or named ones
(`named_axes`: `<axis>_ref` against the recorded `<axis>`). A streamed run sums the squares
and keeps the largest error chunk by chunk (Tracking), so it never holds the whole record.

An axis's e2 over a loop whose measurement adds a noise floor (an e2 that no feedforward
removes, learning.ilc) splits into the floor and the feedforward's own share,
sqrt(e2^2 - floor^2) (`own_share`), the two errors being uncorrelated.
"""

from __future__ import annotations

import math
from collections.abc import Collection, Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from flexff.cosim.machine import Machine
from flexff.cosim.recording import Recording, signal_name
from flexff.fmu.expressions import Expression, evaluate, parse_expression


@dataclass(frozen=True)
class TrackedAxis:
    """One axis's error e = reference - position, each an expression of recorded signals
    (a short name `x` stands for the one recorded `fmu.x`, as signal_name finds it), in
    `unit`; a loop's axis also names its feedforward input and commanded effort (the
    plots' efforts, in `effort_unit`)."""

    name: str
    reference: Expression
    position: Expression
    unit: str = ""
    feedforward: str | None = None
    effort: str | None = None
    effort_unit: str = ""

    def columns(self, names: Collection[str]) -> dict[str, str]:
        """Each name the expressions read -> its recorded column (KeyError if missing)."""
        return {n: signal_name(names, n) for n in self.reference.names | self.position.names}

    def values(self, columns: Mapping[str, np.ndarray], found: Mapping[str, str]
               ) -> tuple[np.ndarray, np.ndarray]:
        """The reference and the position, from the recorded `columns` (`found`: columns)."""
        values = {n: columns[c] for n, c in found.items()}
        key = f"axis {self.name}"
        return (np.asarray(evaluate(self.reference, values, key), dtype=float),
                np.asarray(evaluate(self.position, values, key), dtype=float))

    def error(self, columns: Mapping[str, np.ndarray], found: Mapping[str, str]) -> np.ndarray:
        reference, position = self.values(columns, found)
        error: np.ndarray = reference - position
        return error


def named_axes(names: Sequence[str]) -> tuple[TrackedAxis, ...]:
    """Axes by name alone: `<axis>_ref` against the recorded `<axis>`."""
    return tuple(TrackedAxis(a, parse_expression(f"{a}_ref", a), parse_expression(a, a))
                 for a in names)


def machine_axes(machine: Machine) -> tuple[TrackedAxis, ...]:
    """The tracked axes of a machine description."""
    return tuple(TrackedAxis(a.name, parse_expression(a.reference, a.name), a.evaluated,
                             a.unit, a.loop_feedforward, a.loop_effort, a.effort_unit)
                 for a in machine.axes)


def error_norms(error: np.ndarray, step: float) -> dict[str, float]:
    """e2, einf and rms of one axis's error samples (spaced `step` seconds apart)."""
    error = np.asarray(error, dtype=float)
    if error.size < 2:
        raise ValueError("the error needs at least two samples")
    duration = (error.size - 1) * step
    return {"e2": math.sqrt(float(np.sum(error**2)) * step) / duration,
            "einf": float(np.max(np.abs(error))),
            "rms": math.sqrt(float(np.mean(error**2)))}


def own_share(e2: float, floor: float) -> float:
    """The part of an axis's `e2` that is not the noise `floor`'s: sqrt(e2^2 - floor^2); 0.0
    where e2 <= floor (the error is the floor's alone: "at the floor"), never NaN."""
    if not (math.isfinite(e2) and math.isfinite(floor)) or e2 < 0 or floor < 0:
        raise ValueError(f"e2 {e2} and noise floor {floor} must be finite and not negative")
    return math.sqrt((e2 - floor) * (e2 + floor)) if e2 > floor else 0.0


def tracking_metrics(recording: Recording, axes: Sequence[TrackedAxis]
                     ) -> dict[str, dict[str, float]]:
    """{axis: {e2, einf, rms}} from the recorded references and positions."""
    return {a.name: error_norms(a.error(recording.signals, a.columns(recording.signals)),
                                recording.step) for a in axes}


class Tracking:
    """The tracking metrics of a run fed chunk by chunk (`add`): per axis the sum of e^2, the
    largest |e| and the count, over the recorded columns `names`."""

    def __init__(self, names: Sequence[str], step: float, axes: Sequence[TrackedAxis]) -> None:
        self.step = step
        self.axes = {a.name: (a, a.columns(names)) for a in axes}
        self.squares = dict.fromkeys(self.axes, 0.0)
        self.largest = dict.fromkeys(self.axes, 0.0)
        self.count = 0

    @staticmethod
    def tracks(names: Sequence[str], axes: Sequence[TrackedAxis]) -> bool:
        """Whether `names` holds what every axis's reference and position read."""
        try:
            for a in axes:
                a.columns(names)
        except KeyError:
            return False
        return True

    def add(self, columns: Mapping[str, np.ndarray]) -> None:
        for name, (axis, found) in self.axes.items():
            error = axis.error(columns, found)
            self.squares[name] += float(np.sum(error**2))
            self.largest[name] = max(self.largest[name], float(np.max(np.abs(error)))
                                     if error.size else 0.0)
        self.count += len(next(iter(columns.values()))) if columns else 0

    def metrics(self) -> dict[str, dict[str, float]]:
        """{axis: {e2, einf, rms}} (error_norms' definitions)."""
        if self.count < 2:
            raise ValueError("the error needs at least two samples")
        duration = (self.count - 1) * self.step
        return {a: {"e2": math.sqrt(self.squares[a] * self.step) / duration,
                    "einf": self.largest[a], "rms": math.sqrt(self.squares[a] / self.count)}
                for a in self.axes}


def run_metrics(recording: Recording, axes: Sequence[TrackedAxis]) -> dict[str, Any]:
    """The content of metrics.json of a recording held in memory (summary_metrics)."""
    tracked = Tracking.tracks(tuple(recording.signals), axes)
    return summary_metrics(tracking_metrics(recording, axes) if tracked else {},
                           float(recording.time[-1] - recording.time[0]), recording.wall_s,
                           recording.timing)


def metrics_axes(metrics: Mapping[str, Any]) -> list[str]:
    """The axes a run's (or a trial's) metrics hold: its entries with an e2."""
    return [a for a, m in metrics.items() if isinstance(m, Mapping) and "e2" in m]


SUMMARY = ("wall_s", "real_time_factor", "realtime")  # summary_metrics' entries beside the axes


def summary_metrics(tracking: Mapping[str, Any], duration: float, wall_s: float,
                    timing: Any) -> dict[str, Any]:
    """The content of metrics.json: tracking metrics (where the run records a reference and a
    true position), wall time of the loop, its real-time factor (simulated seconds per
    wall-clock second) and the step timing (cosim.timing: the `realtime` table)."""
    metrics = {**tracking, "wall_s": wall_s,
               "real_time_factor": duration / wall_s if wall_s > 0 else None}
    if timing is not None:
        metrics["realtime"] = timing.table(wall_s)
    return metrics
