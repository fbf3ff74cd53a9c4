"""The trajectory sets that data collection runs (thesis, sec. 4.3), as plain data.

Each trajectory is a name, a split, a [reference] table that cosim.config.parse_config
accepts, the plant variant and its noise seed, drawn from seeded numpy Generators so the sets
are the same on every machine. `sim`: 44 training circles and splines and the thesis's 4 test
trajectories on the nominal plant. `hardware`: the thesis's sec. 4.3.3 protocol, 60 training
and 10 test trajectories. R_MAX stays inside the workspace to keep the currents clear of
their limit. `draws` repeats the training protocol for more data; the test split stays.

Docs: "Learning", section The data (docs/explanation/learning.md).
"""

from __future__ import annotations

import math
from collections.abc import Iterator, Mapping
from dataclasses import dataclass, replace
from typing import Any

import numpy as np

from flexff.fmu.defaults import DEFAULT_STEP
from flexff.fmu.errors import InputError
from flexff.learning.dataset import SETS
from flexff.plant.paths import Spline

R_MIN = 0.007  # m: smallest circle radius (seed)
R_MAX = 0.045  # m: largest radius any training trajectory reaches (docs: Learning, The data)
SPLINE_POINT_RADIUS = 0.04  # m: spline points are drawn inside this disc
MIN_CHORD = 0.006  # m: consecutive spline points (and the last and first) at least this apart
ANGLES = 8  # training start angles: multiples of 2 pi / ANGLES
SEEDS = {"sim": 431, "hardware": 433}  # one root seed per set (after the thesis's sections)

# sim: the thesis's sec. 4.3.1 and fig. 4.3c
SIM_DURATION = 15.0
SIM_LINE, SIM_REST, SIM_CIRCLE = 2.5, 0.5, 12.0
SIM_CIRCLES, SIM_LINE_CIRCLES, SIM_SPLINES = 20, 10, 14
SIM_FREQUENCY = (1.0 / 15.0, 1.0)  # Hz: 1 to 15 turns in 15 s
SIM_TEST_CIRCLES = ((0.01, 0.93, math.pi / 8, 1), (0.043, 0.367, 0.0, 1),
                    (0.02761, 0.632, 5 * math.pi / 8, 1))  # radius, Hz, start angle, direction

# hardware: the thesis's sec. 4.3.3
HW_DURATION = 100.0
HW_LINE, HW_REST, HW_MOTION, HW_END = 21.0, 1.0, 75.0, 3.0
HW_CIRCLES, HW_SPLINES, HW_TEST_SPLINES = 39, 21, 4
HW_FREQUENCY = (1.0 / 75.0, 22.0 / 75.0)  # Hz: 1 to 22 turns in 75 s
HW_LAPS = (1, 10)
HW_TEST_CIRCLES = ((0.066, 0.0125), (0.08, 0.0275), (0.09, 0.0175), (0.106, 0.0225),
                   (0.265, 0.015), (0.28, 0.025))  # Hz, radius


@dataclass(frozen=True)
class TrajectorySpec:
    """One trajectory to collect: `reference` is a [reference] table for parse_config."""

    name: str
    split: str  # "train" or "test"
    reference: Mapping[str, Any]
    variant: str
    seed: int


@dataclass(frozen=True)
class TrajectorySet:
    """A named set of trajectories of equal `duration` [s], run at `step` and saved every
    `decimation`-th sample."""

    name: str
    variant: str
    duration: float
    decimation: int
    trajectories: tuple[TrajectorySpec, ...]
    step: float = DEFAULT_STEP

    @property
    def sample_rate_hz(self) -> int:
        """The rate of the saved signals [Hz]."""
        return round(1.0 / (self.step * self.decimation))


def trajectory_set(name: str, draws: int = 1) -> TrajectorySet:
    """The trajectory set `name` ('sim' or 'hardware').

    `draws` > 1 draws the set's training protocol that many times: the first draw and the
    test split are the set itself, draw j adds training trajectories named '<name>-draw<j>'
    from generators of their own (more data of the same kind).
    """
    builders = {"sim": _sim_set, "hardware": _hardware_set}
    if name not in builders:
        raise InputError(f"unknown trajectory set {name!r}: choose one of {', '.join(SETS)}")
    if isinstance(draws, bool) or not isinstance(draws, int) or draws < 1:
        raise InputError(f"draws must be a whole number of at least 1, got {draws!r}")
    base = builders[name](0)
    extra = [replace(t, name=f"{t.name}-draw{j}") for j in range(1, draws)
             for t in builders[name](j).trajectories if t.split == "train"]
    train = [t for t in base.trajectories if t.split == "train"]
    test = [t for t in base.trajectories if t.split == "test"]
    return replace(base, trajectories=tuple(train + extra + test))


