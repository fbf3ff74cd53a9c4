"""Features and labels for any machine: per axis its motion (position, velocity, acceleration,
optionally jerk) and its directions of motion, from one CasADi function that training
evaluates on the filtered measured motion and the feedforward FMU generates into C on the
reference.

Every preprocessing choice is a setting of MachineFeatures whose default comes from the data:
the low-pass corners (`cutoff_hz`, `data_cutoff`), the model rate, `lead_s` (the zero-order
hold's half-sample lead between effort and motion), and the direction widths, the Coulomb
widths that the identification finds (`friction_widths`) where a prior is identified. A
description's `[machine.learning]` sets the first four (`MachineFeatures.of`); `preprocessing`
records what was used and which of it was derived, `ERROR` how a prediction is scored.

Docs: "Learning", section Any other machine (docs/explanation/learning.md).
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np

from flexff.cosim.machine import Machine
from flexff.fmu.errors import InputError
from flexff.learning.feature_spec import (
    DIRECTION_WIDTHS,
    FeatureInputs,
    feature_function,
)
from flexff.learning.linear_model import EDGE_PERIODS
from flexff.learning.linear_prior import LinearModel
from flexff.learning.samples import evaluate_samples
from flexff.learning.signal_processing import decimation, differentiate, lowpass

ENERGY_SHARE = 0.99  # of the references' velocity energy under the band's edge
CUTOFF_PER_BAND = 4.0  # the default corner: this many times the band's edge (identification
# on the drive example: inertia 0.6 % high at 2x, 0.1 % at 4x; e2 467x -> 701x PID alone)
HIGHEST_CUTOFF = 0.05  # the default corner at most: this share of the data rate
MOTION_PER_CUTOFF = 8.0  # the measured motion's corner: this many times the labels' (the
# drive example's identification residual 0.18 % at 4x, 0.10 % at 8x, 0.13 % at 16x: a lower
# corner smears the Coulomb step in the prior's column, a higher one lets encoder noise in)

MODEL_RATE_PER_CUTOFF = 10.0  # the default model rate: at least this many times the corner
HOLD_LEAD = 0.5  # the default lead of an effort over the motion it causes [samples]
MAX_LEAD = 10.0  # the longest lead accepted [samples]
ERROR = ("relative 2-norm per axis, ||F - P|| / ||F||, over the samples of every log scored: F "
         "the measured efforts, each taken lead_s before its sample and passed through the "
         "labels' filter (a zero-phase Butterworth low-pass of filter_order at cutoff_hz, run "
         "forwards and backwards, then decimated to model_rate_hz), P the model's prediction "
         "at the same samples; edge_periods corner periods at each end of a log left out")


@dataclass(frozen=True)
class MachineFeatures:
    """Everything that turns a machine's trajectory into features and labels; None: derived
    from the data (`resolved`)."""

    cutoff_hz: float | None = None
    filter_order: int = 4
    quantization: Mapping[str, float] = field(default_factory=dict)  # axis -> step [unit]
    position_noise: Mapping[str, float] = field(default_factory=dict)  # axis -> std [unit]
    effort_noise: Mapping[str, float] = field(default_factory=dict)  # axis -> std [effort unit]
    model_rate_hz: float | None = None
    jerk: bool = False  # a jerk feature: three differences of measured positions are noisy
    direction_widths: tuple[float, ...] = DIRECTION_WIDTHS
    lead_s: float | None = None  # the efforts' lead over the motion [s]; None: HOLD_LEAD samples
    terms: bool = True  # features of moving at all and of the description's extra terms

    @classmethod
    def of(cls, machine: Machine) -> MachineFeatures:
        """The settings the description's `[machine.learning]` gives, the rest derived."""
        given = machine.learning
        default = cls()
        return replace(default, cutoff_hz=given.cutoff_hz, lead_s=given.lead_s,
                       model_rate_hz=given.model_rate_hz,
                       filter_order=given.filter_order or default.filter_order)

    @property
    def inputs(self) -> FeatureInputs:
        """What the feedforward FMU needs to compute the same features."""
        return FeatureInputs(self.jerk, self.direction_widths, self.terms)

    def resolved(self, rate_hz: float, references: list[Mapping[str, np.ndarray]],
                 machine: Machine) -> MachineFeatures:
        """The settings with every None derived from the data (`references`: the training
        trajectories' signals), checked."""
        cutoff = self.cutoff_hz or data_cutoff(references, machine, rate_hz)
        if not 0 < cutoff < rate_hz / 2:
            raise InputError(f"cutoff_hz {cutoff:g} must lie between 0 and the Nyquist "
                             f"frequency {rate_hz / 2:g} Hz of the data")
        model_rate = self.model_rate_hz or rate_hz / max(
            1, math.floor(rate_hz / (MODEL_RATE_PER_CUTOFF * cutoff)))
        names = {a.name for a in machine.axes}
        for key, values in (("quantization", self.quantization),
                            ("position_noise", self.position_noise),
                            ("effort_noise", self.effort_noise)):
            for axis, value in values.items():
                if axis not in names or not value >= 0:
                    raise InputError(f"{key}.{axis}: expected a number >= 0 for one of the "
                                     f"axes {', '.join(sorted(names))}, got {value!r}")
        if self.filter_order < 1 or any(w <= 0 for w in self.direction_widths):
            raise InputError("filter_order must be at least 1 and direction widths positive")
        lead = HOLD_LEAD / rate_hz if self.lead_s is None else self.lead_s
        if not 0 <= lead <= MAX_LEAD / rate_hz:
            raise InputError(f"lead_s: expected the efforts' lead over the motion, between 0 "
                             f"and {MAX_LEAD:g} samples ({MAX_LEAD / rate_hz:g} s), got {lead!r}")
        return replace(self, cutoff_hz=cutoff, model_rate_hz=model_rate, lead_s=lead)

    def decimation(self, rate_hz: float) -> int:
        assert self.model_rate_hz is not None, "resolved() first"
        return decimation(rate_hz, self.model_rate_hz)


