"""The plane's reference paths of the manipulator: analytic position, velocity and acceleration
of x and y on a fixed time grid.

A path is built from segments, each an exact function of its own time: skew-sine lines
(eq. 4.2) and circles (eq. 4.1), which start and end at rest with zero acceleration, holds,
and periodic cubic splines through given points. `Chain` joins segments end to start (position
must be continuous) and `sample` evaluates a path on the communication grid. Tables from CSV
files are resampled onto the grid, with missing derivatives from a Savitzky-Golay filter.

Every segment checks its arguments and that it stays inside the nominal workspace
(plant.kinematics), and raises InputError naming the offending point otherwise. Sampling
checks first that the samples fit into the available memory (MemoryNeeded, an InputError,
says how much they need). plant.reference_kinds makes the [reference] kinds of them.
"""

from __future__ import annotations

import csv
import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any, ClassVar

import numpy as np

from flexff.cosim.csv_text import TIME, read_time_table
from flexff.cosim.memory import check_memory
from flexff.cosim.references import SAVGOL_ORDER, SMOOTHING_WINDOW, ReferenceKeyError
from flexff.fmu.defaults import DEFAULT_STEP
from flexff.fmu.errors import InputError
from flexff.fmu.limits import SMOOTHING_SAMPLES
from flexff.plant.signals import (
    ACCELERATION_REFERENCE,
    POSITION_REFERENCE,
    REFERENCE,
    VELOCITY_REFERENCE,
    names,
)

if TYPE_CHECKING:  # SciPy loads with the paths that use it
    from scipy.interpolate import CubicSpline

JOIN_TOLERANCE = 1e-9  # m: largest position jump accepted between chained segments
SAMPLED_ARRAYS = 7  # float64 arrays a sampled reference holds: t, x, y, vx, vy, ax, ay


def check_workspace(x: Any, y: Any, what: str) -> None:
    """Points (x, y) [m] inside the nominal plant's workspace (ValueError otherwise)."""
    from flexff.plant.kinematics import check_workspace as in_workspace  # CasADi
    from flexff.plant.parameters import NOMINAL

    in_workspace(NOMINAL, x, y, what)


@dataclass(frozen=True, eq=False)
class Reference:
    """A sampled reference: times [s], positions [m], velocities [m/s], accelerations [m/s^2]."""

    t: np.ndarray
    x: np.ndarray
    y: np.ndarray
    vx: np.ndarray
    vy: np.ndarray
    ax: np.ndarray
    ay: np.ndarray

    SIGNALS: ClassVar[tuple[str, ...]] = names(REFERENCE)
    positions: ClassVar[tuple[str, ...]] = names(POSITION_REFERENCE)  # held after the end

    def __post_init__(self) -> None:
        arrays = self._arrays()
        if any(a.ndim != 1 or a.shape != arrays[0].shape for a in arrays):
            raise ValueError("reference arrays must be one-dimensional and of equal length")

    def _arrays(self) -> list[np.ndarray]:
        return [self.t, self.x, self.y, self.vx, self.vy, self.ax, self.ay]

    @property
    def duration(self) -> float:
        return float(self.t[-1] - self.t[0])

    def signals(self) -> dict[str, np.ndarray]:
        """The reference signals by their co-simulation names (SIGNALS)."""
        return dict(zip(self.SIGNALS, self._arrays()[1:]))

    def to_csv(self, path: str | Path) -> None:
        """Write a table with columns time and SIGNALS."""
        with open(path, "w", newline="") as handle:
            writer = csv.writer(handle)
            writer.writerow((TIME, *self.SIGNALS))
            writer.writerows(np.column_stack(self._arrays()).tolist())


