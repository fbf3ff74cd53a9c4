"""Discrete filters of the loop blocks: notch and low-pass (first or second order).

The continuous prototype is mapped by blocks.loop_shaping's Tustin with prewarping at its
centre frequency (exact response there), as that module does for the manipulator's notch; the
result is a discrete StateSpace of one or two states, stepped symbolically in the block's FMU.
"""

from __future__ import annotations

import math

import casadi as ca
import numpy as np

from flexff.blocks.loop_shaping import StateSpace, from_polynomials, tustin
from flexff.blocks.options import OptionError

BUTTERWORTH_ZETA = 1 / math.sqrt(2)


def _centre(key: str, hz: float, step: float) -> float:
    nyquist_hz = 0.5 / step
    if not 0 < hz < nyquist_hz:
        raise OptionError(f"{key} {hz} Hz must lie in (0, {nyquist_hz:g}) Hz, below "
                          f"the Nyquist frequency of the {step} s step")
    return 2 * math.pi * hz


def notch(hz: float, zeta: tuple[float, float], step: float) -> StateSpace:
    """(s^2 + 2 z1 w s + w^2) / (s^2 + 2 z2 w s + w^2): depth z1/z2 at `hz`, unity elsewhere."""
    z1, z2 = zeta
    if not 0 <= z1 < z2:
        raise OptionError(f"notch_zeta {list(zeta)} must satisfy 0 <= z1 < z2 (numerator, "
                          "denominator damping)")
    w = _centre("notch_hz", hz, step)
    return tustin(from_polynomials(np.array([1.0, 2 * z1 * w, w**2]),
                                   np.array([1.0, 2 * z2 * w, w**2])), step, w)


def lowpass(hz: float, step: float, order: int = 2, zeta: float | None = None) -> StateSpace:
    """Unity gain at rest: w / (s + w) (order 1, -20 dB/decade above `hz`) or
    w^2 / (s^2 + 2 zeta w s + w^2) (order 2, -40 dB/decade; zeta None: Butterworth)."""
    if order not in (1, 2):
        raise OptionError(f"lowpass_order {order} must be 1 or 2")
    zeta = BUTTERWORTH_ZETA if zeta is None else zeta
    if not zeta > 0:
        raise OptionError(f"lowpass_zeta {zeta} must be positive")
    w = _centre("lowpass_hz", hz, step)
    if order == 1:
        return tustin(from_polynomials(np.array([w]), np.array([1.0, w])), step, w)
    return tustin(from_polynomials(np.array([w**2]), np.array([1.0, 2 * zeta * w, w**2])),
                  step, w)


def step_symbolic(ss: StateSpace, state: ca.SX, value: ca.SX) -> tuple[ca.SX, ca.SX]:
    """The discrete filter's output now and its next state for the input `value`."""
    out = ca.DM(ss.C) @ state + float(ss.D[0, 0]) * value
    return out, ca.DM(ss.A) @ state + ca.DM(np.ravel(ss.B)) * value
