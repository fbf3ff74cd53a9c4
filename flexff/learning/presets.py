"""Training configurations: the thesis's settings (`thesis`) and a CPU-friendly one (`fast`).

`thesis` takes the thesis's sizes, learning rates and epoch counts (sections 5.3-5.5), with
Keras's default batch size; it is meant for a GPU. `fast` trains the same kinds of network on
a 2-core CPU in one to two minutes each: filter edges left out of the loss (and the
manipulator's 100 Hz model rate, learning.features.PRESET_FEATURES), a linear skip started
at least squares, smaller networks, and Adam on a one-cycle schedule with early stopping.
The slow demo test checks the outcome.

Why each choice: "Learning", section The fast preset (docs/explanation/learning.md).
"""

from __future__ import annotations

import dataclasses
import json
import math
from collections.abc import Collection, Mapping
from dataclasses import dataclass, field
from typing import Any

from flexff.fmu.errors import InputError
from flexff.learning.models import check_kind

SCHEDULES = ("constant", "onecycle", "cosine")
# architecture entries that count (units, layers, channels, kernel taps): each at least 1
SIZES = ("hidden", "layers", "channels", "levels", "kernel", "conv_channels", "conv_kernels")
SEED_LIMIT = 2**63  # seeds below it (numpy's and torch's generators take them all)
# the settings that say where and how a run executes, not what it learns: runs that differ in
# them alone resume and reuse each other
PLACEMENT = ("device", "threads", "cuda_graphs")


@dataclass(frozen=True)
class TrainConfig:
    """Everything a training run needs besides the data and its preprocessing (the data
    source's own settings: learning.features.FeatureConfig, learning.machine_features);
    stored in run.json (`record`)."""

    model: str
    preset: str
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
    # periods of the data's low-pass corner at each end of a trajectory left out of every
    # loss (`edge_samples`); 0 as in the thesis
    edge_periods: float = 0.0

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
        if self.edge_periods < 0:
            raise InputError(f"edge_periods must not be negative, got {self.edge_periods}")
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

    def edge_samples(self, cutoff_hz: float, rate_hz: float) -> int:
        """The module's `edge_samples` of `edge_periods`."""
        return edge_samples(self.edge_periods, cutoff_hz, rate_hz)

    def record(self, features: Mapping[str, Any], learned: bool = False) -> dict[str, Any]:
        """The configuration as run.json's `config` holds it, as JSON data: `features` (the
        data source's preprocessing settings, edge_periods among them) after model and
        preset, then the other settings; the PLACEMENT settings left out where `learned`."""
        settings = dataclasses.asdict(self)
        del settings["edge_periods"]
        record = {"model": settings.pop("model"), "preset": settings.pop("preset"),
                  "features": dict(features), **settings}
        plain: dict[str, Any] = json.loads(json.dumps(
            {k: v for k, v in record.items() if not (learned and k in PLACEMENT)}))
        return plain

    @classmethod
    def from_record(cls, record: Mapping[str, Any]) -> TrainConfig:
        """The configuration of run.json's `config` record (its feature settings but
        edge_periods are the data source's)."""
        settings = {k: v for k, v in record.items() if k != "features"}
        return cls(**settings, edge_periods=record["features"]["edge_periods"])


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
        # the residual net sized, trained and started (its linear skip at least squares on
        # the residual) as the TCN: the rough drive (6 / 2 trajectories of 10 s), e2 3.16x
        # PID alone at 32 channels, 60 epochs, batches of 32, no skip (its best epoch the
        # last, test MSE 3.6e-3); 3.37x with the skip; 4.74x so (test MSE 3.0e-4)
        "pgnn": {"architecture": {**_PGNN, "channels": 64, "linear_skip": True}, "epochs": 120,
                 "learning_rate": 3e-3, "batch_size": 16},
    },
}
# filter edges left out of the loss (TrainConfig.edge_periods); the data source's own
# preprocessing has presets of its own (learning.features.PRESET_FEATURES)
_PRESET_EDGES = {"thesis": 0.0, "fast": 2.0}
# epochs between training checkpoints (learning.train): about a minute of work on the machine
# each preset is meant for; not a TrainConfig field, as it does not change the result
CHECKPOINT_EVERY = {"thesis": 10, "fast": 5}


def edge_samples(edge_periods: float, cutoff_hz: float, rate_hz: float) -> int:
    """Samples at `rate_hz` at each end of a trajectory where the zero-phase low-pass of
    corner `cutoff_hz` makes motion and force disagree: `edge_periods` periods of it.

    Measured on the manipulator's sim set (5 Hz corner), the force not explained by the
    rigid-body model of the filtered motion is 0.44 N rms at the first sample, 0.012 N after
    0.2 s, 4e-4 N after 0.4 s and about 1e-4 N after that; the last 0.2 s rise to 5e-3 N
    again. Those few samples dominated the training loss.
    """
    return math.ceil(edge_periods / cutoff_hz * rate_hz)


def _whole(value: object) -> bool:
    return isinstance(value, int) and not isinstance(value, bool)


def make_config(model: str, preset: str, source_settings: Collection[str] = (),
                **overrides: Any) -> TrainConfig:
    """The preset's configuration for `model`, with overrides by field name.

    An override may name a TrainConfig field (`epochs=5`) or an architecture entry
    (`hidden=50`); `source_settings`, the names of the data source's own settings (taken
    from the overrides before), are named among the known ones when an override is neither.
    """
    check_kind(model)
    if preset not in PRESETS:
        raise InputError(f"unknown preset {preset!r}: choose one of {', '.join(PRESETS)}")
    settings = {"edge_periods": _PRESET_EDGES[preset], **PRESETS[preset][model]}
    settings["architecture"] = dict(settings["architecture"])
    top = {f.name for f in dataclasses.fields(TrainConfig)} - {"model", "preset",
                                                               "architecture"}
    for key, value in overrides.items():
        if key in top:
            settings[key] = value
        elif key in settings["architecture"]:
            settings["architecture"][key] = value
        else:
            known = sorted(top | set(source_settings) | set(settings["architecture"]))
            raise InputError(f"unknown setting {key!r} for a {model} run; known: {known}")
    return TrainConfig(model=model, preset=preset, **settings)
