"""Tracking metrics of a run: per axis e = reference - true position.

  e2   = sqrt(sum_k e_k^2 * dt) / T   the thesis's "average 2-norm" [m/sqrt(s)]
  einf = max_k |e_k|                  [m]
  rms  = sqrt(mean_k e_k^2)           [m]

over every communication point k = 0 .. N of a run of length T = N dt. The true position is
the plant's `x`, `y` outputs, which only evaluation ever sees. A streamed run sums the squares
and keeps the largest error chunk by chunk (Tracking), so it never holds the whole record.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

from flexff.cosim.recording import Recording, signal_name

AXES = ("x", "y")


def error_norms(error: np.ndarray, step: float) -> dict[str, float]:
    """e2, einf and rms of one axis's error samples (spaced `step` seconds apart)."""
    error = np.asarray(error, dtype=float)
    if error.size < 2:
        raise ValueError("the error needs at least two samples")
    duration = (error.size - 1) * step
    return {"e2": math.sqrt(float(np.sum(error**2)) * step) / duration,
            "einf": float(np.max(np.abs(error))),
            "rms": math.sqrt(float(np.mean(error**2)))}


def tracking_metrics(recording: Recording) -> dict[str, dict[str, float]]:
    """{"x": {...}, "y": {...}} from the recorded reference and true position."""
    return {axis: error_norms(recording[f"{axis}_ref"] - recording[axis], recording.step)
            for axis in AXES}


class Tracking:
    """The tracking metrics of a run fed chunk by chunk (`add`): per axis the sum of e^2, the
    largest |e| and the count, over the recorded columns `names` (reference and true position
    found by their short names)."""

    def __init__(self, names: Sequence[str], step: float) -> None:
        self.step = step
        self.columns = {a: (signal_name(names, f"{a}_ref"), signal_name(names, a)) for a in AXES}
        self.squares = dict.fromkeys(AXES, 0.0)
        self.largest = dict.fromkeys(AXES, 0.0)
        self.count = 0

    @staticmethod
    def tracks(names: Sequence[str]) -> bool:
        """Whether `names` holds a reference and a true position for both axes."""
        try:
            for a in AXES:
                signal_name(names, a), signal_name(names, f"{a}_ref")
        except KeyError:
            return False
        return True

    def add(self, columns: Mapping[str, np.ndarray]) -> None:
        for axis, (ref, true) in self.columns.items():
            error = columns[ref] - columns[true]
            self.squares[axis] += float(np.sum(error**2))
            self.largest[axis] = max(self.largest[axis], float(np.max(np.abs(error)))
                                     if error.size else 0.0)
        self.count += len(next(iter(columns.values()))) if columns else 0

    def metrics(self) -> dict[str, dict[str, float]]:
        """{"x": {e2, einf, rms}, "y": {...}} (error_norms' definitions)."""
        if self.count < 2:
            raise ValueError("the error needs at least two samples")
        duration = (self.count - 1) * self.step
        return {a: {"e2": math.sqrt(self.squares[a] * self.step) / duration,
                    "einf": self.largest[a], "rms": math.sqrt(self.squares[a] / self.count)}
                for a in AXES}


def run_metrics(recording: Recording) -> dict[str, Any]:
    """The content of metrics.json of a recording held in memory (summary_metrics)."""
    tracked = all(n in recording for axis in AXES for n in (axis, f"{axis}_ref"))
    return summary_metrics(tracking_metrics(recording) if tracked else {},
                           float(recording.time[-1] - recording.time[0]), recording.wall_s,
                           recording.timing)


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
