"""Excitation for any machine: reference trajectories per axis within its description's limits,
and the CSV tables a loop reads them from (learning.machine_loop.on_references).

Classes, each with analytic velocity, acceleration and jerk:
- "moves": point-to-point skew-sine moves (the thesis's lines) between random points of the
  range, each as fast as the limits allow times a random share, with rests between;
- "bang-bang": trapezoidal-velocity moves, +a, coast, -a (robot identification's excitation:
  they separate inertia from Coulomb friction); their acceleration steps, so an axis with a
  jerk limit gets skew-sine moves instead;
- "multisine": a sum of sines at random frequencies and phases, scaled into the limits.
An axis whose limits no move fits (a range too short for the velocity and acceleration within
the duration) is refused with the key at fault. Every trajectory starts and ends at rest.
"""

from __future__ import annotations

import functools
import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from flexff.cosim.csv_text import TIME
from flexff.cosim.machine import Axis, Limits, Machine
from flexff.cosim.recording import atomic_write
from flexff.cosim.schema import ConfigError

CLASSES = ("moves", "bang-bang", "multisine")
SHARE = (0.3, 0.9)  # a move's speed: this share of the limits, drawn uniformly
REST = (0.1, 0.6)  # rests between moves [s], drawn uniformly
MARGIN = 0.95  # of the range used by the moves


@dataclass(frozen=True)
class Excitation:
    """One trajectory of a machine: its name, split and every axis's reference signals."""

    name: str
    split: str
    kind: str
    time: np.ndarray
    signals: dict[str, np.ndarray]  # <axis>_ref, v<axis>_ref, a<axis>_ref, j<axis>_ref


def _skew_sine(distance: float, duration: float, t: np.ndarray) -> np.ndarray:
    """Position, velocity, acceleration, jerk (4, n) of a skew-sine move over `duration`."""
    s = np.clip(t / duration, 0.0, 1.0)
    w = 2 * math.pi / duration
    inside = (t >= 0) & (t <= duration)
    return np.array([distance * (s - np.sin(2 * math.pi * s) / (2 * math.pi)),
                     inside * distance / duration * (1 - np.cos(2 * math.pi * s)),
                     inside * distance / duration * w * np.sin(2 * math.pi * s),
                     inside * distance / duration * w * w * np.cos(2 * math.pi * s)])


def _move_time(distance: float, limits: Limits, share: float) -> float:
    """The shortest skew-sine move over `distance` within `share` of the limits."""
    d = abs(distance)
    times = [2 * d / (share * limits.velocity),
             math.sqrt(2 * math.pi * d / (share * limits.acceleration))]
    if limits.jerk is not None:
        times.append((4 * math.pi**2 * d / (share * limits.jerk)) ** (1 / 3))
    return max(times)


def _moves(axis: Axis, t: np.ndarray, rng: np.random.Generator, bang: bool) -> np.ndarray:
    """Rest-to-rest moves one after the other until the duration is filled."""
    limits = axis.limits
    centre, half = 0.5 * (limits.low + limits.high), 0.5 * MARGIN * (limits.high - limits.low)
    out = np.zeros((4, t.size))
    out[0] = centre
    position, start = centre, float(rng.uniform(*REST))
    while True:
        target = float(rng.uniform(centre - half, centre + half))
        share = float(rng.uniform(*SHARE))
        profile: Callable[[np.ndarray], np.ndarray]
        if bang and limits.jerk is None:
            profile = _bang_bang(target - position, limits, share)
            duration = profile.duration
        else:
            duration = _move_time(target - position, limits, share)
            profile = functools.partial(_skew_sine, target - position, duration)
        if start + duration > t[-1]:
            break
        local = t - start
        segment = profile(local)
        after = local > duration
        out[:, ~after & (local >= 0)] = segment[:, ~after & (local >= 0)]
        out[0, ~after & (local >= 0)] += position
        out[0, after] = target
        out[1:, after] = 0.0
        position, start = target, start + duration + float(rng.uniform(*REST))
    return out


@dataclass(frozen=True)
class _BangBang:
    """A trapezoidal-velocity move: `accelerate` s at +acceleration, `coast` s at the peak
    velocity, `accelerate` s at -acceleration (jerk zero between the steps)."""

    distance: float
    acceleration: float
    accelerate: float  # seconds of acceleration (and of deceleration)
    coast: float

    @property
    def duration(self) -> float:
        return 2 * self.accelerate + self.coast

    def __call__(self, t: np.ndarray) -> np.ndarray:
        sign = math.copysign(1.0, self.distance)
        a, ta, tc = self.acceleration, self.accelerate, self.coast
        acc = np.where((t >= 0) & (t < ta), a, 0.0) - np.where(
            (t >= ta + tc) & (t <= 2 * ta + tc), a, 0.0)
        vmax = a * ta
        vel = np.clip(np.where(t < ta, a * t, np.where(t < ta + tc, vmax,
                                                         vmax - a * (t - ta - tc))), 0, vmax)
        vel = np.where((t < 0) | (t > self.duration), 0.0, vel)
        first = 0.5 * a * np.clip(t, 0, ta) ** 2
        cruise = vmax * np.clip(t - ta, 0, tc)
        back = np.clip(t - ta - tc, 0, ta)
        pos = first + cruise + vmax * back - 0.5 * a * back**2
        return sign * np.array([pos, vel, acc, np.zeros_like(t)])