# -- sets -------------------------------------------------------------------------------------
def _sim_set(draw: int) -> TrajectorySet:
    streams = _streams("sim", draw)
    circles = _stratified(next(streams), SIM_CIRCLES + SIM_LINE_CIRCLES, SIM_FREQUENCY)
    train = []
    for k, (frequency, radius, angle, direction) in enumerate(circles):
        if k < SIM_CIRCLES:
            train.append((f"circle-{k:02d}", _circle(radius, angle,
                                                     direction * frequency * SIM_DURATION)))
        else:
            train.append((f"line-circle-{k - SIM_CIRCLES:02d}", _line_circle(
                radius, angle, direction * frequency * SIM_CIRCLE)))
    spline_rng = next(streams)
    for k in range(SIM_SPLINES):
        points = _spline_points(spline_rng, int(spline_rng.integers(4, 7)))
        laps = int(spline_rng.integers(1, 4))
        train.append((f"spline-{k:02d}", _spline_laps(points, laps, SIM_DURATION)))
    test = [(f"test-circle-{k:02d}", _circle(radius, angle, direction * frequency * SIM_DURATION))
            for k, (radius, frequency, angle, direction) in enumerate(SIM_TEST_CIRCLES)]
    test_rng = next(streams)
    test.append(("test-spline-00", _spline_laps(_spline_points(test_rng, 5), 2,
                                                SIM_DURATION)))
    return _assemble("sim", "nominal", SIM_DURATION, 1, train, test, next(streams))


def _hardware_set(draw: int) -> TrajectorySet:
    streams = _streams("hardware", draw)
    train = [(f"circle-{k:02d}", _hardware_circle(radius, angle, direction * frequency * HW_MOTION))
             for k, (frequency, radius, angle, direction) in enumerate(
                 _stratified(next(streams), HW_CIRCLES, HW_FREQUENCY))]
    spline_rng = next(streams)
    for k in range(HW_SPLINES):
        train.append((f"spline-{k:02d}", _hardware_spline(spline_rng)))
    test = [(f"test-circle-{k:02d}", _hardware_circle(
        radius, (2 * k + 1) * math.pi / ANGLES, (-1) ** k * frequency * HW_MOTION))
        for k, (frequency, radius) in enumerate(HW_TEST_CIRCLES)]
    test_rng = next(streams)
    test += [(f"test-spline-{k:02d}", _hardware_spline(test_rng)) for k in range(HW_TEST_SPLINES)]
    return _assemble("hardware", "hardware", HW_DURATION, 10, train, test, next(streams))


def _assemble(name: str, variant: str, duration: float, decimation: int,
              train: list[tuple[str, dict[str, Any]]], test: list[tuple[str, dict[str, Any]]],
              seed_rng: np.random.Generator) -> TrajectorySet:
    labelled = [(n, "train", r) for n, r in train] + [(n, "test", r) for n, r in test]
    seeds = seed_rng.integers(1, 2**31 - 1, size=len(labelled))
    specs = tuple(TrajectorySpec(n, split, r, variant, int(s))
                  for (n, split, r), s in zip(labelled, seeds))
    return TrajectorySet(name, variant, duration, decimation, specs)


def _streams(set_name: str, draw: int) -> Iterator[np.random.Generator]:
    """Independent generators, one per part of a set, so that parts do not shift each other;
    draw 0 is the set itself, each later draw has generators of its own."""
    k = 0
    while True:
        yield np.random.default_rng([SEEDS[set_name], k] + ([draw] if draw else []))
        k += 1


