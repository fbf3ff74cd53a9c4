"""Plots of a run, as PNG files (matplotlib's Agg backend, no display needed).

  path.png    the true x-y path against the reference
  error.png   tracking error e = reference - true position over time, per axis
  forces.png  feedback, feedforward and total end-effector force over time, per axis
  signals.png every recorded float signal over time, for a run without the manipulator's
              signals (at most MAX_PANELS of them)
  tet.png     a paced run's task execution time per step, each FMU's share, the period and
              the overruns
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
from matplotlib.figure import Figure

from flexff.cosim.recording import Recording, atomic_write
from flexff.cosim.timing import US, StepTiming
from flexff.plant.signals import (
    FEEDBACK_FORCES,
    FEEDFORWARD_FORCES,
    POSITION_REFERENCE,
    TRUE_POSITION,
    names,
)

PLOT_SIGNALS = names(POSITION_REFERENCE, TRUE_POSITION, FEEDBACK_FORCES, FEEDFORWARD_FORCES)
MAX_PANELS = 8
MM = 1e3


def save_figure(figure: Figure, path: Path) -> Path:
    """Lay out and write `figure` atomically as PNG."""
    figure.tight_layout()
    atomic_write(path, lambda tmp: figure.savefig(tmp, dpi=120, format="png"))
    return path


def plot_path(rec: Recording, path: Path) -> Path:
    figure = Figure(figsize=(5.5, 5.5))
    ax = figure.subplots()
    ax.plot(rec["x_ref"] * MM, rec["y_ref"] * MM, "k--", lw=1, label="reference")
    ax.plot(rec["x"] * MM, rec["y"] * MM, lw=1, label="end effector")
    ax.set(xlabel="x [mm]", ylabel="y [mm]", aspect="equal", title="x-y path")
    ax.legend(loc="best")
    return save_figure(figure, path)


def plot_error(rec: Recording, path: Path) -> Path:
    figure = Figure(figsize=(8, 5))
    axes = figure.subplots(2, 1, sharex=True)
    for ax, axis in zip(axes, ("x", "y")):
        ax.plot(rec.time, (rec[f"{axis}_ref"] - rec[axis]) * MM, lw=0.8)
        ax.set(ylabel=f"e_{axis} [mm]")
        ax.grid(True, alpha=0.3)
    axes[0].set_title("tracking error (reference - true position)")
    axes[-1].set_xlabel("time [s]")
    return save_figure(figure, path)


def plot_forces(rec: Recording, path: Path) -> Path:
    figure = Figure(figsize=(8, 5))
    axes = figure.subplots(2, 1, sharex=True)
    for ax, axis in zip(axes, ("x", "y")):
        fb, ff = rec[f"F{axis}_fb"], rec[f"F{axis}_ff"]
        ax.plot(rec.time, fb, lw=0.8, label="feedback")
        ax.plot(rec.time, ff, lw=0.8, label="feedforward")
        ax.plot(rec.time, fb + ff, "k", lw=0.6, label="total")
        ax.set(ylabel=f"F_{axis} [N]")
        ax.grid(True, alpha=0.3)
    axes[0].legend(loc="upper right", ncol=3, fontsize="small")
    axes[0].set_title("end-effector force")
    axes[-1].set_xlabel("time [s]")
    return save_figure(figure, path)


def plot_signals(rec: Recording, path: Path) -> Path:
    """The first MAX_PANELS float signals, one panel each."""
    names = [n for n, v in rec.signals.items() if v.dtype.kind == "f"][:MAX_PANELS]
    figure = Figure(figsize=(8, 1.2 + 1.4 * max(len(names), 1)))
    axes = figure.subplots(max(len(names), 1), 1, sharex=True, squeeze=False)
    for ax, name in zip(axes[:, 0], names):
        ax.plot(rec.time, rec.signals[name], lw=0.8)
        ax.set_ylabel(name, fontsize="small")
        ax.grid(True, alpha=0.3)
    axes[-1, 0].set_xlabel("time [s]")
    return save_figure(figure, path)


def plot_tet(timing: StepTiming, path: Path) -> Path:
    """TET over time (total and per FMU, in microseconds) against the period."""
    figure = Figure(figsize=(9, 4))
    ax = figure.subplots()
    t = np.arange(timing.tet.size) * timing.step
    for i, name in enumerate(timing.names):
        ax.plot(t, timing.fmu_tet[:, i] * US, lw=0.5, alpha=0.7, label=name)
    ax.plot(t, timing.tet * US, "k", lw=0.6, label="TET (step)")
    ax.axhline(timing.period * US, color="r", ls="--", lw=1, label="period")
    late = timing.tet + timing.lateness > timing.period
    if late.any():
        ax.plot(t[late], (timing.tet + timing.lateness)[late] * US, "rx", ms=4,
                label=f"overrun ({timing.overruns})")
    ax.set(xlabel="time [s]", ylabel="[us]", yscale="log",
           title="task execution time per step")
    ax.grid(True, alpha=0.3, which="both")
    ax.legend(loc="upper right", fontsize="small", ncol=2)
    return save_figure(figure, path)


def write_plots(rec: Recording, folder: str | Path) -> list[Path]:
    """Write path.png, error.png and forces.png into `folder` (signals.png for a run
    without the manipulator's signals); return their paths."""
    folder = Path(folder)
    if not all(name in rec for name in PLOT_SIGNALS):
        return [plot_signals(rec, folder / "signals.png")]
    return [plot_path(rec, folder / "path.png"), plot_error(rec, folder / "error.png"),
            plot_forces(rec, folder / "forces.png")]
