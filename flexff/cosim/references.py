"""Reference trajectories: analytic position, velocity and acceleration on a fixed time grid.

A path is built from segments, each an exact function of its own time: skew-sine lines
(eq. 4.2) and circles (eq. 4.1), which start and end at rest with zero acceleration, holds,
and periodic cubic splines through given points. `Chain` joins segments end to start (position
must be continuous) and `sample` evaluates a path on the communication grid. Tables from CSV
files are resampled onto the grid, with missing derivatives from a Savitzky-Golay filter.

Every segment checks its arguments and that it stays inside the workspace (the checks the
machine packages register, cosim.plugins), and raises InputError naming the offending point
otherwise. Sampling checks first that the samples fit
into the available memory (MemoryNeeded, an InputError, says how much they need).

These kinds are the plane's (x, y). The kinds of cosim.axis_references (AXIS_KINDS) make a
reference for the axes of a run's [machine], any number of them; build_reference makes both.
"""

from __future__ import annotations

import csv
import json
import math
from collections import OrderedDict
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any, ClassVar, Protocol

import numpy as np

from flexff.cosim.axis_references import AXIS_KINDS, build_axis_reference
from flexff.cosim.csv_text import TIME, read_time_table
from flexff.cosim.machine import Machine
from flexff.cosim.memory import check_memory
from flexff.cosim.plugins import check_workspace, loaded
from flexff.fmu.defaults import DEFAULT_STEP
from flexff.fmu.errors import InputError
from flexff.fmu.limits import SMOOTHING_SAMPLES

if TYPE_CHECKING:  # SciPy and CasADi load with the references that use them
    from scipy.interpolate import CubicSpline

    from flexff.cosim.checks import TableChecker

JOIN_TOLERANCE = 1e-9  # m: largest position jump accepted between chained segments
SAVGOL_ORDER = 3  # the polynomial a CSV reference's derivatives are fitted with (read_csv)
SMOOTHING_WINDOW = 0.025  # s: the window they are fitted over, unless a configuration sets it
SAMPLED_ARRAYS = 7  # float64 arrays a sampled reference holds: t, x, y, vx, vy, ax, ay


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

    SIGNALS: ClassVar[tuple[str, ...]] = ("x_ref", "y_ref", "vx_ref", "vy_ref", "ax_ref",
                                          "ay_ref")
    positions: ClassVar[tuple[str, ...]] = ("x_ref", "y_ref")  # held after the end

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
        """The reference signals by their co-simulation names (x_ref ... ay_ref)."""
        return dict(zip(self.SIGNALS, self._arrays()[1:]))

    def to_csv(self, path: str | Path) -> None:
        """Write a table with columns time, x_ref, y_ref, vx_ref, vy_ref, ax_ref, ay_ref."""
        with open(path, "w", newline="") as handle:
            writer = csv.writer(handle)
            writer.writerow((TIME, *self.SIGNALS))
            writer.writerows(np.column_stack(self._arrays()).tolist())


class Sampled(Protocol):
    """A sampled reference of either family: the plane's (Reference) or a machine's axes'
    (cosim.axis_references.AxisReference)."""

    @property
    def t(self) -> np.ndarray: ...

    @property
    def positions(self) -> tuple[str, ...]: ...

    @property
    def duration(self) -> float: ...

    def signals(self) -> dict[str, np.ndarray]: ...


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
    """A reference from a CSV table with columns time (or t), x_ref, y_ref (and optionally
    vx_ref, vy_ref, ax_ref, ay_ref; cosim.csv_text's time table), resampled onto the grid t0,
    t0 + step, ... by cubic interpolation.

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
    table = read_time_table(Path(path), ("x_ref", "y_ref"), Reference.SIGNALS[2:])
    columns, t = table.columns, table.time
    check_workspace(columns["x_ref"], columns["y_ref"], f"{path}: point")
    n = _grid_points(t[-1] - t[0], step, f"{path}: resampling the {t[-1] - t[0]:g} s table "
                                         f"every {step:g} s")
    grid = t[0] + np.arange(n) * step
    if grid.size < window:
        raise InputError(f"{path}: the table spans {t[-1] - t[0]:.6g} s, too short for the "
                         f"{smoothing_window} s smoothing window at the {step} s step")
    resampled = {name: CubicSpline(t, values)(grid) for name, values in columns.items()
                 if name != TIME}
    for axis in ("x", "y"):
        for order, prefix in ((1, "v"), (2, "a")):
            name = f"{prefix}{axis}_ref"
            if name not in resampled:
                resampled[name] = savgol_filter(resampled[f"{axis}_ref"], window, SAVGOL_ORDER,
                                                deriv=order, delta=step)
    check_workspace(resampled["x_ref"], resampled["y_ref"],
                    f"{path}: resampled point")
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


GENERIC_KINDS = ("circle", "line-circle", "spline", "segments", "csv", *AXIS_KINDS)


@dataclass(frozen=True)
class ReferenceKind:
    """A machine package's [reference] kind: `check` turns its table, keys included, into
    checked options (None: no keys beside `kind`); `build` samples it (options, step) ->
    Reference."""

    name: str
    build: Callable[[Mapping[str, Any], float], Reference]
    check: Callable[[TableChecker, Mapping[str, Any]], dict[str, Any]] | None = None


_REFERENCE_KINDS: dict[str, ReferenceKind] = {}


def register_reference_kind(kind: ReferenceKind) -> None:
    """Make `kind.name` a [reference] kind (a machine package, through its entry point of
    cosim.plugins.GROUP)."""
    _REFERENCE_KINDS[kind.name] = kind


def reference_kinds() -> dict[str, ReferenceKind]:
    """The machine packages' [reference] kinds, their entry points loaded."""
    loaded()
    return dict(_REFERENCE_KINDS)


