"""A look at one excitation trajectory: position, velocity, acceleration (and jerk where the
axis has a jerk limit) of every axis against time, with the description's limits dashed, as a
PNG file (matplotlib's Agg backend, no display needed)."""

from __future__ import annotations

from pathlib import Path

from flexff.cosim.plots import save_figure
from flexff.learning.excitation import Excitation

UNIT_POWERS = ("", "/s", "/s^2", "/s^3")


def plot_excitation(excitation: Excitation, path: str | Path) -> Path:
    """Write the plot of `excitation` to `path` (PNG): one column per axis, one row per
    quantity, each axis's limits as dashed lines."""
    from matplotlib.figure import Figure

    axes = excitation.machine.axes
    rows = 4 if any(a.limits.jerk is not None for a in axes) else 3
    figure = Figure(figsize=(4.0 * len(axes), 2.2 * rows))
    panels = figure.subplots(rows, len(axes), squeeze=False, sharex=True)
    for column, axis in enumerate(axes):
        limits = axis.limits
        bounds = ((limits.low, limits.high), (-limits.velocity, limits.velocity),
                  (-limits.acceleration, limits.acceleration),
                  None if limits.jerk is None else (-limits.jerk, limits.jerk))
        for row, name in enumerate((axis.reference, *axis.derivatives)[:rows]):
            panel = panels[row][column]
            panel.plot(excitation.time, excitation.signals[name], linewidth=0.8)
            for bound in bounds[row] or ():
                panel.axhline(bound, color="0.4", linestyle="--", linewidth=0.8)
            panel.set_ylabel(f"{name} [{axis.unit}{UNIT_POWERS[row]}]")
            panel.grid(True, alpha=0.3)
        panels[0][column].set_title(f"axis {axis.name}")
        panels[rows - 1][column].set_xlabel("time [s]")
    figure.suptitle(f"{excitation.machine.name}: {excitation.name} ({excitation.split}, "
                    f"{excitation.kind})")
    return save_figure(figure, Path(path))
