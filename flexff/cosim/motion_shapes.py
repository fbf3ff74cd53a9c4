"""Rest-to-rest motion shapes of one axis with analytic velocity, acceleration and jerk.

Each shape is a displacement from its start over `duration` seconds, evaluated at local times
as a (4, n) array (position, velocity, acceleration, jerk), at rest at both ends, and planned
so that its peaks stay within `share` of an axis's Limits: the skew-sine move (the thesis's
line, eq. 4.2), the bang-bang move (piecewise-constant acceleration, or jerk where the axis
has a jerk limit: robot identification's trapezoidal and S-curve velocity profiles) and a
clamped quintic spline through intermediate points, scaled in time. Any of them can be slowed
down to a longer duration (Stretched: synchronised moves). learning.excitation chains them
into a machine's excitation, cosim.axis_references into the reference kinds of any axes.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING, Protocol

import numpy as np

from flexff.cosim.machine import Limits

if TYPE_CHECKING:  # SciPy loads with the splines that use it
    from scipy.interpolate import BSpline

SPLINE_PEAK_GRID = 20001  # points per spline on which its peaks are found


class Shape(Protocol):
    """A rest-to-rest displacement over `duration` seconds."""

    @property
    def duration(self) -> float: ...

    def __call__(self, t: np.ndarray) -> np.ndarray: ...


def skew_sine_time(distance: float, limits: Limits, share: float) -> float:
    """The shortest skew-sine move over `distance` whose peaks are at most `share` of the
    limits: peak |v| = 2 d / T, |a| = 2 pi d / T^2, |j| = 4 pi^2 d / T^3."""
    return max(_bound_times(abs(distance), limits, share, 2.0, 2 * math.pi, 4 * math.pi**2))


def binding_limit(distance: float, limits: Limits, share: float = 1.0) -> str:
    """Which of velocity, acceleration, jerk sets the skew-sine move's time over `distance`."""
    times = _bound_times(abs(distance), limits, share, 2.0, 2 * math.pi, 4 * math.pi**2)
    return ("velocity", "acceleration", "jerk")[int(np.argmax(times))]


def _bound_times(distance: float, limits: Limits, share: float, v: float, a: float, j: float
                 ) -> list[float]:
    """The durations a shape of unit-time peaks distance * (v, a, j) needs per limit."""
    times = [v * distance / (share * limits.velocity),
             math.sqrt(a * distance / (share * limits.acceleration))]
    if limits.jerk is not None:
        times.append((j * distance / (share * limits.jerk)) ** (1 / 3))
    return times


@dataclass(frozen=True)
class SkewSine:
    """The skew-sine move over `distance` in `duration` s."""

    distance: float
    duration: float

    def __call__(self, t: np.ndarray) -> np.ndarray:
        w = 2 * math.pi / self.duration
        phase = w * t
        d = self.distance / self.duration
        return np.array([self.distance * t / self.duration - d * np.sin(phase) / w,
                         d * (1 - np.cos(phase)), d * w * np.sin(phase),
                         d * w * w * np.cos(phase)])


@dataclass(frozen=True)
class PiecewiseJerk:
    """Segments of constant jerk: (length [s], acceleration at its start, jerk); velocity and
    position integrate continuously from rest (the acceleration may step between segments)."""

    segments: tuple[tuple[float, float, float], ...]

    @property
    def duration(self) -> float:
        return sum(s[0] for s in self.segments)

    def __call__(self, t: np.ndarray) -> np.ndarray:
        t = np.clip(t, 0.0, self.duration)  # a time past the end by rounding is the end
        out = np.zeros((4, t.size))
        start, x, v = 0.0, 0.0, 0.0
        for k, (length, a, j) in enumerate(self.segments):
            # the last segment takes the rest: from Python 3.12, sum() in duration rounds
            # otherwise than `start` adds up, so the end may lie an ulp past start + length
            last = k == len(self.segments) - 1
            mine = (t >= start) if last else (t >= start) & (t < start + length)
            u = t[mine] - start
            out[:, mine] = [x + v * u + a * u**2 / 2 + j * u**3 / 6, v + a * u + j * u**2 / 2,
                            a + j * u, np.full(u.size, j)]
            x, v = (x + v * length + a * length**2 / 2 + j * length**3 / 6,
                    v + a * length + j * length**2 / 2)
            start += length
        return out