class Segment:
    """A path piece: `duration` [s] and `evaluate(t)` for 0 <= t <= duration.

    `evaluate` returns a (6, n) array: x, y, vx, vy, ax, ay at the local times t.
    """

    if TYPE_CHECKING:  # a field of the plain segments, a property of Chain: read-only here
        @property
        def duration(self) -> float: ...

    def evaluate(self, t: np.ndarray) -> np.ndarray:
        raise NotImplementedError

    @property
    def start(self) -> np.ndarray:
        return self.evaluate(np.zeros(1))[:2, 0]

    @property
    def end(self) -> np.ndarray:
        return self.evaluate(np.array([self.duration]))[:2, 0]

    def _validate(self) -> None:
        """Positive finite duration and, on a dense grid, the whole path in the workspace."""
        _positive("duration", self.duration, "s")
        n = max(2001, int(self.duration * 2000))
        check_memory(SAMPLED_ARRAYS * n, f"checking the {self.duration:g} s "
                                         f"{type(self).__name__.lower()} on a grid of 0.5 ms")
        dense = self.evaluate(np.linspace(0.0, self.duration, n))
        check_workspace(dense[0], dense[1], f"{type(self).__name__} point")


@dataclass(frozen=True)
class Line(Segment):
    """Skew-sine straight line (eq. 4.2) from `start_point` to `end_point` [m], at rest at both."""

    start_point: tuple[float, float]
    end_point: tuple[float, float]
    duration: float

    def __post_init__(self) -> None:
        _finite_point("start_point", self.start_point)
        _finite_point("end_point", self.end_point)
        self._validate()

    def evaluate(self, t: np.ndarray) -> np.ndarray:
        s, ds, dds = _skew_sine(t, self.duration)
        a, b = np.asarray(self.start_point, float), np.asarray(self.end_point, float)
        stroke = (b - a)[:, None]
        return np.vstack([a[:, None] + stroke * s, stroke * ds, stroke * dds])


@dataclass(frozen=True)
class Circle(Segment):
    """Skew-sine circle (eq. 4.1): `turns` revolutions (negative: clockwise) about `centre`.

    The angle runs from `start_angle` [rad] to start_angle + 2 pi turns, at rest at both ends.
    """

    centre: tuple[float, float]
    radius: float
    start_angle: float
    turns: float
    duration: float

    def __post_init__(self) -> None:
        _finite_point("centre", self.centre)
        _positive("radius", self.radius, "m")
        if not (math.isfinite(self.start_angle) and math.isfinite(self.turns) and self.turns):
            raise InputError(f"start_angle ({self.start_angle}) must be finite and turns "
                             f"({self.turns}) finite and nonzero")
        self._validate()

    def evaluate(self, t: np.ndarray) -> np.ndarray:
        s, ds, dds = _skew_sine(t, self.duration)
        sweep = 2 * math.pi * self.turns
        angle, rate, accel = self.start_angle + sweep * s, sweep * ds, sweep * dds
        c, n, r = np.cos(angle), np.sin(angle), self.radius
        return np.vstack([self.centre[0] + r * c, self.centre[1] + r * n,
                          -r * n * rate, r * c * rate,
                          -r * c * rate**2 - r * n * accel, -r * n * rate**2 + r * c * accel])


@dataclass(frozen=True)
class Hold(Segment):
    """Standing still at `point` [m] for `duration` [s]."""

    point: tuple[float, float]
    duration: float

    def __post_init__(self) -> None:
        _finite_point("point", self.point)
        self._validate()

    def evaluate(self, t: np.ndarray) -> np.ndarray:
        n = np.size(t)
        return np.vstack([np.full(n, float(self.point[0])), np.full(n, float(self.point[1])),
                          np.zeros((4, n))])