def preprocessing(given: MachineFeatures, resolved: MachineFeatures, rate_hz: float
                  ) -> dict[str, Any]:
    """What turned efforts into labels (`resolved` from the settings `given`, data at
    `rate_hz`) and how a prediction is scored, as JSON data (metrics.json, summary.json):
    each value, and which of them were derived from the data."""
    assert resolved.cutoff_hz is not None and resolved.lead_s is not None
    derived = [name for name in ("cutoff_hz", "lead_s", "model_rate_hz")
               if getattr(given, name) is None]
    return {"error": ERROR, "filter": "zero-phase Butterworth low-pass",
            "cutoff_hz": resolved.cutoff_hz, "filter_order": resolved.filter_order,
            "lead_s": resolved.lead_s, "lead_samples": resolved.lead_s * rate_hz,
            "model_rate_hz": resolved.model_rate_hz, "data_rate_hz": rate_hz,
            "edge_periods": EDGE_PERIODS, "derived": derived}


def preprocessing_text(record: Mapping[str, Any]) -> str:
    """`preprocessing`'s record as one line for the terminal: each value, derived ones marked
    with the setting of [machine.learning] that would fix them."""
    def mark(name: str) -> str:
        return f" (derived; set [machine.learning] {name})" if name in record["derived"] else ""
    return (f"labels: efforts {1e3 * record['lead_s']:.4g} ms ahead "
            f"({record['lead_samples']:.3g} samples){mark('lead_s')}, low-pass of order "
            f"{record['filter_order']} at {record['cutoff_hz']:.4g} Hz{mark('cutoff_hz')}, "
            f"model rate {record['model_rate_hz']:.4g} Hz{mark('model_rate_hz')}")


def friction_widths(model: LinearModel) -> tuple[float, ...]:
    """The direction features' tanh widths for a machine whose prior `model` identified: each
    axis's Coulomb width as a fraction of its velocity limit (3 significant digits, each once),
    or DIRECTION_WIDTHS where the prior has no Coulomb friction. At the machine's own width
    a network's linear skip takes the friction step at the loop's rate (the drive example's
    LSTM: 330x -> 726x PID alone); fixed widths around it are nearly collinear once the labels'
    filter smooths them, and their least-squares mix turns each step into spikes."""
    machine = model.machine
    if not any(t.startswith("coulomb") for t in machine.prior.terms):
        return DIRECTION_WIDTHS
    return tuple(sorted({float(f"{model.axes[a.name].width / a.limits.velocity:.3g}")
                         for a in machine.axes}))