def reference_kind_names() -> tuple[str, ...]:
    """Every [reference] kind: the machine packages' (cosim.plugins), then GENERIC_KINDS."""
    return (*reference_kinds(), *GENERIC_KINDS)


def build_reference(kind: str, options: Mapping[str, Any], step: float,
                    machine: Machine | None = None) -> Sampled:
    """The reference of a checked [reference] table (cosim.config), sampled every `step`
    seconds from t = 0 (a kind of AXIS_KINDS for the axes of `machine`): once per process for
    the last few tables (the configuration's check and the run both ask for it; a reference
    is not changed by its users)."""
    stamp = None  # a CSV file changed since is read again
    if kind == "csv" and Path(options["path"]).is_file():
        stat = Path(options["path"]).stat()
        stamp = (stat.st_mtime_ns, stat.st_size)
    axes = None  # an axis reference's axes, limits included
    if kind in AXIS_KINDS and machine is not None:
        axes = [(a.name, a.limits) for a in machine.axes]
    key = json.dumps({"kind": kind, "options": options, "step": step, "file": stamp,
                      "axes": axes}, sort_keys=True, default=str)
    if key not in _SAMPLED:
        reference: Sampled = (build_axis_reference(kind, options, step, machine)
                              if kind in AXIS_KINDS else _built(kind, options, step))
        for values in (reference.t, *reference.signals().values()):
            values.flags.writeable = False  # shared: nobody changes it in place
        _SAMPLED[key] = reference
        while len(_SAMPLED) > SAMPLED_KEPT:
            _SAMPLED.popitem(last=False)
    _SAMPLED.move_to_end(key)
    return _SAMPLED[key]


SAMPLED_KEPT = 4  # references kept sampled (a 100 s one at 1 kHz: 5.6 MB)
_SAMPLED: OrderedDict[str, Sampled] = OrderedDict()


def _built(kind: str, options: Mapping[str, Any], step: float) -> Reference:
    o = options
    registered = reference_kinds().get(kind)
    if registered is not None:
        return registered.build(options, step)
    if kind == "csv":
        ref = read_csv(o["path"], step, o["smoothing_window"])
        return Reference(ref.t - ref.t[0], ref.x, ref.y, ref.vx, ref.vy, ref.ax, ref.ay)
    if kind == "segments":
        return sample(segment_chain(o["start"], o["segments"]), step)
    if kind == "spline":
        return sample(Spline(tuple(map(tuple, o["points"])), o["duration"]), step)
    circle = Circle(tuple(o["centre"]), o["radius"], o["start_angle"], o["turns"],
                    o["duration" if kind == "circle" else "circle_duration"])
    if kind == "circle":
        return sample(circle, step)
    line = Line(tuple(o["start"]), tuple(circle.start), o["line_duration"])
    return sample(Chain((line, circle)), step)


class SegmentError(InputError):
    """A segment of a `segments` reference that cannot be built; `index` says which."""

    def __init__(self, index: int, message: str) -> None:
        super().__init__(message)
        self.index = index


def segment_chain(start: tuple[float, float], segments: Sequence[Mapping[str, Any]]
                  ) -> Chain:
    """The checked segment tables of a `segments` reference as one Chain from `start`."""
    point, pieces = (float(start[0]), float(start[1])), []
    for k, spec in enumerate(segments):
        try:
            piece = _segment(point, spec)
        except ValueError as error:
            raise SegmentError(k, str(error)) from None
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
        return Circle(tuple(centre), radius, math.atan2(dy, dx), spec["turns"],
                                 duration)
    return Spline((point, *map(tuple, spec["points"])), duration)
