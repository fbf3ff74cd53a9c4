"""Synthetic datasets in the collection format, without co-simulation.

For tests, and to exercise training before co-simulated data exist. Each trajectory is a
smooth motion of the wrist, followed exactly (x = x_ref: there is no controller here): either
random (a skew-sine circle, eq. 4.1 of the thesis, at rest at both ends, or a periodic cubic
spline through random workspace points) or the reference of a trajectory of the collection's
sets (`learning.trajectories`). The force labels are the exact rigid-body inverse dynamics of
the nominal model (eq. 2.4) along the motion plus what the motors' Coulomb and viscous
friction (the hardware variant's values) take, mapped to the wrist by A^T, and white noise
standing in for the feedback's reaction to the encoders; the current labels i1..i3 are that
force as the controller allocates it (controllers.allocation, at the true position). The
encoder angles are the exact
shoulder coordinates of eq. (2.1), as the nominal plant reports them (preprocessing counts
them in encoder steps, as the thesis does).
"""

from __future__ import annotations

import functools
from pathlib import Path
from typing import Any

import casadi as ca
import numpy as np
from scipy.interpolate import CubicSpline

from flexff.controllers.allocation import motor_currents
from flexff.controllers.features import nominal_model
from flexff.fmu.defaults import DEFAULT_STEP
from flexff.learning.dataset import (
    CURRENT_SIGNALS,
    ENCODER_SIGNALS,
    REFERENCE_SIGNALS,
    Trajectory,
    write_dataset,
)
from flexff.plant.kinematics import SHOULDER_INDEX
from flexff.plant.parameters import HARDWARE, MOTOR_FRICTION

WORKSPACE = 0.05  # m
MAX_ACCELERATION = 4.0  # m/s^2: keeps the currents well inside the amplifier limit


def skew_sine_circle(t: np.ndarray, duration: float, radius: float, turns: float,
                     start_angle: float, direction: int = 1) -> np.ndarray:
    """Eq. (4.1): circle about the centre, angle on a skew sine; rows x, y, vx, vy, ax, ay."""
    total = 2 * np.pi * turns * direction
    phase = 2 * np.pi * t / duration
    angle = start_angle + total * (t / duration - np.sin(phase) / (2 * np.pi))
    rate = total * (1 - np.cos(phase)) / duration
    accel = total * 2 * np.pi * np.sin(phase) / duration**2
    c, s = np.cos(angle), np.sin(angle)
    return np.vstack([radius * c, radius * s, -radius * s * rate, radius * c * rate,
                      -radius * (c * rate**2 + s * accel), radius * (-s * rate**2 + c * accel)])


def periodic_spline(t: np.ndarray, lap: float, points: np.ndarray) -> np.ndarray:
    """Closed cubic spline through `points` (k, 2), one lap every `lap` seconds; rows as above."""
    knots = np.linspace(0.0, lap, len(points) + 1)
    spline = CubicSpline(knots, np.vstack([points, points[:1]]), bc_type="periodic")
    t = np.mod(t, lap)
    return np.vstack([spline(t).T, spline(t, 1).T, spline(t, 2).T])


def random_motion(rng: np.random.Generator, t: np.ndarray,
                  duration: float) -> tuple[np.ndarray, dict[str, Any]]:
    """A circle (two times in three) or a spline (1 to 4 laps) with random, feasible parameters,
    and its description: the circle's is the [reference] table of the same motion."""
    if rng.uniform() < 2 / 3:
        radius = rng.uniform(0.007, 0.045)
        max_turns = duration / (4 * np.pi) * np.sqrt(MAX_ACCELERATION / radius)
        most = min(15.0, max_turns)
        turns = float(rng.uniform(min(1.0, most), most))
        start_angle = float(rng.uniform(-np.pi, np.pi))
        direction = int(rng.choice([-1, 1]))
        spec = {"kind": "circle", "centre": [0.0, 0.0], "radius": radius,  # a [reference]
                "turns": direction * turns, "start_angle": start_angle, "duration": duration}
        return skew_sine_circle(t, duration, radius, turns, start_angle, direction), spec
    while True:
        count = int(rng.integers(4, 7))
        radii = 0.045 * np.sqrt(rng.uniform(0, 1, count))
        angle = rng.uniform(-np.pi, np.pi, count)
        points = np.column_stack([radii * np.cos(angle), radii * np.sin(angle)])
        laps = int(rng.integers(1, 5))
        motion = periodic_spline(t, duration / laps, points)
        if (np.hypot(motion[0], motion[1]).max() < WORKSPACE
                and np.hypot(motion[4], motion[5]).max() < MAX_ACCELERATION):
            return motion, {"kind": "spline", "points": points.tolist(), "laps": laps}


