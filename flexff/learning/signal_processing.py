"""Sampled signals, whichever machine recorded them: the zero-phase Butterworth low-pass,
velocity and acceleration by central differences, and the down-sampling factor to a model's
rate, shared by every machine's features, labels and identification.
"""

from __future__ import annotations

import functools

import numpy as np
from scipy.signal import butter, sosfiltfilt

from flexff.fmu.errors import InputError


def lowpass(signal: np.ndarray, rate_hz: float, cutoff_hz: float = 1.8,
            order: int = 4) -> np.ndarray:
    """Zero-phase Butterworth low-pass of `signal` along axis 0 (forwards and backwards)."""
    if cutoff_hz >= rate_hz / 2:
        raise InputError(f"cutoff {cutoff_hz} Hz must lie below the Nyquist frequency "
                         f"{rate_hz / 2} Hz")
    return sosfiltfilt(_butterworth(order, cutoff_hz, rate_hz), signal, axis=0)


@functools.cache
def _butterworth(order: int, cutoff_hz: float, rate_hz: float) -> np.ndarray:
    """The low-pass's second-order sections, designed once (a physics-guided run filters
    480 times in its identification alone; each design took 2 ms)."""
    sos: np.ndarray = butter(order, cutoff_hz, btype="low", fs=rate_hz, output="sos")
    return sos


def differentiate(pos: np.ndarray, rate_hz: float) -> tuple[np.ndarray, np.ndarray]:
    """Velocity and acceleration by second-order central differences (np.gradient)."""
    dt = 1.0 / rate_hz
    vel = np.gradient(pos, dt, axis=0)
    return vel, np.gradient(vel, dt, axis=0)


def decimation(rate_hz: float, model_rate_hz: float | None) -> int:
    """Integer down-sampling factor from the data rate to the model rate."""
    if model_rate_hz is None:
        return 1
    factor = rate_hz / model_rate_hz
    if model_rate_hz <= 0 or factor < 1 or abs(factor - round(factor)) > 1e-9:
        raise InputError(f"model_rate_hz {model_rate_hz:g} must divide the data rate "
                         f"{rate_hz:g} Hz by a whole number")
    return round(factor)
