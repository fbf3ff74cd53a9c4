"""Training configurations: the seed's settings (`thesis`) and a CPU-friendly one (`fast`).

`thesis` takes the seed's sizes, learning rates and epoch counts (sections 5.3-5.5): data at
its own rate, Adam at a constant 2e-5 for 1000 epochs (LSTM, CNN-LSTM) or 2e-4 for 1500 epochs
(TCN); the seed does not give batch sizes, so Keras's default of 32 is used. It is meant for a
GPU.

`fast` trains the same kinds of network on a 2-core CPU in one to three minutes each: the
filtered data are down-sampled to 100 Hz (the 1.8 Hz low-pass already removed everything
above), so a window of 100 samples spans a second instead of 0.1 s; Adam runs a one-cycle
schedule peaking at 3e-3 (15 to 150 times the seed's rates) for 60 epochs (TCN 120); the
batches stay small (4 trajectories, 8 windows) because at 100 Hz an epoch holds few windows and
the number of updates, not of samples, limits the accuracy. The LSTM and CNN-LSTM keep the
seed's sizes. The TCN keeps kernel 3 but has 4 levels of 128 channels instead of 6 of 200: at
100 Hz four levels already see 31 samples, 0.31 s, more time than the seed's 127 samples at
1 kHz; the seed's size takes 4.5 times as long per epoch (7.3 s against 1.6 s on one core)
and was no more accurate after the same 40 epochs in a trial on synthetic data (test MSE
2.0e-5, as 128 channels in 6 levels). tests/test_learning_slow.py prints the measured numbers.

The pgnn is not in the seed: a small TCN learning the residual over the rigid-body model.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field, replace
from typing import Any

from learning.features import FeatureConfig
from learning.models import check_kind

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
            raise ValueError(f"unknown schedule {self.schedule!r}: choose one of "
                             f"{', '.join(SCHEDULES)}")
        if self.epochs < 1 or self.batch_size < 1 or self.window < 1:
            raise ValueError("epochs, batch_size and window must be at least 1")
        if not 0 < self.val_fraction < 1:
            raise ValueError(f"val_fraction must lie between 0 and 1, got {self.val_fraction}")
        if not self.learning_rate > 0 or self.grad_clip < 0 or self.threads < 0:
            raise ValueError("learning_rate must be positive, grad_clip and threads not negative")

    def to_dict(self) -> dict[str, Any]:
        return dataclasses.asdict(self)

    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> "TrainConfig":
        data = dict(data)
        data["features"] = FeatureConfig(**data["features"])
        return cls(**data)


_LSTM = {"hidden": 100, "layers": 2, "dropout": 0.05}
_CNN_LSTM = {"conv_channels": [40, 16, 4], "conv_kernels": [10, 4, 2], **_LSTM}
_TCN = {"channels": 200, "levels": 6, "kernel": 3, "dropout": 0.05}
_PGNN = {"channels": 32, "levels": 4, "kernel": 3, "dropout": 0.05}

PRESETS: dict[str, dict[str, dict[str, Any]]] = {
    "thesis": {
        "lstm": dict(architecture=_LSTM, epochs=1000, learning_rate=2e-5, schedule="constant"),
        "cnn-lstm": dict(architecture=_CNN_LSTM, epochs=1000, learning_rate=2e-5,
                         schedule="constant"),
        "tcn": dict(architecture=_TCN, epochs=1500, learning_rate=2e-4, schedule="constant"),
        "pgnn": dict(architecture={**_PGNN, "levels": 6}, epochs=1500, learning_rate=2e-4,
                     schedule="constant"),
    },
    "fast": {
        "lstm": dict(architecture=_LSTM, epochs=60, learning_rate=3e-3, batch_size=4),
        "cnn-lstm": dict(architecture=_CNN_LSTM, epochs=60, learning_rate=3e-3, batch_size=4),
        "tcn": dict(architecture={**_TCN, "channels": 128, "levels": 4}, epochs=120,
                    learning_rate=3e-3, batch_size=8),
        "pgnn": dict(architecture=_PGNN, epochs=60, learning_rate=3e-3, batch_size=32),
    },
}
_PRESET_FEATURES = {"thesis": FeatureConfig(), "fast": FeatureConfig(model_rate_hz=100.0)}
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
        raise ValueError(f"unknown preset {preset!r}: choose one of {', '.join(PRESETS)}")
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
            raise ValueError(f"unknown setting {key!r} for a {model} run; known: {known}")
    return TrainConfig(model=model, preset=preset, features=replace(features, **feature_overrides),
                       **settings)