@functools.cache
def _label_function(friction: bool) -> ca.Function:
    """(pos, vel, acc) -> (force, shoulder angles): the nominal inverse dynamics, with the
    hardware variant's motor friction when `friction`, and theta_s1..3."""
    model = nominal_model()
    p = model.parameter_values(**(HARDWARE.flat_values(*MOTOR_FRICTION) if friction else {}))
    pos, vel, acc = ca.SX.sym("pos", 2), ca.SX.sym("vel", 2), ca.SX.sym("acc", 2)
    shoulders = ca.vertcat(*[model.coordinates(pos, p)[k] for k in SHOULDER_INDEX])
    return ca.Function("labels", [pos, vel, acc], [model.inverse_dynamics(pos, vel, acc, p),
                                                  shoulders])


@functools.cache
def _current_function() -> ca.Function:
    """(force, pos) -> the motor currents the controller allocates for that force there."""
    force, pos = ca.SX.sym("force", 2), ca.SX.sym("pos", 2)
    return ca.Function("currents", [force, pos], [motor_currents(force, pos)])


def motion_trajectory(name: str, split: str, seed: int, t: np.ndarray, motion: np.ndarray,
                      reference: dict[str, Any], friction: bool = True,
                      force_noise: float = 0.02) -> Trajectory:
    """The dataset signals of a wrist motion (rows x, y, vx, vy, ax, ay at times t)."""
    force, theta = _label_function(friction).map(len(t), "thread", 2)(
        motion[0:2], motion[2:4], motion[4:6])
    rng = np.random.default_rng([seed, 1])
    force = np.asarray(force).T + force_noise * rng.standard_normal((len(t), 2))
    currents = np.asarray(_current_function().map(len(t))(force.T, motion[0:2]))
    signals = {"time": t, "x": motion[0], "y": motion[1], "Fx": force[:, 0], "Fy": force[:, 1],
               **dict(zip(CURRENT_SIGNALS, currents))}
    signals.update(zip(REFERENCE_SIGNALS, motion))
    signals.update(zip(ENCODER_SIGNALS, np.asarray(theta)))
    return Trajectory(name=name, split=split, signals=signals, reference=reference, seed=seed)


def synthetic_trajectory(name: str, split: str, seed: int, duration: float = 15.0,
                         rate_hz: float = 1 / DEFAULT_STEP, friction: bool = True,
                         force_noise: float = 0.02) -> Trajectory:
    """One random trajectory with all signals of the dataset format."""
    t = np.arange(round(duration * rate_hz)) / rate_hz
    motion, spec = random_motion(np.random.default_rng(seed), t, duration)
    return motion_trajectory(name, split, seed, t, motion, spec, friction, force_noise)


def synthetic_dataset(path: str | Path, n_train: int = 8, n_test: int = 2, duration: float = 15.0,
                      rate_hz: float = 1 / DEFAULT_STEP, seed: int = 0, friction: bool = True,
                      force_noise: float = 0.02) -> Path:
    """Write a random synthetic 'sim' dataset folder; trajectory k uses seed `seed + k`."""
    trajectories = [
        synthetic_trajectory(f"{split}_{k:03d}", split, seed + k, duration, rate_hz, friction,
                             force_noise)
        for k, split in enumerate(["train"] * n_train + ["test"] * n_test)]
    return write_dataset(path, "sim", rate_hz, _plant(friction, force_noise), trajectories)


def synthetic_collection_set(path: str | Path, set_name: str = "sim", friction: bool = True,
                             force_noise: float = 0.02) -> Path:
    """Write the references of the collection's trajectory set `set_name` (the trajectories,
    splits and rate that `flexff data collect` runs), followed exactly, with synthetic labels."""
    # imported here: the run configurations pull in the co-simulation (fmpy), which the
    # random datasets above do not need
    from flexff.cosim.scenario import reference_signals
    from flexff.learning.collect import trajectory_config
    from flexff.learning.trajectories import trajectory_set

    trajectories = trajectory_set(set_name)
    written = []
    for spec in trajectories.trajectories:
        config = trajectory_config(spec, trajectories)
        signals = reference_signals(config)
        motion = np.vstack([signals[s] for s in REFERENCE_SIGNALS])[:, ::trajectories.decimation]
        t = np.arange(motion.shape[1]) / trajectories.sample_rate_hz
        written.append(motion_trajectory(spec.name, spec.split, spec.seed, t, motion,
                                         dict(spec.reference), friction, force_noise))
    return write_dataset(path, set_name, trajectories.sample_rate_hz,
                         _plant(friction, force_noise), written)


def _plant(friction: bool, force_noise: float) -> dict[str, Any]:
    model = nominal_model()
    return {"variant": "nominal",
            "parameters": dict(zip(model.variant.parameters.names(),
                                   model.parameter_values().tolist())),
            "synthetic": {"friction": friction, "force_noise_n": force_noise}}
