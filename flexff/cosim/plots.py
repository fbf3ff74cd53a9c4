"""Plots of a run, as PNG files (matplotlib's Agg backend, no display needed).

  path.png    the positions against the reference, one tracked axis against the other of two
  error.png   tracking error e = reference - position over time, per tracked axis
  forces.png  per tracked axis of a loop: its feedforward, its effort and their difference,
              the feedback
  signals.png every recorded float signal (at most MAX_PANELS), for a run tracking no axis
  tet.png     a paced run's task execution time per step, each FMU's share, the period and
              the overruns (drawn from a bounded trace, cosim.timing.TetTrace)

The tracked axes are the run's (cosim.metrics.TrackedAxis); positions in m are drawn in mm.
A run feeds RunPlots chunk by chunk; long series are drawn decimated (cosim.decimate: min and
max per pixel column, so a one-sample spike stays visible), in bounded time and memory.
matplotlib loads only when a plot is drawn.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from flexff.cosim.decimate import Envelope, Strided
from flexff.cosim.metrics import TrackedAxis, Tracking
from flexff.cosim.recording import Recording, atomic_write, signal_name
from flexff.cosim.timing import US, StepTiming, StreamedTiming

if TYPE_CHECKING:
    from matplotlib.figure import Figure

MAX_PANELS = 8
MM = 1e3
PATH_AXES = 2  # the tracked axes a path plot draws one against the other


def _figure(**options: Any) -> Figure:
    from matplotlib.figure import Figure

    return Figure(**options)


def save_figure(figure: Figure, path: Path) -> Path:
    """Lay out and write `figure` atomically as PNG."""
    figure.tight_layout()
    atomic_write(path, lambda tmp: figure.savefig(tmp, dpi=120, format="png"))
    return path


def _drawn(unit: str) -> tuple[float, str]:
    """The scale and unit a value in `unit` is drawn in: m as mm, the rest as it is."""
    return (MM, "mm") if unit == "m" else (1.0, unit)


class RunPlots:
    """The plots of one run of `points` points `step` apart, fed chunk by chunk (`add`) with
    the recorded columns by name: path, error and forces of the tracked `axes` where
    `recorded` holds them, else one panel per float signal."""

    def __init__(self, recorded: Sequence[str], points: int, step: float,
                 axes: Sequence[TrackedAxis] = ()) -> None:
        self.points, self.step = points, step
        self.axes = {a.name: (a, a.columns(recorded)) for a in axes} \
            if axes and Tracking.tracks(recorded, axes) else {}
        try:
            self.efforts = {a.name: (signal_name(recorded, a.feedforward),
                                     signal_name(recorded, a.effort))
                            for a, _ in self.axes.values()
                            if a.feedforward is not None and a.effort is not None}
        except KeyError:
            self.efforts = {}
        self.path = {f"{name}{part}": Strided(points) for name in self.axes
                     for part in ("_ref", "")} if len(self.axes) == PATH_AXES else {}
        self.series: dict[str, Envelope] = {}
        self.panels: list[str] | None = None if not self.axes else []

    def _envelope(self, name: str, k0: int, values: np.ndarray) -> None:
        if name not in self.series:
            self.series[name] = Envelope(self.points)
        self.series[name].add(k0, values)

    def add(self, k0: int, columns: Mapping[str, np.ndarray]) -> None:
        """The values of points k0, k0 + 1, ... of every recorded signal."""
        if not self.axes:
            if self.panels is None:
                self.panels = [n for n, v in columns.items() if v.dtype.kind == "f"][:MAX_PANELS]
            for name in self.panels:
                self._envelope(name, k0, columns[name])
            return
        for name, (axis, found) in self.axes.items():
            reference, position = axis.values(columns, found)
            if self.path:
                self.path[f"{name}_ref"].add(k0, reference)
                self.path[name].add(k0, position)
            self._envelope(f"e_{name}", k0, reference - position)
        for name, (feedforward, effort) in self.efforts.items():
            ff, total = columns[feedforward], columns[effort]
            self._envelope(f"{name}_feedback", k0, total - ff)
            self._envelope(f"{name}_feedforward", k0, ff)
            self._envelope(f"{name}_effort", k0, total)

    def write(self, folder: str | Path) -> list[Path]:
        """Write path.png (two tracked axes), error.png and forces.png (a loop's axes) into
        `folder` (signals.png for a run that tracks no axis); return their paths."""
        folder = Path(folder)
        if not self.axes:
            return [self._signals(folder / "signals.png")]
        return [*([self._path(folder / "path.png")] if self.path else []),
                self._error(folder / "error.png"),
                *([self._forces(folder / "forces.png")] if self.efforts else [])]

    def _line(self, name: str) -> tuple[np.ndarray, np.ndarray]:
        return self.series[name].line(self.step) if name in self.series else (
            np.zeros(0), np.zeros(0))

    def _path(self, path: Path) -> Path:
        figure = _figure(figsize=(5.5, 5.5))
        ax = figure.subplots()
        (first, (a, _)), (second, (b, _)) = self.axes.items()
        (scale_a, unit_a), (scale_b, unit_b) = _drawn(a.unit), _drawn(b.unit)
        p = {name: strided.values() for name, strided in self.path.items()}
        ax.plot(p[f"{first}_ref"] * scale_a, p[f"{second}_ref"] * scale_b, "k--", lw=1,
                label="reference")
        ax.plot(p[first] * scale_a, p[second] * scale_b, lw=1, label="position")
        ax.set(xlabel=f"{first} [{unit_a}]", ylabel=f"{second} [{unit_b}]",
               title=f"{first}-{second} path")
        if unit_a == unit_b:
            ax.set_aspect("equal")
        ax.legend(loc="best")
        return save_figure(figure, path)

    def _error(self, path: Path) -> Path:
        figure = _figure(figsize=(8, 1.5 + 1.75 * len(self.axes)))
        axes = figure.subplots(len(self.axes), 1, sharex=True, squeeze=False)[:, 0]
        for ax, (name, (axis, _)) in zip(axes, self.axes.items()):
            scale, unit = _drawn(axis.unit)
            t, e = self._line(f"e_{name}")
            ax.plot(t, e * scale, lw=0.8)
            ax.set(ylabel=f"e_{name} [{unit}]")
            ax.grid(True, alpha=0.3)
        axes[0].set_title("tracking error (reference - position)")
        axes[-1].set_xlabel("time [s]")
        return save_figure(figure, path)

    def _forces(self, path: Path) -> Path:
        figure = _figure(figsize=(8, 1.5 + 1.75 * len(self.efforts)))
        axes = figure.subplots(len(self.efforts), 1, sharex=True, squeeze=False)[:, 0]
        for ax, name in zip(axes, self.efforts):
            for part, style in (("feedback", {"lw": 0.8}), ("feedforward", {"lw": 0.8}),
                                ("effort", {"color": "k", "lw": 0.6})):
                ax.plot(*self._line(f"{name}_{part}"),
                        label="total" if part == "effort" else part, **style)
            ax.set(ylabel=f"{name} [{self.axes[name][0].effort_unit}]")
            ax.grid(True, alpha=0.3)
        axes[0].legend(loc="upper right", ncol=3, fontsize="small")
        axes[0].set_title("effort per axis")
        axes[-1].set_xlabel("time [s]")
        return save_figure(figure, path)

    def _signals(self, path: Path) -> Path:
        """The first MAX_PANELS float signals, one panel each."""
        panels = self.panels or []
        figure = _figure(figsize=(8, 1.2 + 1.4 * max(len(panels), 1)))
        axes = figure.subplots(max(len(panels), 1), 1, sharex=True, squeeze=False)
        for ax, name in zip(axes[:, 0], panels):
            ax.plot(*self._line(name), lw=0.8)
            ax.set_ylabel(name, fontsize="small")
            ax.grid(True, alpha=0.3)
        axes[-1, 0].set_xlabel("time [s]")
        return save_figure(figure, path)


def plot_tet(timing: StepTiming | StreamedTiming, path: Path) -> Path:
    """TET over time (total and per FMU, in microseconds) against the period, from the
    timing's bounded trace (cosim.timing.TetTrace: the least and largest value per block of
    steps); overruns marked where a block's largest TET plus lateness passed the period, and
    at the exact steps of the engine's first listed overruns."""
    trace, step, period = timing.trace(), timing.step, timing.period
    figure = _figure(figsize=(9, 4))
    ax = figure.subplots()
    for name, envelope in zip(timing.names, trace.fmu_tet):
        t, values = envelope.line(step)
        ax.plot(t, values * US, lw=0.5, alpha=0.7, label=name)
    t, values = trace.tet.line(step)
    ax.plot(t, values * US, "k", lw=0.6, label="TET (step)")
    ax.axhline(period * US, color="r", ls="--", lw=1, label="period")
    t, late = trace.late.peaks(step)
    over = late > period
    if over.any():
        ax.plot(t[over], late[over] * US, "rx", ms=4, label=f"overrun ({timing.overruns})")
    first = np.array(timing.first_overruns, dtype=np.int64)
    if first.size:
        blocks = np.minimum(first // trace.late.size, late.size - 1)
        ax.plot(first * step, late[blocks] * US, "r|", ms=8,
                label=f"first {first.size} overruns")
    ax.set(xlabel="time [s]", ylabel="[us]", yscale="log",
           title="task execution time per step")
    ax.grid(True, alpha=0.3, which="both")
    ax.legend(loc="upper right", fontsize="small", ncol=2)
    return save_figure(figure, path)


def write_plots(rec: Recording, folder: str | Path, axes: Sequence[TrackedAxis] = ()
                ) -> list[Path]:
    """The plots of a recording held in memory (RunPlots, fed at once) into `folder`."""
    plots = RunPlots(list(rec.signals), rec.time.size, rec.step, axes)
    plots.add(0, rec.signals)
    return plots.write(folder)
