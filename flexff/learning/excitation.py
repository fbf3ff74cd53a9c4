"""Excitation for any machine: reference trajectories per axis within its description's limits,
and the CSV tables a loop reads them from (learning.machine_loop.on_references).

Classes, each with analytic derivatives (cosim.motion_shapes, cosim.axis_references): "moves"
(skew-sine moves between random points, rests between), "bang-bang" (trapezoidal or S-curve
velocity), "spline" (quintic splines through random points), "multisine"; on request "sine",
"random" (a smooth random path), "rest" and "solo" (one axis in turn moves: the coupling
alone). Every trajectory starts where the loop rests (`starts`, default the range's centre)
and ends at rest: moves chain from there, the sine kinds lead to the centre first. Peaks are
a random share of the limits; each axis draws from its own generator, train and test from
streams apart; synchronised moves start and end together. Limits no move fits are refused
with the key at fault (check_limits).

Docs: "Your own machine" (docs/tutorials/own-machine.md).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from flexff.cosim.axis_references import (
    lead_in,
    multisine_shape,
    natural_frequency,
    sine,
    smooth_random,
)
from flexff.cosim.config_error import ConfigError
from flexff.cosim.csv_text import TIME
from flexff.cosim.machine import Limits, Machine
from flexff.cosim.motion_shapes import (
    Shape,
    SkewSine,
    Stretched,
    bang_bang,
    binding_limit,
    quintic_spline,
    skew_sine_time,
    spline_extent,
)
from flexff.cosim.recording import atomic_write

CLASSES = ("moves", "bang-bang", "spline", "multisine")  # the default set's classes, in turn
EVERY_CLASS = (*CLASSES, "sine", "random", "rest", "solo")
SHARE = (0.3, 0.9)  # a move's peaks: this share of the limits, drawn uniformly
REST = (0.1, 0.6)  # rests between moves [s], drawn uniformly
MARGIN = 0.95  # of the range used by the moves
MIN_STROKE = 0.2  # of the used range: the shortest move drawn
MIN_REACH = 0.1  # a move across the range must reach this share of velocity and acceleration
SPLINE_POINTS = (2, 4)  # points a spline passes through after its start
SPLINE_TRIES = 20  # draws of a spline's points that overshoot the range before a single point
FILL_TRIES = 3  # draws of a move that does not fit the time left before the axis rests
LEAD_SHARE = 0.5  # of the limits: the move from where the loop rests to a sine's centre
FREQUENCY_SHARE = (0.1, 1.0)  # a sine's frequency, a random path's bandwidth: this share of
# the frequency where the range's amplitude meets the limits (natural_frequency), uniformly
PHASE_SAMPLES = 5  # samples a bang-bang phase lasts at least (_resolved)
MOVE_SAMPLES = 20  # samples a move lasts at least


@dataclass(frozen=True, eq=False)
class Excitation:
    """One trajectory of a machine: its name, split, class and every axis's reference
    signals (`<axis>_ref`, `v<axis>_ref`, `a<axis>_ref`, `j<axis>_ref`) at `time` [s]."""

    name: str
    split: str
    kind: str
    time: np.ndarray
    signals: dict[str, np.ndarray]
    machine: Machine

    @property
    def duration(self) -> float:
        return float(self.time[-1] - self.time[0])


def excitation_set(machine: Machine, n_train: int, n_test: int, duration: float,
                   rate_hz: float, seed: int = 0, classes: Sequence[str] = CLASSES,
                   origin: str = "machine", synchronised: bool = False,
                   starts: Sequence[float] | None = None) -> list[Excitation]:
    """`n_train` + `n_test` trajectories of `duration` s sampled at `rate_hz`, the classes in
    turn, every axis its own independent trajectory (or, `synchronised`, moves that start
    and end together on every axis) from its position in `starts` (default its range's
    centre); the same for the same seed, the test split from generators of its own (it does
    not change with `n_train`). Errors name `origin` (the description's file) and the key."""
    _check_request(n_train, n_test, duration, rate_hz, seed, classes)
    check_limits(machine, duration, origin)
    t = np.arange(round(duration * rate_hz) + 1) / rate_hz
    limits = [axis.limits for axis in machine.axes]
    origins = list(starts) if starts is not None else [0.5 * (lim.low + lim.high)
                                                       for lim in limits]
    out = []
    for split, count, stream, prefix in (("train", n_train, 0, ""), ("test", n_test, 1, "test-")):
        for k in range(count):
            kind = classes[k % len(classes)]
            rngs = [np.random.default_rng([seed, stream, k, a]) for a in range(len(limits))]
            if kind == "solo":
                moving = k // len(classes) % len(limits)  # the solos' turn
                motions = [trajectories("moves" if a == moving else "rest", [lim], t, [rng],
                                        starts=[start])[0]
                           for a, (lim, rng, start) in enumerate(zip(limits, rngs, origins))]
            else:
                motions = trajectories(kind, limits, t, rngs, synchronised, origins)
            signals: dict[str, np.ndarray] = {}
            for axis, values in zip(machine.axes, motions):
                signals.update(zip((axis.reference, *axis.derivatives), values))
            out.append(Excitation(f"{prefix}{kind}-{k:03d}", split, kind, t, signals, machine))
    return out


def trajectories(kind: str, limits: Sequence[Limits], t: np.ndarray,
                 rngs: Sequence[np.random.Generator], synchronised: bool = False,
                 starts: Sequence[float] | None = None) -> list[np.ndarray]:
    """Position, velocity, acceleration and jerk (4, n) of each axis's trajectory of class
    `kind` at the times `t` (from 0), from `starts` (default the ranges' centres), each axis
    drawing from its own generator; moves `synchronised` last as long as the slowest axis's
    (the others slowed down)."""
    limits = [_resolved(lim, float(t[1] - t[0])) for lim in limits]
    origins = list(starts) if starts is not None else [0.5 * (lim.low + lim.high)
                                                       for lim in limits]
    if kind in ("multisine", "sine", "random"):
        return [lead_in(start, lim, t, LEAD_SHARE, _body(kind, lim, rng))
                for start, lim, rng in zip(origins, limits, rngs)]
    if kind == "rest":
        return [_held(start, t) for start in origins]
    draws = [_draw(kind, lim) for lim in limits]
    if synchronised:
        return _chained(origins, t, rngs, draws)
    return [_chained([start], t, [rng], [draw])[0]
            for start, rng, draw in zip(origins, rngs, draws)]


def _body(kind: str, limits: Limits, rng: np.random.Generator
          ) -> Callable[[np.ndarray], np.ndarray]:
    """A sine-like class's motion about the range's centre (cosim.axis_references), at a
    random share of the limits, drawn when called on its times (from 0)."""
    def multisine(t: np.ndarray) -> np.ndarray:
        return multisine_shape(limits, t, rng) * _share(rng)

    def one_sine(t: np.ndarray) -> np.ndarray:
        natural = natural_frequency(limits, 0.5 * (_band(limits)[1] - _band(limits)[0]))
        return sine(limits, t, _share(rng), natural * float(rng.uniform(*FREQUENCY_SHARE)))

    def random_path(t: np.ndarray) -> np.ndarray:
        natural = natural_frequency(limits, 0.5 * (_band(limits)[1] - _band(limits)[0]))
        return smooth_random(limits, t, rng, _share(rng),
                             natural * float(rng.uniform(*FREQUENCY_SHARE)))

    bodies = {"multisine": multisine, "sine": one_sine, "random": random_path}
    return bodies[kind]


Draw = Callable[[float, np.random.Generator], Shape]


def _draw(kind: str, limits: Limits) -> Draw:
    """How a move of class `kind` is drawn from a position on an axis with `limits`."""
    draws: dict[str, Draw] = {
        "moves": lambda x, r: _skew_sine_move(limits, x, r),
        "bang-bang": lambda x, r: bang_bang(_target(limits, x, r) - x, limits, _share(r)),
        "spline": lambda x, r: _spline_move(limits, x, r)}
    return draws[kind]


def _chained(starts: Sequence[float], t: np.ndarray, rngs: Sequence[np.random.Generator],
             draws: Sequence[Draw]) -> list[np.ndarray]:
    """Moves drawn one after the other from `starts`, each after a rest (the first axis's
    generator draws the rests), every axis's move slowed down to the longest one, until the
    next does not fit before the last rest."""
    out = [_held(start, t) for start in starts]
    positions = list(starts)
    begin, end = float(rngs[0].uniform(*REST)), float(t[-1]) - REST[0]
    while True:
        for _ in range(FILL_TRIES):
            shapes = [draw(x, rng) for draw, x, rng in zip(draws, positions, rngs)]
            duration = max(*(shape.duration for shape in shapes),
                           MOVE_SAMPLES * float(t[1] - t[0]))
            if begin + duration <= end:
                break
        else:
            return out
        local = t - begin
        during, after = (local >= 0) & (local <= duration), local > duration
        for a, shape in enumerate(shapes):
            stretched = shape if shape.duration == duration else Stretched(shape, duration)
            out[a][:, during] = stretched(local[during])
            out[a][0, during] += positions[a]
            positions[a] += float(shape(np.array([shape.duration]))[0, 0])
            out[a][0, after] = positions[a]
            out[a][1:, after] = 0.0
        begin += duration + float(rngs[0].uniform(*REST))


def _held(position: float, t: np.ndarray) -> np.ndarray:
    """At rest at `position` at the times `t`: (4, n)."""
    return np.vstack([np.full(t.size, position), np.zeros((3, t.size))])


def _resolved(limits: Limits, step: float) -> Limits:
    """The limits the moves keep at the sampling `step`: an acceleration reached no faster
    than in PHASE_SAMPLES steps from zero to the velocity, a jerk likewise to it, so that the
    samples show every phase of a move (a shorter one would fall between them)."""
    acceleration = min(limits.acceleration, limits.velocity / (PHASE_SAMPLES * step))
    jerk = None if limits.jerk is None else min(limits.jerk,
                                                acceleration / (PHASE_SAMPLES * step))
    return replace(limits, acceleration=acceleration, jerk=jerk)


def _band(limits: Limits) -> tuple[float, float]:
    """The part of the range the moves use (MARGIN of it, about the centre)."""
    centre, half = 0.5 * (limits.low + limits.high), 0.5 * MARGIN * (limits.high - limits.low)
    return centre - half, centre + half


def _share(rng: np.random.Generator) -> float:
    return float(rng.uniform(*SHARE))


def _target(limits: Limits, position: float, rng: np.random.Generator) -> float:
    """A random point of the band at least MIN_STROKE of it away from `position`."""
    low, high = _band(limits)
    while True:
        target = float(rng.uniform(low, high))
        if abs(target - position) >= MIN_STROKE * (high - low):
            return target


def _skew_sine_move(limits: Limits, position: float, rng: np.random.Generator) -> SkewSine:
    distance = _target(limits, position, rng) - position
    return SkewSine(distance, skew_sine_time(distance, limits, _share(rng)))


def _spline_move(limits: Limits, position: float, rng: np.random.Generator) -> Shape:
    """A spline through 2-4 random points of the band, drawn again while it overshoots the
    band or moves less than MIN_STROKE; after SPLINE_TRIES draws one point (no overshoot)."""
    low, high = _band(limits)
    share = _share(rng)
    for _ in range(SPLINE_TRIES):
        points = rng.uniform(low, high, int(rng.integers(SPLINE_POINTS[0], SPLINE_POINTS[1] + 1)))
        shape = quintic_spline(points - position, limits, share)
        lowest, highest = spline_extent(shape)
        if position + lowest >= low and position + highest <= high \
                and max(-lowest, highest) >= MIN_STROKE * (high - low):
            return shape
    return quintic_spline([_target(limits, position, rng) - position], limits, share)


def check_limits(machine: Machine, duration: float, origin: str = "machine") -> None:
    """Refuse an axis whose limits no move fits, naming the key: a move over MIN_STROKE of
    the range longer than `duration` (its binding limit), or limits that a move across the
    whole range cannot come near (MIN_REACH: a jerk too low for the acceleration, a range
    too short for the velocity; often a unit slip)."""
    for k, axis in enumerate(machine.axes):
        limits, unit, key = axis.limits, axis.unit, f"machine.axis[{k}]"
        low, high = _band(limits)
        stroke = MIN_STROKE * (high - low)
        shortest = skew_sine_time(stroke, limits, 1.0)
        if shortest + 2 * REST[0] > duration:
            name = binding_limit(stroke, limits)
            raise ConfigError(origin, f"{key}.{name}", (
                f"a move over {MIN_STROKE:.0%} of the range ({stroke:.3g} {unit}) takes "
                f"{shortest:.3g} s at this {name}, longer than the {duration:g} s trajectory: "
                f"raise {name} or the duration"))
        across = skew_sine_time(high - low, limits, 1.0)
        acceleration = 2 * math.pi * (high - low) / across**2
        if binding_limit(high - low, limits) == "jerk" \
                and acceleration < MIN_REACH * limits.acceleration:
            raise ConfigError(origin, f"{key}.jerk", (
                f"{limits.jerk:g} {unit}/s^3 is so low that a move across the range reaches "
                f"{acceleration:.3g} {unit}/s^2, under {MIN_REACH:.0%} of the acceleration "
                f"{limits.acceleration:g}: raise jerk or lower acceleration"))
        velocity = 2 * (high - low) / across
        if velocity < MIN_REACH * limits.velocity:
            raise ConfigError(origin, f"{key}.range", (
                f"{limits.low:g} .. {limits.high:g} {unit} is too short for these limits: a "
                f"move across it reaches {velocity:.3g} {unit}/s, under {MIN_REACH:.0%} of the "
                f"velocity {limits.velocity:g}: widen the range or lower velocity (units?)"))


def _check_request(n_train: int, n_test: int, duration: float, rate_hz: float, seed: int,
                   classes: Sequence[str]) -> None:
    """Refuse a set request that is not whole counts, a positive duration and rate, a seed
    and known classes, naming the argument."""
    def whole(value: object, least: int) -> bool:
        return isinstance(value, int) and not isinstance(value, bool) and value >= least

    def positive(value: object) -> bool:
        return isinstance(value, int | float) and not isinstance(value, bool) \
            and math.isfinite(value) and value > 0

    unknown = [c for c in classes if c not in EVERY_CLASS]
    problems = {
        "classes": (unknown or not classes, f"{list(classes)}: choose among "
                    f"{', '.join(EVERY_CLASS)}"),
        "n_train": (not whole(n_train, 1), f"{n_train!r}: give at least one"),
        "n_test": (not whole(n_test, 0), f"{n_test!r}: give a whole number, 0 or more"),
        "seed": (not whole(seed, 0), f"{seed!r}: give a whole number, 0 or more"),
        "duration": (not positive(duration), f"{duration!r}: give a positive number of s"),
        "rate_hz": (not positive(rate_hz) or (positive(duration) and duration * rate_hz < 2),
                    f"{rate_hz!r}: give a positive rate with at least two samples in the "
                    f"duration"),
    }
    for name, (wrong, message) in problems.items():
        if wrong:
            raise ConfigError("excitation", name, message)


def write_table(excitation: Excitation, path: str | Path) -> Path:
    """The trajectory as a CSV time table (time and its reference signals): a `[[source]]`
    kind = "csv" of a run reads it (learning.machine_loop.on_references)."""
    names = list(excitation.signals)
    data = np.column_stack([excitation.time, *(excitation.signals[n] for n in names)])
    header = ",".join([TIME, *names])
    return atomic_write(path, lambda tmp: np.savetxt(tmp, data, fmt="%.17g", delimiter=",",
                                                     header=header, comments=""))
