"""Preprocessing: from recorded signals (or a reference) to network features and labels.

As the seed: the encoder angles counted in whole counts of the 2048 counts/rev encoders about
their home angles (the thesis quantizes its ideal simulated angles so; angles already counted,
as the hardware's, stay as they are), the wrist position from them by forward kinematics (two
encoders as the thesis; three as an option), optional white noise on positions and forces
(training data only), a 4th-order Butterworth low-pass at 1.8 Hz run forwards and backwards
(zero phase, as MATLAB's filtfilt; second-order sections keep a 1.8 Hz corner at 1 kHz well
conditioned), and velocities and accelerations by central differences of the filtered
positions.

The features are then a function of (position, velocity, acceleration) only,
`motion_features`, used both for training data and at evaluation time on the reference signals
x_ref ... ay_ref (the feedforward runs on the reference); their definition lives in
controllers.features, which the feedforward FMU generates into C.
"""

from __future__ import annotations

import dataclasses
import functools
from dataclasses import dataclass
from typing import Any

import casadi as ca
import numpy as np

from flexff.controllers.features import FEATURE_SETS, motion_features, nominal_model
from flexff.fmu.errors import InputError
from flexff.learning.dataset import (
    CURRENT_SIGNALS,
    ENCODER_SIGNALS,
    LABEL_SIGNALS,
    DatasetError,
    Trajectory,
)
from flexff.learning.samples import evaluate_samples
from flexff.learning.signal_processing import decimation, differentiate, lowpass
from flexff.plant.kinematics import SHOULDER_INDEX

# a model's labels (controllers.manipulator.MODEL_OUTPUTS): the force the controller applied to the
# wrist, or the motor currents it commanded (after the control allocation). Measured with
# flexff evaluate --currents (fast preset, e2 ratio PID alone / feedforward, x / y, forces
# against currents): sim TCN 207 / 246 against 276 / 335, pgnn 304 / 362 against 386 / 468;
# hardware stand-in TCN 31 / 38 against 39 / 44, pgnn (3 seeds) 107 / 89 against 97 / 91;
# with the hardware environment's directions, 1 Hz corner and three encoders, TCN 83 / 71
# against 135 / 114 (the test split's references: geometric means 40 / 47 against 42 / 53).
LABELS = {"forces": LABEL_SIGNALS, "currents": CURRENT_SIGNALS}


@dataclass(frozen=True)
class FeatureConfig:
    """Everything that turns a recorded trajectory into features and labels."""

    # "full": 63 coordinates/velocities/accelerations; "directions": those and the motors'
    # directions of motion; or "compact" (controllers.features)
    feature_set: str = "full"
    encoders: int = 2  # forward kinematics from theta_s1..2 (thesis) or all three
    quantize_encoders: bool = True  # count the angles in whole encoder counts first (seed)
    cutoff_hz: float = 1.8  # low-pass corner, slightly above the 1.7 Hz first mode (seed)
    filter_order: int = 4
    filter_forces: bool = True  # the thesis filters the force labels with the same filter
    position_noise_m: float = 1e-4  # white noise std added to training positions [m]
    force_noise_n: float = 1e-2  # white noise std added to training forces [N]
    labels: str = "forces"  # or "currents": i1..i3 instead of Fx, Fy (LABELS)
    # white noise std added to training currents [A]: force_noise_n times the median 6.8 A/N
    # of |i| / |F| on the sim set
    current_noise_a: float = 0.068
    model_rate_hz: float | None = None  # down-sample to this rate; None keeps the data rate
    # the rigid-body model's forces pass the labels' filter (`filter_labels`) before they are
    # compared with the labels: the pgnn's prior in its residual labels
    # (learning.manipulator_data), the regressor in the identification (learning.identify), a
    # black-box network's force inputs in training (learning.manipulator_data.with_force_inputs)
    filtered_prior: bool = True
    # the rigid-body model identified on the training split (learning.identify, without the
    # training noise) gives its force along the motion as two more inputs
    # (controllers.features.FORCE_INPUTS), computed from the filtered motion as the other
    # features are (and filtered as the labels are: filtered_prior), in the deployed
    # feedforward from the reference
    force_input: bool = False

    def __post_init__(self) -> None:
        if self.feature_set not in FEATURE_SETS:
            raise InputError(f"unknown feature set {self.feature_set!r}: choose one of "
                             f"{', '.join(FEATURE_SETS)}")
        if self.encoders not in (2, 3):
            raise InputError(f"encoders must be 2 or 3, got {self.encoders!r}")
        if not (self.cutoff_hz > 0 and self.filter_order >= 1):
            raise InputError("cutoff_hz must be positive and filter_order at least 1")
        if self.labels not in LABELS:
            raise InputError(f"unknown labels {self.labels!r}: choose one of "
                             f"{', '.join(LABELS)}")
        if min(self.position_noise_m, self.force_noise_n, self.current_noise_a) < 0:
            raise InputError("noise levels must not be negative")


