"""Training configurations: the thesis's settings (`thesis`) and a CPU-friendly one (`fast`).

`thesis` takes the thesis's sizes, learning rates and epoch counts (sections 5.3-5.5): data at
its own rate, Adam at a constant 2e-5 for 1000 epochs (LSTM, CNN-LSTM) or 2e-4 for 1500 epochs
(TCN); the thesis does not give batch sizes, so Keras's default of 32 is used. It is meant for a
GPU.

`fast` trains the same kinds of network on a 2-core CPU in one to two minutes each, the four
models of an evaluation side by side (learning.workers). Each choice, and what it was measured
to do (closed-loop e2 ratio PID alone / feedforward, x / y, on the sim evaluation reference,
with a 0.03 m circle and a spline beside it as references nobody trained for; the slow demo
test, tests/flexff/test_cli.py, checks the outcome):

- 100 Hz model rate (sim; the hardware environment's slow data 25 Hz, learning.evaluate):
  the filtered data hold nothing above 5 Hz, and the feedforward FMU extrapolates linearly
  between calls, which costs 2e-4 N rms on the sim reference at 100 Hz and 9e-4 N at 50 Hz.
- Filter edges out of every loss (`edge_periods` = 2 corner periods at each end): the
  zero-phase filter's start and end transients made motion and force disagree by up to
  0.44 N where the rest of a trajectory agrees to 1e-4 N, and those few samples dominated the
  loss. LSTM alone: test MSE 4.6e-6 -> 2.5e-7, e2 68 / 91 -> 146 / 287.
- A linear skip (`linear_skip`, learning.models.LinearSkip): the full features' inverse
  dynamics is nearly linear, but their covariance spans 16 decades, and gradient descent does
  not reach in minutes what least squares solves at once. The skip starts from the
  least-squares fit and the network learns the rest. On the nominal sim plant the rest is
  small: the least-squares fit alone reaches a test MSE of 1.95e-8 and each network 1.96e-8
  to 2.01e-8, and the closed-loop figures of the LSTM and CNN-LSTM agree to three digits. On
  the hardware stand-in (friction, a tool mode, noisy encoders) the network part matters: on
  the 63 full features the linear fit alone gave e2 11 / 11 there, the TCN with it 31 / 38,
  the LSTM 27 / 31 (10 / 12 without the skip, after 60 epochs); with the motors' directions
  among the features, which let the linear fit hold the Coulomb friction, the TCN 132 / 63
  (wrist position from two encoders; learning.evaluate).
- Smaller recurrent networks (one LSTM layer of 64 instead of two of 100): 0.8 s per epoch
  against 2.3 s, and e2 68 / 91 against 48 / 56 after the same 120 epochs without skip.
- TCN of 4 levels of 64 channels, batches of 16 windows: 0.9 s per epoch (128 channels:
  2.3 s).
- Adam with a one-cycle schedule peaking at 3e-3 (1e-2 was worse: 34 / 61), early stopping on
  the validation loss (the best epoch is kept), batches of 4 trajectories for the recurrent
  networks: at 100 Hz an epoch holds few windows, and the number of updates limits the
  accuracy (all 44 trajectories per batch: 1.4 s per epoch and a validation loss 15 times
  higher after 100 epochs).

The pgnn is not in the thesis: a small TCN learning the residual over the rigid-body model.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field, replace
from typing import Any

from flexff.fmu.errors import InputError
from flexff.learning.features import FeatureConfig
from flexff.learning.models import check_kind

SCHEDULES = ("constant", "onecycle", "cosine")


@dataclass(frozen=True)
class TrainConfig:
    """Everything a training run needs besides the data; stored in run.json."""

    model: str
    preset: str
    features: FeatureConfig = field(default_factory=FeatureConfig)
    architecture: dict[str, Any] = field(default_factory=dict)
    epochs: int = 50
    learning_rate: float = 1e-3  # constant rate, or the peak of a schedule
    schedule: str = "onecycle"
    batch_size: int = 32  # trajectories (recurrent models) or windows (convolutional ones)
    window: int = 100  # TBPTT length, TCN output length and validation block length [samples]
    val_fraction: float = 0.125  # share of training windows held out for validation (seed)
    grad_clip: float = 1.0  # largest gradient norm; 0 switches clipping off
    seed: int = 0
    device: str = "auto"  # "auto": CUDA when available, else CPU
    threads: int = 0  # CPU threads; 0: half the cores granted, at least one (learning.threads)

    def __post_init__(self) -> None:
        check_kind(self.model)
        if self.schedule not in SCHEDULES:
            raise InputError(f"unknown schedule {self.schedule!r}: choose one of "
                             f"{', '.join(SCHEDULES)}")
        if self.epochs < 1 or self.batch_size < 1 or self.window < 1:
            raise InputError("epochs, batch_size and window must be at least 1")
        if not 0 < self.val_fraction < 1:
            raise InputError(f"val_fraction must lie between 0 and 1, got {self.val_fraction}")
        if not self.learning_rate > 0 or self.grad_clip < 0 or self.threads < 0:
            raise InputError("learning_rate must be positive, grad_clip and threads not negative")

    def to_dict(self) -> dict[str, Any]:
        return dataclasses.asdict(self)

    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> TrainConfig:
        data = dict(data)
        data["features"] = FeatureConfig(**data["features"])
        return cls(**data)


_LSTM = {"hidden": 100, "layers": 2, "dropout": 0.05}
_CNN_LSTM = {"conv_channels": [40, 16, 4], "conv_kernels": [10, 4, 2], **_LSTM}
_TCN = {"channels": 200, "levels": 6, "kernel": 3, "dropout": 0.05}
_PGNN = {"channels": 32, "levels": 4, "kernel": 3, "dropout": 0.05}
_FAST_LSTM = {**_LSTM, "hidden": 64, "layers": 1, "linear_skip": True}

PRESETS: dict[str, dict[str, dict[str, Any]]] = {
    "thesis": {
        "lstm": {"architecture": _LSTM, "epochs": 1000, "learning_rate": 2e-5,
                 "schedule": "constant"},
        "cnn-lstm": {"architecture": _CNN_LSTM, "epochs": 1000, "learning_rate": 2e-5,
                         "schedule": "constant"},
        "tcn": {"architecture": _TCN, "epochs": 1500, "learning_rate": 2e-4,
                "schedule": "constant"},
        "pgnn": {"architecture": {**_PGNN, "levels": 6}, "epochs": 1500, "learning_rate": 2e-4,
                     "schedule": "constant"},
    },
    "fast": {
        "lstm": {"architecture": _FAST_LSTM, "epochs": 60, "learning_rate": 3e-3, "batch_size": 4},
        "cnn-lstm": {"architecture": {**_CNN_LSTM, **_FAST_LSTM}, "epochs": 60,
                         "learning_rate": 3e-3, "batch_size": 4},
        "tcn": {"architecture": {**_TCN, "channels": 64, "levels": 4, "linear_skip": True},
                    "epochs": 120, "learning_rate": 3e-3, "batch_size": 16},
        "pgnn": {"architecture": _PGNN, "epochs": 60, "learning_rate": 3e-3, "batch_size": 32},
    },
}
_PRESET_FEATURES = {"thesis": FeatureConfig(),
                    "fast": FeatureConfig(model_rate_hz=100.0, edge_periods=2.0)}
# epochs between training checkpoints (learning.train): about a minute of work on the machine
# each preset is meant for; not a TrainConfig field, as it does not change the result
CHECKPOINT_EVERY = {"thesis": 10, "fast": 5}


def make_config(model: str, preset: str, **overrides: Any) -> TrainConfig:
    """The preset's configuration for `model`, with overrides by field name.

    An override may name a TrainConfig field (`epochs=5`), a FeatureConfig field
    (`feature_set="compact"`, `model_rate_hz=200`) or an architecture entry (`hidden=50`).
    """
    check_kind(model)
    if preset not in PRESETS:
        raise InputError(f"unknown preset {preset!r}: choose one of {', '.join(PRESETS)}")
    settings = dict(PRESETS[preset][model])
    settings["architecture"] = dict(settings["architecture"])
    features = _PRESET_FEATURES[preset]
    top = {f.name for f in dataclasses.fields(TrainConfig)} - {"model", "preset", "features",
                                                               "architecture"}
    feature_fields = {f.name for f in dataclasses.fields(FeatureConfig)}
    feature_overrides = {}
    for key, value in overrides.items():
        if key in top:
            settings[key] = value
        elif key in feature_fields:
            feature_overrides[key] = value
        elif key in settings["architecture"]:
            settings["architecture"][key] = value
        else:
            known = sorted(top | feature_fields | set(settings["architecture"]))
            raise InputError(f"unknown setting {key!r} for a {model} run; known: {known}")
    return TrainConfig(model=model, preset=preset, features=replace(features, **feature_overrides),
                       **settings)