def data_cutoff(references: list[Mapping[str, np.ndarray]], machine: Machine,
                rate_hz: float) -> float:
    """CUTOFF_PER_BAND times the frequency under which ENERGY_SHARE of the references'
    velocity energy lies (all axes and trajectories), at most HIGHEST_CUTOFF of the rate: the
    band the feedforward must reproduce, well below where the encoders' noise dominates the
    differentiated positions (an acceleration's or jerk's band reaches far out at every step
    of a bang-bang move)."""
    curves = []  # (frequencies, cumulative share of the energy) per trajectory and axis
    for signals in references:
        for axis in machine.axes:
            velocity = np.asarray(signals[axis.derivatives[0]], dtype=float)
            window = np.hanning(velocity.size)  # leakage of a non-periodic record
            power = np.abs(np.fft.rfft((velocity - velocity.mean()) * window)) ** 2
            curves.append((np.fft.rfftfreq(velocity.size, 1.0 / rate_hz),
                           np.cumsum(power) / max(float(power.sum()), 1e-300)))
    if not curves:
        raise InputError("no training trajectory to derive the filter's corner from")
    finest = min(float(f[1]) for f, _ in curves)
    frequencies = np.arange(0.0, rate_hz / 2, finest)
    spectra = [np.interp(frequencies, f, share) for f, share in curves]
    share = np.mean(spectra, axis=0)
    edge = float(frequencies[np.searchsorted(share, ENERGY_SHARE)])
    return float(min(max(CUTOFF_PER_BAND * edge, 4 * frequencies[1]), HIGHEST_CUTOFF * rate_hz))


def motion(signals: Mapping[str, np.ndarray], rate_hz: float, machine: Machine,
           config: MachineFeatures, rng: np.random.Generator | None = None
           ) -> tuple[np.ndarray, np.ndarray]:
    """Each axis's measured motion (n, 4 axes: position, velocity, acceleration, jerk) at the
    data rate, filtered at the motion's corner (MOTION_PER_CUTOFF times the labels'), and the
    efforts (n, axes) commanded `lead_s` before each sample (the labels' alignment); with `rng`
    (training only) the settings' noise added first."""
    assert config.cutoff_hz is not None and config.lead_s is not None, "resolved() first"
    corner = min(MOTION_PER_CUTOFF * config.cutoff_hz, 0.45 * rate_hz)
    columns, efforts = [], []
    for axis in machine.axes:
        position = np.asarray(signals[axis.measured_signal], dtype=float)
        effort = np.asarray(signals[axis.effort_signal], dtype=float)
        step = config.quantization.get(axis.name, 0.0)
        if step > 0:
            position = step * np.floor(position / step + 0.5)
        if rng is not None:
            position = position + config.position_noise.get(axis.name, 0.0) \
                * rng.standard_normal(position.shape)
            effort = effort + config.effort_noise.get(axis.name, 0.0) \
                * rng.standard_normal(effort.shape)
        position = lowpass(position, rate_hz, corner, config.filter_order)
        velocity, acceleration = differentiate(position, rate_hz)
        jerk = np.gradient(acceleration, 1.0 / rate_hz)
        columns.append(np.column_stack([position, velocity, acceleration, jerk]))
        efforts.append(lagged(effort, rate_hz, config.lead_s))
    return np.column_stack(columns), np.column_stack(efforts)


def lagged(values: np.ndarray, rate_hz: float, lead_s: float) -> np.ndarray:
    """`values` (one per sample) as they were `lead_s` earlier, linearly interpolated (the
    first value held before the start)."""
    t = np.arange(values.size) / rate_hz
    return np.asarray(np.interp(t - lead_s, t, values))


def named_motion(moved: np.ndarray, machine: Machine) -> dict[str, np.ndarray]:
    """`motion`'s columns by the axes' motion names (x, vx, ax of every axis)."""
    named: dict[str, np.ndarray] = {}
    for k, axis in enumerate(machine.axes):
        named.update(zip(axis.motion, moved[:, 4 * k:4 * k + 3].T))
    return named


def label_filter(values: np.ndarray, rate_hz: float, config: MachineFeatures) -> np.ndarray:
    """The labels' low-pass and decimation to the model rate, along axis 0: applied to the
    efforts and to whatever is compared with them (features, regressor columns) alike."""
    assert config.cutoff_hz is not None, "resolved() first"
    filtered = lowpass(values, rate_hz, config.cutoff_hz, config.filter_order)
    return np.asarray(filtered[::config.decimation(rate_hz)])


def prepare(signals: Mapping[str, np.ndarray], rate_hz: float, machine: Machine,
            config: MachineFeatures, rng: np.random.Generator | None = None
            ) -> tuple[np.ndarray, np.ndarray]:
    """Features (n, n_features) and labels (n, axes) at the model rate from a trajectory's
    signals (machine.signals), `config` resolved; with `rng` (training only) its noise. The
    features of the measured motion pass the labels' filter as the efforts do."""
    moved, efforts = motion(signals, rate_hz, machine, config, rng)
    features = evaluate_samples(feature_function(machine, config.inputs), moved)
    return label_filter(features, rate_hz, config), label_filter(efforts, rate_hz, config)