# -- circles ----------------------------------------------------------------------------------
def _stratified(rng: np.random.Generator, n: int, frequency: tuple[float, float]
                ) -> list[tuple[float, float, float, int]]:
    """n circles (mean frequency [Hz], radius [m], start angle [rad], direction): frequency and
    radius each fall once into each of n equal strata of their range, paired at random."""
    def strata(low: float, high: float) -> np.ndarray:
        return low + (high - low) * (rng.permutation(n) + rng.uniform(size=n)) / n

    frequencies, radii = strata(*frequency), strata(R_MIN, R_MAX)
    angles = rng.integers(ANGLES, size=n) * 2 * math.pi / ANGLES
    directions = rng.permutation(np.resize([1, -1], n))
    return [(float(f), round(float(r), 4), float(a), int(d))
            for f, r, a, d in zip(frequencies, radii, angles, directions)]


def _circle(radius: float, angle: float, turns: float) -> dict[str, Any]:
    return {"kind": "circle", "centre": [0.0, 0.0], "radius": radius, "start_angle": angle,
            "turns": round(turns, 3), "duration": SIM_DURATION}


def _on_circle(radius: float, angle: float) -> list[float]:
    """The point at `angle` on the circle about the centre (to 1e-12 m: no -1e-18 zeros)."""
    return [round(radius * math.cos(angle), 12) + 0.0, round(radius * math.sin(angle), 12) + 0.0]


def _line_circle(radius: float, angle: float, turns: float) -> dict[str, Any]:
    return {"kind": "segments", "start": [0.0, 0.0], "segments": [
        {"kind": "line", "to": _on_circle(radius, angle), "duration": SIM_LINE},
        {"kind": "hold", "duration": SIM_REST},
        {"kind": "circle", "centre": [0.0, 0.0], "turns": round(turns, 3),
         "duration": SIM_CIRCLE}]}


def _hardware_run(to: list[float], motion: list[dict[str, Any]]) -> dict[str, Any]:
    """The hardware protocol: line from the centre, rest, the motion, rest."""
    return {"kind": "segments", "start": [0.0, 0.0], "segments": [
        {"kind": "line", "to": to, "duration": HW_LINE}, {"kind": "hold", "duration": HW_REST},
        *motion, {"kind": "hold", "duration": HW_END}]}


def _hardware_circle(radius: float, angle: float, turns: float) -> dict[str, Any]:
    return _hardware_run(_on_circle(radius, angle), [
        {"kind": "circle", "centre": [0.0, 0.0], "turns": round(turns, 3),
         "duration": HW_MOTION}])


# -- splines ----------------------------------------------------------------------------------
def _spline_points(rng: np.random.Generator, n: int) -> list[list[float]]:
    """n points (0.1 mm grid) inside SPLINE_POINT_RADIUS whose closed spline stays within
    R_MAX and whose consecutive points are MIN_CHORD apart; drawn again until they are."""
    while True:
        radius = SPLINE_POINT_RADIUS * np.sqrt(rng.uniform(size=n))
        angle = rng.uniform(0.0, 2 * math.pi, size=n)
        points = np.round(np.column_stack([radius * np.cos(angle), radius * np.sin(angle)]), 4)
        chords = np.hypot(*(np.roll(points, -1, axis=0) - points).T)
        if chords.min() < MIN_CHORD:
            continue
        try:
            path = Spline(tuple(map(tuple, points)), 1.0)  # the shape does not depend on time
        except ValueError:  # leaves the workspace
            continue
        xy = path.evaluate(np.linspace(0.0, 1.0, 4001))[:2]
        if np.hypot(*xy).max() <= R_MAX:
            coordinates: list[list[float]] = points.tolist()
            return coordinates


def _laps(points: list[list[float]], laps: int, duration: float) -> list[dict[str, Any]]:
    """Spline segments: `laps` laps in `duration` of the closed spline through `points`, from
    the first of them (each segment passes through the current point, then the others)."""
    return [{"kind": "spline", "points": points[1:], "duration": duration / laps}
            for _ in range(laps)]


def _spline_laps(points: list[list[float]], laps: int, duration: float) -> dict[str, Any]:
    return {"kind": "segments", "start": points[0], "segments": _laps(points, laps, duration)}


def _hardware_spline(rng: np.random.Generator) -> dict[str, Any]:
    points = _spline_points(rng, int(rng.integers(4, 7)))
    laps = int(rng.integers(HW_LAPS[0], HW_LAPS[1] + 1))
    return _hardware_run(points[0], _laps(points, laps, HW_MOTION))
