"""Plots of a run, as PNG files (matplotlib's Agg backend, no display needed).

  path.png    the true x-y path against the reference
  error.png   tracking error e = reference - true position over time, per axis
  forces.png  feedback, feedforward and total end-effector force over time, per axis
  signals.png every recorded float signal over time, for a run without those signals
              (PLOT_SIGNALS: per axis x, y the reference, the true position, the feedback and
              the feedforward force; at most MAX_PANELS of them)
  tet.png     a paced run's task execution time per step, each FMU's share, the period and
              the overruns (drawn from a bounded trace, cosim.timing.TetTrace)

A run feeds RunPlots chunk by chunk while it runs; long series are drawn decimated
(cosim.decimate: min and max per pixel column, so a one-sample spike stays visible), so a plot
takes bounded time and memory whatever the run's length. matplotlib loads only when a plot is
drawn.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from flexff.cosim.decimate import Envelope, Strided
from flexff.cosim.metrics import AXES
from flexff.cosim.recording import Recording, atomic_write, signal_name
from flexff.cosim.timing import US, StepTiming, StreamedTiming

if TYPE_CHECKING:
    from matplotlib.figure import Figure

# a tracking loop's signals per axis: reference, true position, feedback and feedforward force
PATH_SIGNALS = (*(f"{a}_ref" for a in AXES), *AXES)
PLOT_SIGNALS = (*PATH_SIGNALS, *(f"F{a}_fb" for a in AXES), *(f"F{a}_ff" for a in AXES))
MAX_PANELS = 8
MM = 1e3


def _figure(**options: Any) -> Figure:
    from matplotlib.figure import Figure

    return Figure(**options)


def save_figure(figure: Figure, path: Path) -> Path:
    """Lay out and write `figure` atomically as PNG."""
    figure.tight_layout()
    atomic_write(path, lambda tmp: figure.savefig(tmp, dpi=120, format="png"))
    return path


class RunPlots:
    """The plots of one run of `points` points `step` apart, fed chunk by chunk (`add`) with
    the recorded columns by name: path, error and forces where `recorded` has
    PLOT_SIGNALS, else one panel per float signal."""

    def __init__(self, recorded: Sequence[str], points: int, step: float) -> None:
        self.points, self.step = points, step
        try:
            self.columns = {s: signal_name(recorded, s) for s in PLOT_SIGNALS}
        except KeyError:
            self.columns = {}
        self.path = {s: Strided(points) for s in PATH_SIGNALS} if self.columns else {}
        self.series: dict[str, Envelope] = {}
        self.panels: list[str] | None = None if not self.columns else []

    def _envelope(self, name: str, k0: int, values: np.ndarray) -> None:
        if name not in self.series:
            self.series[name] = Envelope(self.points)
        self.series[name].add(k0, values)

    def add(self, k0: int, columns: Mapping[str, np.ndarray]) -> None:
        """The values of points k0, k0 + 1, ... of every recorded signal."""
        if not self.columns:
            if self.panels is None:
                self.panels = [n for n, v in columns.items() if v.dtype.kind == "f"][:MAX_PANELS]
            for name in self.panels:
                self._envelope(name, k0, columns[name])
            return
        c = {s: columns[n] for s, n in self.columns.items()}
        for name, strided in self.path.items():
            strided.add(k0, c[name])
        for axis in AXES:
            fb, ff = c[f"F{axis}_fb"], c[f"F{axis}_ff"]
            self._envelope(f"e_{axis}", k0, c[f"{axis}_ref"] - c[axis])
            self._envelope(f"F{axis}_fb", k0, fb)
            self._envelope(f"F{axis}_ff", k0, ff)
            self._envelope(f"F{axis}", k0, fb + ff)

    def write(self, folder: str | Path) -> list[Path]:
        """Write path.png, error.png and forces.png into `folder` (signals.png for a run
        without PLOT_SIGNALS); return their paths."""
        folder = Path(folder)
        if not self.columns:
            return [self._signals(folder / "signals.png")]
        return [self._path(folder / "path.png"), self._error(folder / "error.png"),
                self._forces(folder / "forces.png")]

    def _line(self, name: str) -> tuple[np.ndarray, np.ndarray]:
        return self.series[name].line(self.step) if name in self.series else (
            np.zeros(0), np.zeros(0))

    def _path(self, path: Path) -> Path:
        figure = _figure(figsize=(5.5, 5.5))
        ax = figure.subplots()
        p = {name: strided.values() * MM for name, strided in self.path.items()}
        ax.plot(p["x_ref"], p["y_ref"], "k--", lw=1, label="reference")
        ax.plot(p["x"], p["y"], lw=1, label="end effector")
        ax.set(xlabel="x [mm]", ylabel="y [mm]", aspect="equal", title="x-y path")
        ax.legend(loc="best")
        return save_figure(figure, path)

    def _error(self, path: Path) -> Path:
        figure = _figure(figsize=(8, 5))
        axes = figure.subplots(2, 1, sharex=True)
        for ax, axis in zip(axes, AXES):
            t, e = self._line(f"e_{axis}")
            ax.plot(t, e * MM, lw=0.8)
            ax.set(ylabel=f"e_{axis} [mm]")
            ax.grid(True, alpha=0.3)
        axes[0].set_title("tracking error (reference - true position)")
        axes[-1].set_xlabel("time [s]")
        return save_figure(figure, path)

    def _forces(self, path: Path) -> Path:
        figure = _figure(figsize=(8, 5))
        axes = figure.subplots(2, 1, sharex=True)
        for ax, axis in zip(axes, AXES):
            for name, style, label in ((f"F{axis}_fb", {"lw": 0.8}, "feedback"),
                                       (f"F{axis}_ff", {"lw": 0.8}, "feedforward"),
                                       (f"F{axis}", {"color": "k", "lw": 0.6}, "total")):
                ax.plot(*self._line(name), label=label, **style)
            ax.set(ylabel=f"F_{axis} [N]")
            ax.grid(True, alpha=0.3)
        axes[0].legend(loc="upper right", ncol=3, fontsize="small")
        axes[0].set_title("end-effector force")
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


def write_plots(rec: Recording, folder: str | Path) -> list[Path]:
    """The plots of a recording held in memory (RunPlots, fed at once) into `folder`."""
    plots = RunPlots(list(rec.signals), rec.time.size, rec.step)
    plots.add(0, rec.signals)
    return plots.write(folder)