def feature_record(config: FeatureConfig, edge_periods: float) -> dict[str, Any]:
    """The preprocessing `config` with the training's `edge_periods` (learning.presets) as
    run.json's config and identified.json record them: edge_periods after model_rate_hz."""
    settings = dataclasses.asdict(config)
    names = list(settings)
    place = names.index("model_rate_hz") + 1
    return {**{name: settings[name] for name in names[:place]}, "edge_periods": edge_periods,
            **{name: settings[name] for name in names[place:]}}


# each training preset's preprocessing (learning.presets.PRESETS): the fast one's networks
# run at 100 Hz
PRESET_FEATURES = {"thesis": FeatureConfig(), "fast": FeatureConfig(model_rate_hz=100.0)}


def quantize_encoders(theta: np.ndarray) -> np.ndarray:
    """Angles (n, 3) counted in whole encoder counts from the home angles (wrist at the centre),
    as the plant's encoders count; angles already on that grid are returned unchanged."""
    model = nominal_model()
    p = model.parameter_values()
    home = np.asarray(model.coordinates([0.0, 0.0], p), dtype=float).ravel()[list(SHOULDER_INDEX)]
    count = 2 * np.pi / model.variant.parameters.encoder_counts
    counts = np.floor((np.asarray(theta, dtype=float) - home) / count + 0.5)
    counted: np.ndarray = home + count * counts
    return counted


def encoder_positions(theta: np.ndarray, encoders: int = 2) -> np.ndarray:
    """Wrist positions (n, 2) from encoder angles (n, 3) by the nominal forward kinematics."""
    return evaluate_samples(_forward_kinematics(encoders),
                            np.asarray(theta, dtype=float)[:, :encoders])


@functools.cache
def _forward_kinematics(encoders: int) -> ca.Function:
    model = nominal_model()
    fk = model.fk2 if encoders == 2 else model.fk3
    symbol = ca.SX.sym("theta", encoders)
    return ca.Function(f"fk{encoders}", [symbol], [fk(symbol, model.parameter_values())])


def prepare_trajectory(traj: Trajectory, rate_hz: float, config: FeatureConfig,
                       rng: np.random.Generator | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Features (n, n_features) and labels (n, 2 forces or 3 currents: `config.labels`) at the
    model rate from a recorded trajectory.

    With `rng` (training trajectories only) white noise is added to positions and labels
    before filtering.
    """
    theta = np.column_stack([traj.signals[s] for s in ENCODER_SIGNALS])
    if config.quantize_encoders:
        theta = quantize_encoders(theta)
    pos = encoder_positions(theta, config.encoders)
    forces = np.column_stack([label_signal(traj, s) for s in LABELS[config.labels]])
    if rng is not None:
        noise = config.current_noise_a if config.labels == "currents" else config.force_noise_n
        pos = pos + config.position_noise_m * rng.standard_normal(pos.shape)
        forces = forces + noise * rng.standard_normal(forces.shape)
    pos = lowpass(pos, rate_hz, config.cutoff_hz, config.filter_order)
    forces = filter_labels(forces, rate_hz, config)
    vel, acc = differentiate(pos, rate_hz)
    step = decimation(rate_hz, config.model_rate_hz)
    features = motion_features(pos[::step], vel[::step], acc[::step], config.feature_set)
    return features, forces[::step]


def filter_labels(labels: np.ndarray, rate_hz: float, config: FeatureConfig) -> np.ndarray:
    """Labels (n, k) sampled at `rate_hz` through the filter `config` gives the labels (the
    motion's low-pass where `filter_forces`, else none): what a signal compared with the
    labels must pass through too."""
    if not config.filter_forces:
        return labels
    return lowpass(labels, rate_hz, config.cutoff_hz, config.filter_order)


def label_signal(traj: Trajectory, name: str) -> np.ndarray:
    """The label `name` of a trajectory; DatasetError if the dataset lacks it (a current
    before dataset version 3, or in imported logs)."""
    if name not in traj.signals:
        raise DatasetError(f"trajectory {traj.name!r} has no {name}: current-level labels need "
                           f"the motor currents of a set collected with this flexff (flexff "
                           f"data collect)")
    return traj.signals[name]
