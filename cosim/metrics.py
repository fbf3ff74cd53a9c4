"""Tracking metrics of a run: per axis e = reference - true position.

  e2   = sqrt(sum_k e_k^2 * dt) / T   the thesis's "average 2-norm" [m/sqrt(s)]
  einf = max_k |e_k|                  [m]
  rms  = sqrt(mean_k e_k^2)           [m]

over every communication point k = 0 .. N of a run of length T = N dt. The true position is
the plant's `x`, `y` outputs, which only evaluation ever sees.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from flexff.cosim.recording import Recording

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


def run_metrics(recording: Recording) -> dict[str, Any]:
    """The content of metrics.json: tracking metrics (where the run records a reference and a
    true position), wall time of the loop, its real-time factor (simulated seconds per
    wall-clock second) and the step timing (cosim.timing: the `realtime` table)."""
    duration = float(recording.time[-1] - recording.time[0])
    tracked = all(n in recording for axis in AXES for n in (axis, f"{axis}_ref"))
    metrics = {**(tracking_metrics(recording) if tracked else {}), "wall_s": recording.wall_s,
               "real_time_factor": duration / recording.wall_s if recording.wall_s > 0
               else None}
    if recording.timing is not None:
        metrics["realtime"] = recording.timing.table(recording.wall_s)
    return metrics
