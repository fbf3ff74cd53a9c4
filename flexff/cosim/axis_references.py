"""Reference kinds for any machine's axes, within its description's limits: a run's `[reference]`
for a loop with a `[machine]` of any number of axes, and shapes a collection's excitation uses.

Per axis, each kind makes `<axis>_ref` with its analytic velocity, acceleration and jerk, at
rest at both ends, its peaks at most `share` of the axis's limits, its positions in MARGIN of
the range: "point-to-point" (skew-sine moves to `points` or random ones, a `rest` between),
"sine" (at `frequency_hz`, faded in and out), "multisine" (SINES random sines, faded) and
"random" (a quintic spline through random points spaced by 1 / `bandwidth_hz`). Every axis
starts at its `start` (default the centre); the sine kinds and "random" excite about the
centre, led there first by a skew-sine move (lead_in).

Docs: "Run configuration", references for a machine's axes (docs/reference/configuration.md).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from flexff.cosim.machine import Limits, Machine
from flexff.cosim.memory import check_memory
from flexff.cosim.motion_shapes import SkewSine, skew_sine_time
from flexff.fmu.errors import InputError

AXIS_KINDS = ("point-to-point", "sine", "multisine", "random")
AXIS_OPTIONS = {  # the [reference] keys beside kind: every kind's, then each kind's own
    "common": ("duration", "seed", "share", "start"), "point-to-point": ("points", "rest"),
    "sine": ("frequency_hz",), "multisine": (), "random": ("bandwidth_hz",)}
SHARE = 0.8  # of each limit the reference reaches at most, by default
REST = 0.2  # s: point-to-point's hold between moves, by default
MARGIN = 0.95  # of the range a reference uses about its centre
MIN_STROKE = 0.2  # of the used range: the shortest random move
SINES = 4  # a multisine's sines
FADE_PERIODS = 2.0  # a sine fades in and out over this many periods (at most a quarter of it)
SPLINE_ORDER = 5  # the random path's spline: velocity, acceleration and jerk continuous


@dataclass(frozen=True, eq=False)
class AxisReference:
    """A sampled reference of a machine's axes: times [s] and every axis's position,
    velocity, acceleration and jerk by their signal names; `positions` names the positions
    (held after the end, the derivatives then zero)."""

    t: np.ndarray
    columns: Mapping[str, np.ndarray]
    positions: tuple[str, ...]

    @property
    def duration(self) -> float:
        return float(self.t[-1] - self.t[0])

    def signals(self) -> dict[str, np.ndarray]:
        """The reference signals by their co-simulation names."""
        return dict(self.columns)


def build_axis_reference(kind: str, options: Mapping[str, Any], step: float,
                         machine: Machine | None) -> AxisReference:
    """The reference of kind `kind` (AXIS_KINDS) with the checked `options` of a [reference]
    table (duration, seed, share, start and the kind's own; cosim.config) for every axis of
    `machine`, sampled every `step` seconds from 0; InputError naming the option at fault."""
    if machine is None:
        raise InputError(f"a {kind!r} reference is made for the axes of a machine: add a "
                         f"[machine] description (its axes and their limits)")
    names = [a.name for a in machine.axes]
    for key in ("start", "points", "frequency_hz", "bandwidth_hz"):
        given = options.get(key)
        if isinstance(given, Mapping):
            unknown = sorted(set(given) - set(names))
            if unknown:
                raise InputError(f"reference.{key}.{unknown[0]}: the machine has no axis "
                                 f"{unknown[0]!r} (its axes: {', '.join(names)})")
    duration = float(options["duration"])
    n = math.floor(min(duration / step + 1e-9, 2.0**62)) + 1
    check_memory(4 * len(names) * n, f"sampling the {duration:g} s reference of "
                                     f"{len(names)} axes every {step:g} s")
    t = np.arange(n) * step
    columns: dict[str, np.ndarray] = {}
    for k, axis in enumerate(machine.axes):
        rng = np.random.default_rng([int(options.get("seed", 0)), k])
        start = _per_axis(options.get("start"), axis.name)
        motion = axis_motion(kind, axis.limits, t, rng, float(options.get("share", SHARE)),
                             None if start is None else float(start),
                             **{key: _per_axis(options.get(key), axis.name)
                                for key in ("points", "rest", "frequency_hz", "bandwidth_hz")
                                if key in options}, where=f"axis {axis.name}")
        columns.update(zip((axis.reference, *axis.derivatives), motion))
    return AxisReference(t, columns, tuple(a.reference for a in machine.axes))


def _per_axis(value: Any, axis: str) -> Any:
    """An option's value for one axis: its entry of a per-axis table, else the value itself."""
    return value.get(axis) if isinstance(value, Mapping) else value


def axis_motion(kind: str, limits: Limits, t: np.ndarray, rng: np.random.Generator,
                share: float = SHARE, start: float | None = None,
                points: Sequence[float] | None = None, rest: float = REST,
                frequency_hz: float | None = None, bandwidth_hz: float | None = None,
                where: str = "the axis") -> np.ndarray:
    """Position, velocity, acceleration and jerk (4, n) of one axis's reference of `kind` at
    the times `t` (from 0, evenly spaced), from `start` (default the centre)."""
    centre = 0.5 * (limits.low + limits.high)
    origin = centre if start is None else start
    if kind == "point-to-point":
        return point_to_point(limits, t, rng, share, origin, points, rest, where)
    bodies: dict[str, Callable[[np.ndarray], np.ndarray]] = {
        "sine": lambda time: sine(limits, time, share, frequency_hz),
        "multisine": lambda time: multisine_shape(limits, time, rng) * share,
        "random": lambda time: smooth_random(limits, time, rng, share, bandwidth_hz)}
    if kind not in bodies:
        raise InputError(f"{kind!r} is no reference kind of a machine's axes (known: "
                         f"{', '.join(AXIS_KINDS)})")
    return lead_in(origin, limits, t, share, bodies[kind], where)


def lead_in(start: float, limits: Limits, t: np.ndarray, share: float,
            body: Callable[[np.ndarray], np.ndarray], where: str = "the axis") -> np.ndarray:
    """A skew-sine move from `start` to the range's centre at `share` of the limits, then
    `body` (local times from 0 -> (4, m) about 0, at rest at both ends) about the centre for
    the rest of `t`; `body` alone where the axis starts at the centre."""
    centre = 0.5 * (limits.low + limits.high)
    distance = centre - start
    if abs(distance) <= 1e-12 * (limits.high - limits.low):
        out = body(t)
        out[0] += centre
        return out
    step = float(t[1] - t[0])
    samples = math.ceil(skew_sine_time(distance, limits, share) / step - 1e-9)
    if samples + 2 >= t.size:
        raise InputError(f"{where}: the move from its start {start:g} to its range's centre "
                         f"{centre:g} takes {samples * step:.3g} s, not less than the "
                         f"{float(t[-1]):g} s reference: lengthen duration")
    out = np.empty((4, t.size))
    out[:, :samples + 1] = SkewSine(distance, samples * step)(t[:samples + 1])
    out[0, :samples + 1] += start
    rest = body(t[samples:] - t[samples])
    rest[0] += centre
    out[:, samples:] = rest
    return out


def point_to_point(limits: Limits, t: np.ndarray, rng: np.random.Generator, share: float,
                   start: float, points: Sequence[float] | None, rest: float,
                   where: str = "the axis") -> np.ndarray:
    """Skew-sine moves at `share` of the limits from `start` to each of `points` in turn, or
    (None) to random points of the range at least MIN_STROKE of it apart while they fit, a
    `rest` [s] before each and after the last; then held."""
    step = float(t[1] - t[0])
    low, high = _band(limits)
    if points is not None:
        outside = [p for p in points if not limits.low <= p <= limits.high]
        if outside:
            raise InputError(f"{where}: the point {outside[0]:g} lies outside its range "
                             f"{limits.low:g} .. {limits.high:g}")
    out = np.vstack([np.full(t.size, start), np.zeros((3, t.size))])
    pause = round(rest / step)  # samples: every move starts and ends on one
    position, begin, k = start, pause, 0
    while True:
        if points is not None:
            if k == len(points):
                return out
            target = float(points[k])
        else:
            target = _away(low, high, position, rng)
        k += 1
        if target == position:
            continue
        samples = math.ceil(skew_sine_time(target - position, limits, share) / step - 1e-9)
        if begin + samples + pause >= t.size:
            if points is not None:
                raise InputError(f"{where}: the moves to its points take longer than the "
                                 f"{float(t[-1]):g} s reference (at share {share:g} of the "
                                 f"limits, {rest:g} s rests): lengthen duration or give fewer "
                                 f"points")
            return out
        move = slice(begin, begin + samples + 1)
        out[:, move] = SkewSine(target - position, samples * step)(t[move] - t[begin])
        out[0, move] += position
        position = target
        out[0, begin + samples + 1:] = position
        out[1:, begin + samples + 1:] = 0.0
        begin += samples + pause


def sine(limits: Limits, t: np.ndarray, share: float, frequency_hz: float | None = None
         ) -> np.ndarray:
    """A sine about 0 at `frequency_hz` (default: where the band's half-width meets the
    binding limit), faded in and out (fade), scaled to `share` of the tightest bound."""
    half = 0.5 * (_band(limits)[1] - _band(limits)[0])
    frequency = frequency_hz or natural_frequency(limits, half)
    duration = float(t[-1])
    w = 2 * math.pi * frequency
    sines = [w**n * np.sin(w * t + n * math.pi / 2) for n in range(4)]
    return _scaled(_faded(sines, fade(t, min(FADE_PERIODS / frequency, duration / 4))),
                   limits, half, share)


def multisine_shape(limits: Limits, t: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """SINES sines about 0 in the band the limits allow (up to where the band's half-width
    takes the whole acceleration, down to two periods in the duration), faded in and out over
    half the duration each (fade: at rest at both ends, its jerk continuous), scaled so that
    its peaks just reach the tightest bound (share 1)."""
    half = 0.5 * (_band(limits)[1] - _band(limits)[0])
    duration = float(t[-1])
    top = math.sqrt(limits.acceleration / half) / (2 * math.pi)
    frequencies = rng.uniform(min(max(0.1 * top, 2 / duration), top), top, SINES)
    phases = rng.uniform(0, 2 * math.pi, SINES)
    window = fade(t, duration / 2)
    w = 2 * math.pi * frequencies[:, None]
    angle = w * t + phases[:, None]
    sines = [(w**n * np.sin(angle + n * math.pi / 2)).sum(0) for n in range(4)]
    return _scaled(_faded(sines, window), limits, half, 1.0)


def smooth_random(limits: Limits, t: np.ndarray, rng: np.random.Generator, share: float,
                  bandwidth_hz: float | None = None) -> np.ndarray:
    """A smooth random path about 0: a clamped quintic spline (at rest at both ends) through
    random points of the band spaced by 1 / `bandwidth_hz`, scaled to `share` of the
    tightest bound (its position within the band)."""
    from scipy.interpolate import make_interp_spline

    low, high = _band(limits)
    half = 0.5 * (high - low)
    duration = float(t[-1])
    bandwidth = bandwidth_hz or natural_frequency(limits, half)
    count = max(2, round(duration * bandwidth))
    knots = np.linspace(0.0, duration, count + 1)
    values = np.concatenate([[0.0], rng.uniform(-half, half, count - 1), [0.0]])
    rest = [(1, 0.0), (2, 0.0)]
    # SciPy takes (order, value) pairs as documented; its type stubs know only named kinds
    spline = make_interp_spline(knots, values, k=SPLINE_ORDER,
                                bc_type=(rest, rest))  # type: ignore[arg-type]
    return _scaled(np.array([spline(t, nu) for nu in range(4)]), limits, half, share)


def natural_frequency(limits: Limits, half: float) -> float:
    """The frequency at which a sine of amplitude `half` reaches the velocity or the
    acceleration limit, whichever first (the jerk too, where given)."""
    candidates = [limits.velocity / (2 * math.pi * half),
                  math.sqrt(limits.acceleration / half) / (2 * math.pi)]
    if limits.jerk is not None:
        candidates.append((limits.jerk / half) ** (1 / 3) / (2 * math.pi))
    return min(candidates)


def fade(t: np.ndarray, length: float) -> list[np.ndarray]:
    """A window rising from 0 to 1 over `length` s from t = 0 and falling back to 0 over
    `length` s to t[-1], with its first three derivatives: the product of two septic
    smoothsteps (_smoothstep), so that a signal it multiplies is at rest at both ends."""
    duration = float(t[-1])
    rising = np.clip(t / length, 0.0, 1.0)
    falling = np.clip((duration - t) / length, 0.0, 1.0)
    up = [_smoothstep(rising, n) / length**n for n in range(4)]
    down = [_smoothstep(falling, n) * (-1.0 / length) ** n for n in range(4)]
    return list(_faded(up, down))


def _smoothstep(u: np.ndarray, n: int) -> np.ndarray:
    """The n-th derivative (0-3) of the septic smoothstep 35u^4 - 84u^5 + 70u^6 - 20u^7 at `u`
    in [0, 1]: from 0 to 1 with its first three derivatives 0 at both ends, so that a signal
    it fades keeps its jerk continuous."""
    return np.asarray([35 * u**4 - 84 * u**5 + 70 * u**6 - 20 * u**7,
                       140 * u**3 - 420 * u**4 + 420 * u**5 - 140 * u**6,
                       420 * u**2 - 1680 * u**3 + 2100 * u**4 - 840 * u**5,
                       840 * u - 5040 * u**2 + 8400 * u**3 - 4200 * u**4][n])


def _faded(signal: Sequence[np.ndarray], window: Sequence[np.ndarray]) -> np.ndarray:
    """The product window * signal and its first three derivatives (Leibniz's rule)."""
    binomial = ((1,), (1, 1), (1, 2, 1), (1, 3, 3, 1))
    return np.array([sum(b * window[n - m] * signal[m] for m, b in enumerate(binomial[n]))
                     for n in range(4)])


def _scaled(motion: np.ndarray, limits: Limits, half: float, share: float) -> np.ndarray:
    """`motion` (4, n) about 0 scaled so that its position stays within `half` and its
    derivatives within `share` of the limits, the tightest of them reached."""
    bounds = [half, share * limits.velocity, share * limits.acceleration,
              share * limits.jerk if limits.jerk is not None else math.inf]
    peaks = np.abs(motion).max(axis=1)
    scale = min(b / float(p) for b, p in zip(bounds, peaks) if p > 0)
    return np.asarray(motion * scale)


def _band(limits: Limits) -> tuple[float, float]:
    """The part of the range the references use (MARGIN of it, about the centre)."""
    centre, half = 0.5 * (limits.low + limits.high), 0.5 * MARGIN * (limits.high - limits.low)
    return centre - half, centre + half


def _away(low: float, high: float, position: float, rng: np.random.Generator) -> float:
    """A random point of [low, high] at least MIN_STROKE of it away from `position`."""
    while True:
        target = float(rng.uniform(low, high))
        if abs(target - position) >= MIN_STROKE * (high - low):
            return target