def _bang_bang(distance: float, limits: Limits, share: float) -> _BangBang:
    d = abs(distance)
    a, v = share * limits.acceleration, share * limits.velocity
    ta = min(v / a, math.sqrt(d / a))
    coast = max(d - a * ta * ta, 0.0) / (a * ta) if ta > 0 else 0.0
    return _BangBang(distance, a, ta, coast)


def _multisine(axis: Axis, t: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """Sines at random frequencies in the band the limits allow, faded in and out, scaled so
    that position, velocity and acceleration stay within the limits."""
    limits = axis.limits
    half = 0.5 * MARGIN * (limits.high - limits.low)
    top = math.sqrt(limits.acceleration / half) / (2 * math.pi)  # full range at full a
    frequencies = rng.uniform(0.1 * top, top, 4) if top > 0 else np.zeros(4)
    phases = rng.uniform(0, 2 * math.pi, 4)
    # faded in and out by f = sin^2(pi t / T): at rest at both ends; derivatives exact
    c = math.pi / t[-1]
    fade = [0.5 * (1 - np.cos(2 * c * t)), c * np.sin(2 * c * t),
            2 * c * c * np.cos(2 * c * t), -4 * c**3 * np.sin(2 * c * t)]
    w = 2 * math.pi * frequencies[:, None]
    angle = w * t + phases[:, None]
    sines = [(w**n * np.sin(angle + n * math.pi / 2)).sum(0) for n in range(4)]
    binomial = ((1,), (1, 1), (1, 2, 1), (1, 3, 3, 1))
    derivatives = [sum(b * fade[n - m] * sines[m] for m, b in enumerate(binomial[n]))
                   for n in range(4)]
    bounds = [half, limits.velocity, limits.acceleration, limits.jerk or math.inf]
    scale = min(b / max(float(np.abs(d).max()), 1e-300) for b, d in zip(bounds, derivatives))
    out = np.array(derivatives) * scale * float(rng.uniform(*SHARE))
    out[0] += 0.5 * (limits.low + limits.high)
    return out


def check_limits(machine: Machine, duration: float, origin: str = "machine") -> None:
    """Refuse limits that no move fits in `duration`, naming the key."""
    for k, axis in enumerate(machine.axes):
        limits = axis.limits
        shortest = _move_time(0.5 * MARGIN * (limits.high - limits.low), limits, SHARE[1])
        if shortest + 2 * REST[1] > duration:
            key = f"machine.axis[{k}]"
            raise ConfigError(origin, f"{key}.velocity", (
                f"a move over half the range {limits.low:g} .. {limits.high:g} {axis.unit} "
                f"takes {shortest:.3g} s at these limits, longer than the {duration:g} s "
                f"trajectory: raise velocity, acceleration or jerk, or the duration"))


def excitation_set(machine: Machine, n_train: int, n_test: int, duration: float,
                   rate_hz: float, seed: int = 0, classes: Sequence[str] = CLASSES
                   ) -> list[Excitation]:
    """`n_train` + `n_test` trajectories of `duration` s at `rate_hz`, the classes in turn,
    every axis its own independent trajectory; the same for the same seed."""
    unknown = [c for c in classes if c not in CLASSES]
    if unknown or not classes:
        raise ConfigError("excitation", "classes", f"{unknown or classes}: choose among "
                          f"{', '.join(CLASSES)}")
    if n_train < 1 or n_test < 0 or not duration > 0 or not rate_hz > 0:
        raise ConfigError("excitation", "count", "at least one training trajectory, a positive "
                          "duration and rate")
    check_limits(machine, duration)
    t = np.arange(round(duration * rate_hz) + 1) / rate_hz
    out = []
    for k in range(n_train + n_test):
        kind = classes[k % len(classes)]
        rng = np.random.default_rng([seed, k])
        signals: dict[str, np.ndarray] = {}
        for axis in machine.axes:
            values = (_multisine(axis, t, rng) if kind == "multisine"
                      else _moves(axis, t, rng, kind == "bang-bang"))
            signals.update(zip((axis.reference, *axis.derivatives), values))
        split = "train" if k < n_train else "test"
        out.append(Excitation(f"{kind}-{k:03d}", split, kind, t, signals))
    return out


def write_table(excitation: Excitation, path: str | Path) -> Path:
    """The trajectory as a CSV time table (time and its reference signals)."""
    names = list(excitation.signals)
    data = np.column_stack([excitation.time, *(excitation.signals[n] for n in names)])
    header = ",".join([TIME, *names])
    return atomic_write(path, lambda tmp: np.savetxt(tmp, data, fmt="%.17g", delimiter=",",
                                                     header=header, comments=""))
