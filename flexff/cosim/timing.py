"""Step timing of a run, as Simulink Real-Time reports it: the task execution time (TET) of
every step, each FMU's share of it, and, when the run is paced to the wall clock, how late each
step started and which steps overran their period.

Runs count these in histograms chunk by chunk (StreamedTiming, Histogram) and draw tet.png
from a bounded trace (TetTrace), so memory stays flat in the run's length. A network in its
own task (fmu/c/wrapper_task.c) adds its call times and rate-transition overruns.

Definitions of TET, lateness and overrun: "A run's cost and real time"
(docs/explanation/run-cost.md); the "Real time" tutorial shows them.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from typing import Any, ClassVar, Protocol

import numpy as np

from flexff.cosim.decimate import Envelope
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


class Distribution(Protocol):
    """Durations counted one way or another: how many, the largest, and percentiles."""

    size: int
    max: float  # [s]

    def percentile(self, q: float) -> float:
        """The q-th percentile [s] (numpy's rank q/100 * (size - 1))."""


class Exact:
    """Durations [s] kept one by one: exact percentiles (numpy's)."""

    def __init__(self, values: np.ndarray) -> None:
        self.values, self.size = values, int(values.size)
        self.max = float(values.max()) if values.size else 0.0

    def percentile(self, q: float) -> float:
        return float(np.percentile(self.values, q)) if self.size else 0.0


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


def _stats(values: Distribution) -> dict[str, float]:
    """p50, p99, p99.9 and max in microseconds."""
    out = {name: values.percentile(q) * US for name, q in PERCENTILES.items()}
    out["max"] = values.max * US
    return out


class TetTrace:
    """What tet.png draws of a run of `steps` steps, in bounded memory: per block of steps
    (cosim.decimate.Envelope: about a thousand blocks whatever the run's length) the least and
    the largest TET, TET plus lateness (the largest tells the blocks that overran) and each
    FMU's share, so that every spike stays visible."""

    def __init__(self, steps: int, fmus: int) -> None:
        self.tet, self.late = Envelope(steps), Envelope(steps)
        self.fmu_tet = tuple(Envelope(steps) for _ in range(fmus))

    def add(self, k0: int, tet: np.ndarray, fmu_tet: np.ndarray, lateness: np.ndarray) -> None:
        """Steps k0, k0 + 1, ...: their TET, the FMUs' shares (steps x FMUs), their lateness."""
        self.tet.add(k0, tet)
        self.late.add(k0, tet + lateness)
        for i, envelope in enumerate(self.fmu_tet):
            envelope.add(k0, fmu_tet[:, i])


class _Timing:
    """The tables and the stop message of a run's step timing, from its counted durations
    (_counted: StepTiming's arrays, exact; StreamedTiming's histograms), one code for both."""

    step: float
    names: tuple[str, ...]  # the FMUs, in stepping order
    pacing: Pacing | None
    overruns: int
    task_overruns: int  # slower tasks' results not ready when due (counted when paced)
    first_overruns: tuple[int, ...]  # step indices of the first overruns
    stopped_at: int | None  # the step at which max_overruns stopped the run
    process: Any  # cosim.realtime.ProcessReport of a paced run
    # FMU -> its network's call times (calls; p50, p99, max in us; period_steps; overruns of
    # its own task), for FMUs that embed one
    network_calls: dict[str, dict[str, float]]
    resolution: ClassVar[float | None] = None  # of the percentiles (None: exact)

    @property
    def period(self) -> float:
        """Wall-clock seconds per step."""
        return self.step / (self.pacing.rt_factor if self.pacing else 1.0)

    def _counted(self) -> tuple[Distribution, tuple[Distribution, ...], Distribution]:
        """The steps' TET, each FMU's share of it, their lateness."""
        raise NotImplementedError

    def _stopped_step(self) -> tuple[float, float]:
        """The TET and the lateness [s] of the step at which max_overruns stopped the run."""
        raise NotImplementedError

    def table(self, wall_s: float) -> dict[str, Any]:
        """The `realtime` table of metrics.json (times in microseconds)."""
        tet, fmu_tet, lateness = self._counted()
        tet_us = _stats(tet)
        table: dict[str, Any] = {
            "period_us": self.period * US,
            "target_real_time_factor": self.pacing.rt_factor if self.pacing else None,
            "achieved_real_time_factor": tet.size * self.step / wall_s if wall_s > 0 else None,
            "steps": tet.size,
            "tet_us": tet_us,
            "tet_us_per_fmu": {n: _stats(d) for n, d in zip(self.names, fmu_tet)},
            "tet_over_period_p99": tet_us["p99"] / US / self.period if tet.size else None,
            "network_call_us": self.network_calls,
            "tasks": self._tasks(tet_us),
        }
        if self.resolution is not None:
            table["percentile_resolution"] = self.resolution
        if self.pacing is not None:
            table.update({
                "lateness_us": {"p99": lateness.percentile(99.0) * US, "max": lateness.max * US},
                "overruns": self.overruns,
                "rate_transition_overruns": self.task_overruns,
                "first_overruns_s": [k * self.step for k in self.first_overruns],
                "max_overruns": self.pacing.max_overruns, "grace_s": self.pacing.grace,
                "stopped_at_s": None if self.stopped_at is None
                else self.stopped_at * self.step,
                "process": dataclasses.asdict(self.process) if self.process else None})
        return table

    def _tasks(self, tet_us: dict[str, float]) -> dict[str, dict[str, Any]]:
        """Per task, as Simulink Real-Time lists them: the base task (every step: its TET
        statistics `tet_us` and overruns) and each network in its own task (`FMU.network`: its
        period, the time per call and its rate-transition overruns, which its FMU counts paced
        or not; the base task's overruns only mean something when paced)."""
        tasks: dict[str, dict[str, Any]] = {"base": {
            "period_us": self.period * US, "tet_us": tet_us,
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
        tet, late = self._stopped_step()
        over = (tet + late - self.period) * US
        if over <= 0:  # the step kept its period: a slower task's result was late
            return (f"stopped after {self.overruns} overruns and {self.task_overruns} "
                    f"rate-transition overruns (--max-overruns {pacing.max_overruns}): at "
                    f"t = {k * self.step:.6g} s a network's task had not finished when its "
                    f"result was due")
        return (f"stopped after {self.overruns} overruns (--max-overruns "
                f"{pacing.max_overruns}): the step from t = {k * self.step:.6g} s took "
                f"{tet * US:.1f} us and started {late * US:.1f} us late, "
                f"{over:.1f} us past its {self.period * US:.1f} us period")


@dataclass(frozen=True, eq=False)
class StepTiming(_Timing):
    """What the engine measured, one value per step made (a run held in memory)."""

    step: float
    names: tuple[str, ...]
    tet: np.ndarray  # [s]
    fmu_tet: np.ndarray  # steps x FMUs [s]
    lateness: np.ndarray  # [s], zero when not paced
    pacing: Pacing | None
    overruns: int
    task_overruns: int
    first_overruns: tuple[int, ...]
    stopped_at: int | None
    process: Any = None
    network_calls: dict[str, dict[str, float]] = dataclasses.field(default_factory=dict)

    def _counted(self) -> tuple[Distribution, tuple[Distribution, ...], Distribution]:
        return (Exact(self.tet), tuple(Exact(self.fmu_tet[:, i]) for i in range(len(self.names))),
                Exact(self.lateness))

    def _stopped_step(self) -> tuple[float, float]:
        assert self.stopped_at is not None
        return float(self.tet[self.stopped_at]), float(self.lateness[self.stopped_at])

    def trace(self) -> TetTrace:
        """The steps' timing as tet.png draws it."""
        trace = TetTrace(self.tet.size, len(self.names))
        trace.add(0, self.tet, self.fmu_tet, self.lateness)
        return trace


@dataclass(frozen=True, eq=False)
class StreamedTiming(_Timing):
    """What the engine measured in a run whose record was streamed, paced or not, in memory
    that does not grow with the run's length: each step's TET, each FMU's share and the
    lateness counted in histograms (percentiles within RESOLUTION), the bounded trace tet.png
    draws (paced), and the engine's overrun counts; of the step that stopped a run, its TET
    and lateness."""

    step: float
    names: tuple[str, ...]
    tet: Histogram
    fmu_tet: tuple[Histogram, ...]
    lateness: Histogram
    tet_trace: TetTrace
    pacing: Pacing | None = None
    overruns: int = 0
    task_overruns: int = 0
    first_overruns: tuple[int, ...] = ()
    stopped_at: int | None = None
    stopped_step: tuple[float, float] = (0.0, 0.0)  # TET, lateness [s] of step stopped_at
    process: Any = None
    network_calls: dict[str, dict[str, float]] = dataclasses.field(default_factory=dict)
    resolution: ClassVar[float | None] = RESOLUTION

    @classmethod
    def counting(cls, step: float, names: tuple[str, ...], steps: int,
                 pacing: Pacing | None) -> StreamedTiming:
        """Nothing counted yet, for a run of `steps` steps of the FMUs `names`."""
        return cls(step, names, Histogram(), tuple(Histogram() for _ in names), Histogram(),
                   TetTrace(steps, len(names)), pacing)

    def add(self, k0: int, tet: np.ndarray, fmu_tet: np.ndarray, lateness: np.ndarray) -> None:
        """Count steps k0, k0 + 1, ...: their TET, the FMUs' shares (steps x FMUs) and, paced,
        their lateness and the trace (only a paced run draws tet.png)."""
        self.tet.add(tet)
        for i, h in enumerate(self.fmu_tet):
            h.add(fmu_tet[:, i])
        if self.pacing is not None:
            self.lateness.add(lateness)
            self.tet_trace.add(k0, tet, fmu_tet, lateness)

    def _counted(self) -> tuple[Distribution, tuple[Distribution, ...], Distribution]:
        return self.tet, self.fmu_tet, self.lateness

    def _stopped_step(self) -> tuple[float, float]:
        return self.stopped_step

    def trace(self) -> TetTrace:
        """The steps' timing as tet.png draws it."""
        return self.tet_trace
