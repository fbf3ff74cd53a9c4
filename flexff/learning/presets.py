"""Training configurations: the thesis's settings (`thesis`) and a CPU-friendly one (`fast`).

`thesis` takes the thesis's sizes, learning rates and epoch counts (sections 5.3-5.5), with
Keras's default batch size; it is meant for a GPU. `fast` trains the same kinds of network on
a 2-core CPU in one to two minutes each: a 100 Hz model rate, filter edges left out of the
loss, a linear skip started at least squares, smaller networks, and Adam on a one-cycle
schedule with early stopping. The slow demo test checks the outcome.

Why each choice: "Learning", section The fast preset (docs/explanation/learning.md).
"""

from __future__ import annotations

import dataclasses
import json
from dataclasses import dataclass, field, replace
from typing import Any

from flexff.fmu.errors import InputError
from flexff.learning.features import FeatureConfig
from flexff.learning.models import check_kind, uses_prior

SCHEDULES = ("constant", "onecycle", "cosine")
# architecture entries that count (units, layers, channels, kernel taps): each at least 1
SIZES = ("hidden", "layers", "channels", "levels", "kernel", "conv_channels", "conv_kernels")
SEED_LIMIT = 2**63  # seeds below it (numpy's and torch's generators take them all)
# the settings that say where and how a run executes, not what it learns: runs that differ in
# them alone resume and reuse each other
PLACEMENT = ("device", "threads", "cuda_graphs")


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
    # on CUDA, each training step replayed from a CUDA graph (learning.training_step); off
    # by default: on an H200 its TCN trained otherwise than eager steps (docs/how-to/gpu.md)
    cuda_graphs: bool = False

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
        if not _whole(self.seed) or not 0 <= self.seed < SEED_LIMIT:
            raise InputError(f"seed must be a whole number from 0 to 2**63 - 1, got {self.seed!r}")
        for name in SIZES:
            value = self.architecture.get(name, 1)
            if not all(_whole(v) and v >= 1 for v in (value if isinstance(value, list | tuple)
                                                      else [value])):
                raise InputError(f"{name} must be at least 1 (whole numbers), got {value!r}")
        if not 0 <= self.architecture.get("dropout", 0) < 1:
            raise InputError(f"dropout must lie from 0 up to 1, got "
                             f"{self.architecture['dropout']!r}")

    def to_dict(self) -> dict[str, Any]:
        return dataclasses.asdict(self)

    def learned_settings(self) -> dict[str, Any]:
        """`to_dict` without the PLACEMENT settings, as JSON holds it."""
        settings = {k: v for k, v in self.to_dict().items() if k not in PLACEMENT}
        plain: dict[str, Any] = json.loads(json.dumps(settings))
        return plain

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


def _whole(value: object) -> bool:
    return isinstance(value, int) and not isinstance(value, bool)


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
    if uses_prior(model) and feature_overrides.get("force_input"):
        raise InputError(f"force_input is for the black-box networks: the {model} model has the "
                         f"identified rigid-body force as its prior already")
    return TrainConfig(model=model, preset=preset, features=replace(features, **feature_overrides),
                       **settings)