@dataclass(frozen=True)
class Stretched:
    """`shape` slowed down to last `duration` s (at least its own): velocity, acceleration and
    jerk shrink by the ratio to the power 1, 2, 3, so it stays within the limits it kept."""

    shape: Shape
    duration: float

    def __call__(self, t: np.ndarray) -> np.ndarray:
        ratio = self.shape.duration / self.duration
        slowed: np.ndarray = self.shape(t * ratio) * ratio ** np.arange(4)[:, None]
        return slowed


def bang_bang(distance: float, limits: Limits, share: float) -> PiecewiseJerk:
    """The fastest move over `distance` at `share` of the limits: +a, coast, -a (trapezoidal
    velocity), or where the axis has a jerk limit the seven-segment S-curve (+j, 0, -j, coast,
    -j, 0, +j) with the acceleration ramped at that jerk."""
    d, sign = abs(distance), math.copysign(1.0, distance)
    v_max, a_max = share * limits.velocity, share * limits.acceleration
    if limits.jerk is None:
        ramp = min(v_max / a_max, math.sqrt(d / a_max))
        coast = (d - a_max * ramp**2) / (a_max * ramp)
        return PiecewiseJerk(((ramp, sign * a_max, 0.0), (coast, 0.0, 0.0),
                              (ramp, -sign * a_max, 0.0)))
    j_max = share * limits.jerk
    peak_a = min(a_max, math.sqrt(v_max * j_max))  # the velocity reached while ramping
    peak_v = v_max
    if d < peak_v * (peak_v / peak_a + peak_a / j_max):  # too short to coast: a lower peak
        peak_v = peak_a / 2 * (math.sqrt((peak_a / j_max) ** 2 + 4 * d / peak_a)
                               - peak_a / j_max)
        if peak_v < peak_a**2 / j_max:  # too short to hold the acceleration: a triangle
            ramp = (d / (2 * j_max)) ** (1 / 3)
            peak_a, peak_v = j_max * ramp, j_max * ramp**2
    ramp = peak_a / j_max
    hold = max(peak_v / peak_a - ramp, 0.0)
    coast = max(d / peak_v - (2 * ramp + hold), 0.0)
    a, j = sign * peak_a, sign * j_max
    return PiecewiseJerk(((ramp, 0.0, j), (hold, a, 0.0), (ramp, a, -j), (coast, 0.0, 0.0),
                          (ramp, 0.0, -j), (hold, -a, 0.0), (ramp, -a, j)))


@dataclass(frozen=True)
class QuinticSpline:
    """A clamped quintic spline (velocity and acceleration zero at both ends) from 0 through
    `points` (displacements), knots spaced by the distance between points, run in `duration`."""

    spline: BSpline  # over unit time
    duration: float

    def __call__(self, t: np.ndarray) -> np.ndarray:
        u = t / self.duration
        return np.array([self.spline(u, nu) / self.duration**nu for nu in range(4)])


def quintic_spline(points: Sequence[float] | np.ndarray, limits: Limits, share: float
                   ) -> QuinticSpline:
    """The spline through `points`, scaled in time to reach `share` of the binding limit."""
    from scipy.interpolate import make_interp_spline

    values = np.concatenate([[0.0], np.asarray(points, dtype=float)])
    steps = np.abs(np.diff(values))
    knots = np.concatenate([[0.0], np.cumsum(steps + 0.1 * steps.mean())])
    rest = [(1, 0.0), (2, 0.0)]
    # SciPy takes (order, value) pairs as documented; its type stubs know only named kinds
    spline = make_interp_spline(knots / knots[-1], values, k=5,
                                bc_type=(rest, rest))  # type: ignore[arg-type]
    grid = np.linspace(0.0, 1.0, SPLINE_PEAK_GRID)
    v, a, j = (float(np.abs(spline(grid, nu)).max()) for nu in (1, 2, 3))
    scale = [v / (share * limits.velocity), math.sqrt(a / (share * limits.acceleration))]
    if limits.jerk is not None:
        scale.append((j / (share * limits.jerk)) ** (1 / 3))
    return QuinticSpline(spline, max(scale))


def spline_extent(shape: QuinticSpline) -> tuple[float, float]:
    """The lowest and highest displacement the spline reaches between its points."""
    x = shape.spline(np.linspace(0.0, 1.0, SPLINE_PEAK_GRID))
    return float(x.min()), float(x.max())
