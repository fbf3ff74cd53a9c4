"""Step timing of a run, as Simulink Real-Time reports it: the task execution time (TET) of
every step, each FMU's share of it, and, when the run is paced to the wall clock, how late each
step started and which steps overran their period.

TET of step k: from the first FMI call of communication point k to the end of the step to
t_{k+1} (cosim/c/engine.c). Lateness: the step's start after its due time on the absolute
schedule start + k * period (period = step / real-time factor). An overrun: a step whose TET
plus lateness passes its period, so that it ends after the next step was due.

A run that streams its record (cosim.run) keeps no per-step array either: its TET goes into
a Histogram per chunk (StreamedTiming), whose percentiles are within RESOLUTION of the exact
ones (the maximum is exact), so that memory stays flat in the run's length.

Slower tasks, as Simulink Real-Time's multitasking runs them: a flexff network in its own task
(fmu/c/wrapper_task.c) reports its call times and its rate-transition overruns (a result not
ready at the step it is due), which --max-overruns counts with the steps' own.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from typing import Any

import numpy as np

from flexff.fmu.errors import InputError

US = 1e6
PERCENTILES = {"p50": 50.0, "p99": 99.0, "p99.9": 99.9}


class OverrunError(RuntimeError):
    """A paced run stopped by --max-overruns (its results up to there were written)."""


@dataclass(frozen=True)
class Pacing:
    """How a run is paced: `rt_factor` simulated seconds per wall-clock second; stop after
    `max_overruns` overruns (0: never) that come after the first `grace` seconds."""

    rt_factor: float = 1.0
    max_overruns: int = 0
    grace: float = 0.0

    def __post_init__(self) -> None:
        if not self.rt_factor > 0:
            raise InputError(f"the real-time factor must be positive, got {self.rt_factor}")
        if self.max_overruns < 0 or self.grace < 0:
            raise InputError("max_overruns and grace must not be negative")


@dataclass(frozen=True, eq=False)
class StepTiming:
    """What the engine measured, one value per step made."""

    step: float
    names: tuple[str, ...]  # the FMUs, in stepping order
    tet: np.ndarray  # [s]
    fmu_tet: np.ndarray  # steps x FMUs [s]
    lateness: np.ndarray  # [s], zero when not paced
    pacing: Pacing | None
    overruns: int
    task_overruns: int  # slower tasks' results not ready when due (counted when paced)
    first_overruns: tuple[int, ...]  # step indices of the first overruns
    stopped_at: int | None  # the step at which max_overruns stopped the run
    process: Any = None  # cosim.realtime.ProcessReport of a paced run
    # FMU -> its network's call times (calls; p50, p99, max in us; period_steps; overruns of
    # its own task), for FMUs that embed one
    network_calls: dict[str, dict[str, float]] = dataclasses.field(default_factory=dict)

    @property
    def period(self) -> float:
        """Wall-clock seconds per step."""
        return self.step / (self.pacing.rt_factor if self.pacing else 1.0)

    def table(self, wall_s: float) -> dict[str, Any]:
        """The `realtime` table of metrics.json (times in microseconds)."""
        simulated = self.tet.size * self.step
        table: dict[str, Any] = {
            "period_us": self.period * US,
            "target_real_time_factor": self.pacing.rt_factor if self.pacing else None,
            "achieved_real_time_factor": simulated / wall_s if wall_s > 0 else None,
            "steps": int(self.tet.size),
            "tet_us": _stats(self.tet),
            "tet_us_per_fmu": {n: _stats(self.fmu_tet[:, i]) for i, n in enumerate(self.names)},
            "tet_over_period_p99": float(np.percentile(self.tet, 99) / self.period)
            if self.tet.size else None,
            "network_call_us": self.network_calls,
            "tasks": self.tasks(),
        }
        if self.pacing is not None:
            table.update({
                "lateness_us": {"p99": _percentile(self.lateness, 99.0),
                                "max": float(self.lateness.max() * US)
                                if self.lateness.size else 0.0},
                "overruns": self.overruns,
                "rate_transition_overruns": self.task_overruns,
                "first_overruns_s": [k * self.step for k in self.first_overruns],
                "max_overruns": self.pacing.max_overruns, "grace_s": self.pacing.grace,
                "stopped_at_s": None if self.stopped_at is None
                else self.stopped_at * self.step,
                "process": dataclasses.asdict(self.process) if self.process else None})
        return table

    def tasks(self) -> dict[str, dict[str, Any]]:
        """Per task, as Simulink Real-Time lists them: the base task (every step: its TET and
        overruns) and each network in its own task (`FMU.network`: its period, the time per
        call and its rate-transition overruns, which its FMU counts paced or not; the base task's
        overruns only mean something when paced)."""
        tasks: dict[str, dict[str, Any]] = {"base": {
            "period_us": self.period * US, "tet_us": _stats(self.tet),
            "overruns": self.overruns if self.pacing else None}}
        for name, calls in self.network_calls.items():
            if "overruns" not in calls:
                continue  # the network runs inside the base task's step
            tasks[f"{name}.network"] = {
                "period_us": calls["period_steps"] * self.period * US,
                "calls": calls["calls"],
                "tet_us": {k: calls[k] for k in ("p50", "p99", "max")},
                "overruns": int(calls["overruns"])}
        return tasks

    def stop_message(self) -> str:
        """Why max_overruns stopped the run: when, and how late its last step ended."""
        k, pacing = self.stopped_at, self.pacing
        if k is None or pacing is None:
            raise ValueError("the run was not stopped by max_overruns")
        over = (self.tet[k] + self.lateness[k] - self.period) * US
        if over <= 0:  # the step kept its period: a slower task's result was late
            return (f"stopped after {self.overruns} overruns and {self.task_overruns} "
                    f"rate-transition overruns (--max-overruns {pacing.max_overruns}): at "
                    f"t = {k * self.step:.6g} s a network's task had not finished when its "
                    f"result was due")
        return (f"stopped after {self.overruns} overruns (--max-overruns "
                f"{pacing.max_overruns}): the step from t = {k * self.step:.6g} s took "
                f"{self.tet[k] * US:.1f} us and started {self.lateness[k] * US:.1f} us late, "
                f"{over:.1f} us past its {self.period * US:.1f} us period")


def _percentile(values: np.ndarray, q: float) -> float:
    return float(np.percentile(values, q) * US) if values.size else 0.0


def _stats(values: np.ndarray) -> dict[str, float]:
    """p50, p99, p99.9 and max in microseconds."""
    out = {name: _percentile(values, q) for name, q in PERCENTILES.items()}
    out["max"] = float(values.max() * US) if values.size else 0.0
    return out


BINS_PER_DECADE = 400
EDGES = np.geomspace(1e-9, 1e3, 12 * BINS_PER_DECADE + 1)  # [s], 1 ns .. 1000 s
RESOLUTION = float(EDGES[1] / EDGES[0] - 1)  # a bin's relative width (0.58 %)


class Histogram:
    """Durations [s] counted in logarithmic bins (EDGES): percentiles in constant memory."""

    def __init__(self) -> None:
        self.counts = np.zeros(EDGES.size + 1, dtype=np.int64)
        self.size, self.max = 0, 0.0

    def add(self, values: np.ndarray) -> None:
        if values.size:
            # bin i holds EDGES[i - 1] < v <= EDGES[i]: found by the logarithm, not a search
            with np.errstate(divide="ignore"):
                bins = np.ceil(np.log10(values / EDGES[0]) * BINS_PER_DECADE)
            index = np.clip(np.nan_to_num(bins, nan=0.0, neginf=0.0), 0, EDGES.size)
            self.counts += np.bincount(index.astype(np.int64), minlength=EDGES.size + 1)
            self.size += values.size
            self.max = max(self.max, float(values.max()))

    def percentile(self, q: float) -> float:
        """The q-th percentile [s] (numpy's rank q/100 * (size - 1)): the geometric centre of
        the bin that holds it, at most the maximum."""
        if not self.size:
            return 0.0
        rank = q / 100.0 * (self.size - 1)
        i = int(np.searchsorted(np.cumsum(self.counts), rank, side="right"))
        low, high = (EDGES[i - 1] if i > 0 else 0.0), (EDGES[i] if i < EDGES.size else self.max)
        return min(float(np.sqrt(low * high)) if low > 0 else float(high), self.max)


def _histogram_stats(h: Histogram) -> dict[str, float]:
    out = {name: h.percentile(q) * US for name, q in PERCENTILES.items()}
    out["max"] = h.max * US
    return out


@dataclass(frozen=True, eq=False)
class StreamedTiming:
    """What the engine measured in an unpaced run whose record was streamed: each step's TET
    and each FMU's share, counted in histograms (the `realtime` table of StepTiming, with
    percentiles within RESOLUTION)."""

    step: float
    names: tuple[str, ...]
    tet: Histogram
    fmu_tet: tuple[Histogram, ...]
    network_calls: dict[str, dict[str, float]] = dataclasses.field(default_factory=dict)
    pacing: None = None
    stopped_at: None = None

    @property
    def period(self) -> float:
        return self.step

    def add(self, tet: np.ndarray, fmu_tet: np.ndarray) -> None:
        """Count the TET of some steps (and the FMUs' shares, steps x FMUs)."""
        self.tet.add(tet)
        for i, h in enumerate(self.fmu_tet):
            h.add(fmu_tet[:, i])

    def table(self, wall_s: float) -> dict[str, Any]:
        """The `realtime` table of metrics.json, as StepTiming.table gives it unpaced."""
        return {
            "period_us": self.period * US, "target_real_time_factor": None,
            "achieved_real_time_factor": self.tet.size * self.step / wall_s
            if wall_s > 0 else None,
            "steps": self.tet.size,
            "tet_us": _histogram_stats(self.tet),
            "tet_us_per_fmu": {n: _histogram_stats(h) for n, h in zip(self.names, self.fmu_tet)},
            "tet_over_period_p99": self.tet.percentile(99.0) / self.period
            if self.tet.size else None,
            "network_call_us": self.network_calls,
            "percentile_resolution": RESOLUTION,
        }
