"""Min-max scaling to [0, 1] (eq. 4.3 of the thesis), fitted on training data only.

The thesis normalizes features and labels separately, with coefficients from the training set
applied unchanged to validation and test data; the test MSE it reports is in these units.
"""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class MinMaxScaler:
    """Per-column affine map x -> (x - low) / (high - low); constant columns keep a unit span."""

    low: np.ndarray
    high: np.ndarray

    @classmethod
    def fit(cls, arrays: Iterable[np.ndarray]) -> MinMaxScaler:
        """Fit on the rows of all `arrays` (each (n_i, k)), each array reduced on its own (a
        training set's features stacked were 300 MB)."""
        parts = [np.asarray(a, dtype=float) for a in arrays]
        parts = [a for a in parts if a.size]
        if not parts:
            raise ValueError("cannot fit a scaler on no data")
        return cls(low=np.min([a.min(axis=0) for a in parts], axis=0),
                   high=np.max([a.max(axis=0) for a in parts], axis=0))

    @property
    def span(self) -> np.ndarray:
        span = self.high - self.low
        return np.where(span > 0, span, 1.0)

    def transform(self, x: np.ndarray) -> np.ndarray:
        scaled: np.ndarray = (np.asarray(x, dtype=float) - self.low) / self.span
        return scaled

    def inverse(self, z: np.ndarray) -> np.ndarray:
        unscaled: np.ndarray = np.asarray(z, dtype=float) * self.span + self.low
        return unscaled

    def to_dict(self) -> dict[str, list[float]]:
        return {"low": self.low.tolist(), "high": self.high.tolist()}

    @classmethod
    def from_dict(cls, data: dict[str, list[float]]) -> MinMaxScaler:
        return cls(low=np.asarray(data["low"], dtype=float),
                   high=np.asarray(data["high"], dtype=float))
