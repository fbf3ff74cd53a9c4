"""Long records reduced for plotting, chunk by chunk, in memory bounded by the plot's width.

Envelope keeps the minimum and the maximum of each bucket of consecutive points (about one
bucket per pixel column), so that a line through them shows every spike, even one of a single
sample; Strided keeps every n-th point, for curves of one signal against another (the x-y path),
where a pair of extremes would not be a point of the curve.
"""

from __future__ import annotations

import numpy as np

BUCKETS = 1000  # about the pixel columns of a plot (8 inches at 120 dpi)
STRIDED_POINTS = 20_000


def _ceil_div(a: int, b: int) -> int:
    return -(-a // b)


class Envelope:
    """Minimum and maximum of a series of `points` values per bucket of `size` points."""

    def __init__(self, points: int, buckets: int = BUCKETS) -> None:
        self.size = max(1, _ceil_div(points, buckets))
        n = _ceil_div(max(points, 1), self.size)
        self.low, self.high = np.full(n, np.inf), np.full(n, -np.inf)
        self.filled = 0  # buckets up to here have had a value

    def add(self, k0: int, values: np.ndarray) -> None:
        """The values of points k0, k0 + 1, ..."""
        if not values.size:
            return
        first = (-k0) % self.size  # the first bucket boundary inside the chunk
        starts = np.arange(first, values.size, self.size)
        if first:
            starts = np.concatenate([[0], starts])
        buckets = (k0 + starts) // self.size
        self.low[buckets] = np.minimum(self.low[buckets], np.minimum.reduceat(values, starts))
        self.high[buckets] = np.maximum(self.high[buckets], np.maximum.reduceat(values, starts))
        self.filled = max(self.filled, int(buckets[-1]) + 1)

    def line(self, step: float) -> tuple[np.ndarray, np.ndarray]:
        """(t, value) of a line through each bucket's minimum then maximum, at the bucket's
        start time (`step` seconds per point); the plain series when buckets are points."""
        t = np.arange(self.filled) * self.size * step
        low, high = self.low[:self.filled], self.high[:self.filled]
        if self.size == 1:
            return t, low
        return np.repeat(t, 2), np.column_stack([low, high]).ravel()

    def peaks(self, step: float) -> tuple[np.ndarray, np.ndarray]:
        """(t, value) of each bucket's maximum, at the bucket's start time."""
        return np.arange(self.filled) * self.size * step, self.high[:self.filled]


class Strided:
    """Every n-th of `points` values (n so that at most `most` are kept)."""

    def __init__(self, points: int, most: int = STRIDED_POINTS) -> None:
        self.every = max(1, _ceil_div(points, most))
        self.kept: list[np.ndarray] = []

    def add(self, k0: int, values: np.ndarray) -> None:
        self.kept.append(values[(-k0) % self.every::self.every])

    def values(self) -> np.ndarray:
        return np.concatenate(self.kept) if self.kept else np.zeros(0)