@dataclass(frozen=True)
class Spline(Segment):
    """Closed periodic cubic spline through `points` [m], traversed once in `duration` [s].

    Knot times are proportional to the chord lengths (including the closing chord), so the
    speed is roughly even; velocity and acceleration are the spline's own derivatives and are
    continuous around the loop, but not zero at the start.
    """

    points: tuple[tuple[float, float], ...]
    duration: float
    _spline: CubicSpline = field(init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        pts = np.asarray(self.points, dtype=float)
        if pts.ndim != 2 or pts.shape[1] != 2 or len(pts) < 2 or not np.all(np.isfinite(pts)):
            raise InputError(f"points must be at least two finite (x, y) pairs, got {self.points}")
        closed = np.vstack([pts, pts[:1]])
        chords = np.hypot(*np.diff(closed, axis=0).T)
        if np.any(chords == 0):
            k = int(np.argmin(chords))
            raise InputError(f"consecutive spline points {k} and {(k + 1) % len(pts)} coincide "
                             f"at ({pts[k][0]:g}, {pts[k][1]:g}) m")
        _positive("duration", self.duration, "s")
        from scipy.interpolate import CubicSpline

        knots = np.concatenate([[0.0], np.cumsum(chords)]) / chords.sum() * self.duration
        object.__setattr__(self, "_spline", CubicSpline(knots, closed, bc_type="periodic"))
        self._validate()

    def evaluate(self, t: np.ndarray) -> np.ndarray:
        return np.vstack([self._spline(t, nu).T for nu in (0, 1, 2)])


@dataclass(frozen=True)
class Chain(Segment):
    """Segments one after the other; each must start where the previous one ends."""

    segments: tuple[Segment, ...]

    def __post_init__(self) -> None:
        if not self.segments:
            raise InputError("a chain needs at least one segment")
        for k, (a, b) in enumerate(zip(self.segments[:-1], self.segments[1:])):
            jump = np.linalg.norm(b.start - a.end)
            if jump > JOIN_TOLERANCE:
                raise InputError(
                    f"segment {k + 1} ({type(b).__name__}) starts at {tuple(b.start)} m but "
                    f"segment {k} ({type(a).__name__}) ends at {tuple(a.end)} m: a jump of "
                    f"{jump:.3g} m")

    @property
    def duration(self) -> float:
        return float(sum(s.duration for s in self.segments))

    def evaluate(self, t: np.ndarray) -> np.ndarray:
        t = np.atleast_1d(np.asarray(t, dtype=float))
        starts = np.concatenate([[0.0], np.cumsum([s.duration for s in self.segments])[:-1]])
        index = np.clip(np.searchsorted(starts, t, side="right") - 1, 0, len(starts) - 1)
        out = np.empty((6, t.size))
        for k, segment in enumerate(self.segments):
            mine = index == k
            out[:, mine] = segment.evaluate(np.minimum(t[mine] - starts[k], segment.duration))
        return out


def sample(path: Segment, step: float = DEFAULT_STEP) -> Reference:
    """`path` on the grid 0, step, 2 step, ... up to its duration."""
    _positive("step", step, "s")
    n = _grid_points(path.duration, step, f"sampling the {path.duration:g} s reference every "
                                          f"{step:g} s")
    t = np.arange(n) * step
    return Reference(t, *path.evaluate(t))


def _grid_points(duration: float, step: float, what: str) -> int:
    """The points of the grid 0, step, ... up to `duration`, checked to fit into memory as a
    sampled reference (check_memory; `what` names them). Capped before rounding: a step of
    5e-324 s makes infinitely many, which math.floor cannot count."""
    n = math.floor(min(duration / step + 1e-9, 2.0**62)) + 1
    check_memory(SAMPLED_ARRAYS * n, what)
    return n


def read_csv(path: str | Path, step: float = DEFAULT_STEP,
             smoothing_window: float = SMOOTHING_WINDOW) -> Reference:
    """A reference from a CSV table with columns time (or t), the positions of
    Reference.SIGNALS (and optionally their velocities and accelerations; cosim.csv_text's time
    table), resampled onto the grid t0, t0 + step, ... by cubic interpolation.

    Missing velocities and accelerations come from a cubic Savitzky-Golay filter over
    `smoothing_window` seconds of the resampled positions, which also smooths measured data.
    """
    from scipy.interpolate import CubicSpline
    from scipy.signal import savgol_filter

    _positive("step", step, "s")
    _positive("smoothing_window", smoothing_window, "s")
    # an odd number of samples, at least SAVGOL_ORDER + 2: the cubic fit needs more points
    # than coefficients, which a window of a few coarse steps would not give (capped, as
    # _grid_points: round cannot count the infinitely many of a 5e-324 s step)
    window = max(2 * round(min(smoothing_window / step, 2.0**62) / 2) + 1, SAVGOL_ORDER + 2)
    SMOOTHING_SAMPLES.check(window, f"{path}: the {smoothing_window:g} s smoothing window at "
                                    f"the {step:g} s step (a larger step or a shorter window)")
    table = read_time_table(Path(path), Reference.positions, Reference.SIGNALS[2:])
    columns, t = table.columns, table.time
    x, y = (columns[p] for p in Reference.positions)
    check_workspace(x, y, f"{path}: point")
    n = _grid_points(t[-1] - t[0], step, f"{path}: resampling the {t[-1] - t[0]:g} s table "
                                         f"every {step:g} s")
    grid = t[0] + np.arange(n) * step
    if grid.size < window:
        raise InputError(f"{path}: the table spans {t[-1] - t[0]:.6g} s, too short for the "
                         f"{smoothing_window} s smoothing window at the {step} s step")
    resampled = {name: CubicSpline(t, values)(grid) for name, values in columns.items()
                 if name != TIME}
    for position, *derivatives in zip(*(names(g) for g in (
            POSITION_REFERENCE, VELOCITY_REFERENCE, ACCELERATION_REFERENCE))):
        for order, name in enumerate(derivatives, start=1):
            if name not in resampled:
                resampled[name] = savgol_filter(resampled[position], window, SAVGOL_ORDER,
                                                deriv=order, delta=step)
    x, y = (resampled[p] for p in Reference.positions)
    check_workspace(x, y, f"{path}: resampled point")
    return Reference(grid, *(resampled[name] for name in Reference.SIGNALS))


def _skew_sine(t: np.ndarray, duration: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Normalized skew-sine profile s(t) from 0 to 1 in `duration`, with s' and s''."""
    t = np.atleast_1d(np.asarray(t, dtype=float))
    phase = 2 * math.pi * t / duration
    return (t / duration - np.sin(phase) / (2 * math.pi), (1 - np.cos(phase)) / duration,
            2 * math.pi * np.sin(phase) / duration**2)


def _positive(name: str, value: float, unit: str) -> None:
    if not (isinstance(value, (int, float, np.floating, np.integer)) and math.isfinite(value)
            and value > 0):
        raise InputError(f"{name} must be a positive finite number of {unit}, got {value!r}")


def _finite_point(name: str, point: Sequence[float]) -> None:
    if len(point) != 2 or not all(math.isfinite(float(v)) for v in point):
        raise InputError(f"{name} must be a finite (x, y) pair in m, got {point!r}")


def segment_chain(start: tuple[float, float], segments: Sequence[Mapping[str, Any]]
                  ) -> Chain:
    """The checked segment tables of a `segments` reference as one Chain from `start`."""
    point, pieces = (float(start[0]), float(start[1])), []
    for k, spec in enumerate(segments):
        try:
            piece = _segment(point, spec)
        except ValueError as error:
            raise ReferenceKeyError(f"segments[{k}]", str(error)) from None
        pieces.append(piece)
        point = (float(piece.end[0]), float(piece.end[1]))
    return Chain(tuple(pieces))


def _segment(point: tuple[float, float], spec: Mapping[str, Any]) -> Segment:
    """One segment starting at `point`; circles and splines take their geometry from it."""
    kind, duration = spec["kind"], spec["duration"]
    if kind == "line":
        return Line(point, tuple(spec["to"]), duration)
    if kind == "hold":
        return Hold(point, duration)
    if kind == "circle":
        centre = spec["centre"]
        dx, dy = point[0] - centre[0], point[1] - centre[1]
        radius = math.hypot(dx, dy)
        if radius == 0:
            raise InputError(f"the circle starts at its centre {tuple(centre)} m (radius 0): "
                             f"move the centre or the point before it")
        return Circle(tuple(centre), radius, math.atan2(dy, dx), spec["turns"], duration)
    return Spline((point, *map(tuple, spec["points"])), duration)
