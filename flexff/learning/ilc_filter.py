"""The learning filter of iterative learning control (learning.ilc): from one trial's force and
error to the next trial's feedforward force.

The update is f_{j+1} = Q (u_j + g P^-1 e_j): u_j the force the plant received (feedforward
plus the controller's recorded feedback), P^-1 e_j the rigid-body inverse dynamics along the
reference less along the trial's path, g the learning gain (1 by default) and Q a zero-phase
Butterworth low-pass (filtfilt) that keeps the iteration away from what the rigid model misses.
The iteration converges in the 2-norm where |Q (1 - g S P / P_model)| < 1 at every frequency:
a model of the wrong sign (a negative identified mass) never does, one off by a factor converges
with g below 2 / (that factor).

Docs: "ILC and the noise floor" (docs/explanation/ilc-noise-floor.md).
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass

import casadi as ca
import numpy as np
from scipy.signal import butter, filtfilt

from flexff.fmu.errors import InputError
from flexff.learning.samples import evaluate_samples

ORDER = 4  # Q's Butterworth order, run twice: 8th-order roll-off, zero phase
GAIN = 1.0  # the learning gain g on the model's correction P^-1 e


@dataclass(frozen=True)
class LearningFilter:
    """L and Q along one reference: the model's inverse dynamics with its parameters built in,
    the reference's motion (each (n, axes): position, velocity, acceleration), Q's corner
    [Hz], the learning gain, and the effort the model needs along it."""

    step: float
    inverse_dynamics: ca.Function  # (pos, vel, acc) -> effort of one sample
    reference: tuple[np.ndarray, np.ndarray, np.ndarray]
    cutoff_hz: float
    gain: float = GAIN

    @functools.cached_property
    def reference_force(self) -> np.ndarray:
        return evaluate_samples(self.inverse_dynamics, *self.reference)

    def model_force(self, error: np.ndarray) -> np.ndarray:
        """P^-1 e: the force (n, 2) [N] the model needs along the reference less the force it
        needs along the path that misses it by `error` (n, 2) [m] (derivatives by central
        differences, second order at the ends)."""
        rate = np.gradient(error, self.step, axis=0, edge_order=2)
        acceleration = np.gradient(rate, self.step, axis=0, edge_order=2)
        position, velocity, reference_acceleration = self.reference
        path = evaluate_samples(self.inverse_dynamics, position - error, velocity - rate,
                                reference_acceleration - acceleration)
        return np.asarray(self.reference_force - path)

    def q(self, force: np.ndarray) -> np.ndarray:
        """Q: the zero-phase low-pass along time (axis 0), the force held at its first and last
        values beyond the run (the loop rests before it starts) for three periods of the
        corner, so the filter's start and end transients stay outside the run."""
        b, a = butter(ORDER, self.cutoff_hz, fs=1.0 / self.step)
        settle = round(3.0 / (self.cutoff_hz * self.step))
        return np.asarray(filtfilt(b, a, force, axis=0, padtype="constant",
                                   padlen=min(force.shape[0] - 1, settle)))

    def update(self, applied: np.ndarray, error: np.ndarray) -> np.ndarray:
        """The next trial's feedforward force (n, 2) [N] from the force the plant received,
        u_j = f_j + F_fb (n, 2) [N], and the tracking error e_j (n, 2) [m]."""
        return self.q(applied + self.gain * self.model_force(error))


def filter_along(motion: tuple[np.ndarray, np.ndarray, np.ndarray], step: float,
                 inverse_dynamics: ca.Function, cutoff_hz: float, gain: float = GAIN
                 ) -> LearningFilter:
    """The learning filter of the model `inverse_dynamics` (pos, vel, acc) -> effort of one
    sample along the reference `motion` (position, velocity, acceleration, each (n, axes));
    InputError for a cutoff at or above the Nyquist frequency, a gain that is not positive or
    a reference too short."""
    check_cutoff(cutoff_hz, step)
    check_gain(gain)
    n = motion[0].shape[0]
    if n <= 3 * (2 * ORDER + 1):
        raise InputError(f"the reference has {n} points: the learning filter needs more than "
                         f"{3 * (2 * ORDER + 1)}; lengthen run.stop")
    return LearningFilter(step, inverse_dynamics, motion, cutoff_hz, gain)


def check_gain(gain: float) -> None:
    """InputError unless the learning gain is a positive finite number."""
    if not (isinstance(gain, int | float) and math.isfinite(gain) and gain > 0):
        raise InputError(f"the learning gain {gain!r} must be a positive finite number "
                         f"(1: the model's whole correction each trial)")


def check_cutoff(cutoff_hz: float, step: float) -> None:
    """InputError unless Q's corner lies between 0 and the Nyquist frequency of `step`."""
    nyquist = 0.5 / step
    if not 0 < cutoff_hz < nyquist:
        raise InputError(f"the learning filter's cutoff {cutoff_hz:g} Hz must lie between 0 "
                         f"and the Nyquist frequency {nyquist:g} Hz of the {step:g} s step")
