"""What a feedforward's force misses against the ILC limit's, the best force for the reference.

The difference per axis, ILC limit's force minus the feedforward's, is split by frequency band
(BANDS_HZ) and tried at time shifts of the feedforward (up to MAX_SHIFT_S either way). A
difference in the reference's own band is a model error, above the loop's crossover mostly
noise; one that a shift removes is in quadrature with the motion, a phase error such as a
missing damping. On the hardware stand-in this found the physics-guided model's y gap: 74 %
in the reference's band, 2 ms of shift, the flexure damping the identification kept nominal
(learning.identify, `_common_damping`).
"""

from __future__ import annotations

from itertools import pairwise
from typing import Any

import numpy as np

BANDS_HZ = (0.3, 1.0, 5.0)  # edges: the references' band, up to the crossover, around it, above
MAX_SHIFT_S = 0.02  # the feedforward shifted by up to this, either way


def _bands() -> list[tuple[str, float, float]]:
    """Each band's name (force_gap's band_share key) and edges [Hz]."""
    edges = [0.0, *BANDS_HZ, np.inf]
    return [(f"{low:g}-{high:g} Hz" if np.isfinite(high) else f"above {low:g} Hz", low, high)
            for low, high in pairwise(edges)]


def band_names() -> list[str]:
    """The bands' names, as force_gap's band_share keys."""
    return [name for name, _, _ in _bands()]


def force_gap(feedforward: np.ndarray, ideal: np.ndarray, step_s: float) -> dict[str, Any]:
    """The difference `ideal` - `feedforward` (forces of one axis at the steps of `step_s`):
    its rms [N], its power's share per band, the shift of the feedforward [s] (positive: its
    force taken that much later) that matches `ideal` best and the rms there."""
    feedforward, ideal = np.asarray(feedforward, float), np.asarray(ideal, float)
    if feedforward.shape != ideal.shape or feedforward.ndim != 1 or len(ideal) < 2:
        raise ValueError("the forces must be two series of the same length, at least 2")
    gap = ideal - feedforward
    power = np.abs(np.fft.rfft(gap - gap.mean())) ** 2
    frequency = np.fft.rfftfreq(len(gap), step_s)
    total = power.sum()
    shares = {name: float(power[(frequency >= low) & (frequency < high)].sum() / total)
              if total > 0 else 0.0 for name, low, high in _bands()}
    reach = min(round(MAX_SHIFT_S / step_s), (len(gap) - 1) // 4)
    inner = slice(reach, len(gap) - reach)  # the samples every shift compares

    def rms_at(shift: int) -> float:
        moved = feedforward[reach + shift:len(gap) - reach + shift]
        return float(np.sqrt(np.mean((ideal[inner] - moved) ** 2)))

    best = min(range(-reach, reach + 1), key=lambda shift: (rms_at(shift), abs(shift)))
    return {"rms_n": float(np.sqrt(np.mean(gap**2))), "band_share": shares,
            "best_shift_s": best * step_s, "rms_at_best_shift_n": rms_at(best)}
