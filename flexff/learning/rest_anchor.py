"""A learned model's constant effort, held where the machine's description says there is none.

A one-sided friction feature (tanh(v / w)^2, learning.feature_spec) is 1 while an axis moves,
as a constant is: only the rests tell them apart, where the measured motion is encoder noise
and the labels the controller's settling. Fitted freely, the constant came out at 9 mN on both
axes of the stage example in every learned model, and the feedforward gave it at rest, where
it crept the stage off its position (e2 ratio 62 against the identified model's 75 on x, 231
against 340 on y). Where an axis's prior has no `offset` term, a learned model is held to none
either: its linear skip is fitted through zero effort at zero features (`fit_through`; the
description's extra terms are features the skip weighs), and once trained the skip's constant
is set back to none and the inner network's head bias shifted so that, resting at the origin,
it adds nothing (learning.models.pin_at_rest; each part on its own, as the exported
physics-guided model fades its inner network where a feature leaves the training range). A
network without a skip is held to zero effort there where its axis has no extra terms either.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, replace

import numpy as np
import torch

from flexff.cosim.machine import Machine
from flexff.learning.feature_spec import FeatureInputs, feature_function
from flexff.learning.samples import evaluate_samples

REST_SAMPLES = 2000  # model-rate samples a network rests on its inputs before it is read


@dataclass(frozen=True)
class RestAnchor:
    """Where a model is held, in its features and targets (unscaled as a machine's data gives
    it; `scaled` as training sees it): zero features, the features of every axis at rest at
    the origin, zero effort; the outputs without a constant (`pinned`) and, of those, the ones
    whose effort at rest at the origin is zero (`still`)."""

    zero: np.ndarray  # (n_features,)
    resting: np.ndarray  # (n_features,)
    outputs: np.ndarray  # (n_outputs,)
    pinned: tuple[int, ...]
    still: tuple[int, ...]

    def scaled(self, scale_features: Callable[[np.ndarray], np.ndarray],
               scale_targets: Callable[[np.ndarray], np.ndarray]) -> RestAnchor:
        """The anchor in training's units: features by `scale_features`, the zero effort as
        a target by `scale_targets` (each of (1, k) arrays)."""
        return replace(self, zero=scale_features(self.zero[None])[0],
                       resting=scale_features(self.resting[None])[0],
                       outputs=scale_targets(self.outputs[None])[0])


def rest_anchor(machine: Machine, inputs: FeatureInputs) -> RestAnchor | None:
    """The anchor of a model of `machine` whose features `inputs` describes: without an
    `offset` term in the prior every axis pinned, those without extra terms still; None with
    one."""
    if "offset" in machine.prior.terms:
        return None
    at_rest = evaluate_samples(feature_function(machine, inputs),
                               np.zeros((1, 4 * len(machine.axes))))[0]
    return RestAnchor(np.zeros_like(at_rest), at_rest, np.zeros(len(machine.axes)),
                      tuple(range(len(machine.axes))),
                      tuple(k for k, axis in enumerate(machine.axes)
                            if not machine.prior.extra.get(axis.name)))


def fit_through(x: torch.Tensor, y: torch.Tensor, anchor: RestAnchor | None,
                columns: slice = slice(None)) -> torch.Tensor:
    """The least-squares solution (n_features + 1, n_outputs) of y ~ x W + b (float64 samples
    (n, n_features) of the anchor's `columns`, (n, n_outputs); the last row b), each pinned
    output's through the anchor's zero: (x - x0) W = y - y0, b = y0 - x0 W."""
    design = torch.cat([x, torch.ones(len(x), 1, dtype=x.dtype)], dim=1)
    solution: torch.Tensor = torch.linalg.lstsq(design, y, driver="gelsd").solution
    if anchor is None:
        return solution
    x0 = torch.as_tensor(anchor.zero, dtype=x.dtype)[columns]
    y0 = torch.as_tensor(anchor.outputs, dtype=y.dtype)
    pinned = list(anchor.pinned)
    weights = torch.linalg.lstsq(x - x0, y[:, pinned] - y0[pinned], driver="gelsd").solution
    solution[:-1, pinned] = weights
    solution[-1, pinned] = y0[pinned] - x0 @ weights
    return solution
