"""A training run on disk: `run.json` (everything needed to rebuild) and `model.pt` (weights).

run.json holds the training configuration, the feature and label names, the model's sample
rate, the min-max scalers fitted on the training data and where the data came from; with the
weights that is enough to rebuild the network and run it in SI units (`learning.deploy`).
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from importlib import metadata
from pathlib import Path
from typing import Any

import torch

from learning.models import SequenceNetwork, build_network
from learning.presets import TrainConfig
from learning.scaling import MinMaxScaler

FORMAT = "flexff-run"
VERSION = 1
RUN_FILE = "run.json"
WEIGHTS_FILE = "model.pt"


def flexff_version() -> str:
    """The installed flexff distribution's version ('unknown' when run from a bare checkout)."""
    try:
        return metadata.version("flexff")
    except metadata.PackageNotFoundError:
        return "unknown"


@dataclass(frozen=True)
class Run:
    """A rebuilt training run: configuration, trained network (eval mode, CPU) and scalers."""

    path: Path
    config: TrainConfig
    network: SequenceNetwork
    feature_scaler: MinMaxScaler
    label_scaler: MinMaxScaler
    feature_names: list[str]
    model_rate_hz: float
    info: dict[str, Any]


def save_run(out: Path, config: TrainConfig, network: SequenceNetwork,
             feature_scaler: MinMaxScaler, label_scaler: MinMaxScaler, feature_names: list[str],
             model_rate_hz: float, extra: dict[str, Any]) -> None:
    """Write run.json and model.pt into `out`."""
    out.mkdir(parents=True, exist_ok=True)
    torch.save({k: v.detach().cpu() for k, v in network.state_dict().items()}, out / WEIGHTS_FILE)
    info = {"format": FORMAT, "version": VERSION, "flexff_version": flexff_version(),
            "config": config.to_dict(), "feature_names": feature_names,
            "label_names": ["Fx", "Fy"], "model_rate_hz": model_rate_hz,
            "scalers": {"features": feature_scaler.to_dict(), "labels": label_scaler.to_dict()},
            "history": network.history,
            "state": [{"name": n, "shape": list(s)}
                      for n, s in zip(network.state_names(), network.state_shapes(1))],
            **extra}
    (out / RUN_FILE).write_text(json.dumps(info, indent=2) + "\n")


def load_run(path: str | Path) -> Run:
    """Rebuild a run folder written by `learning.train.train`."""
    path = Path(path)
    if not (path / RUN_FILE).is_file() or not (path / WEIGHTS_FILE).is_file():
        raise FileNotFoundError(f"{path} is not a training run folder ({RUN_FILE} and "
                                f"{WEIGHTS_FILE} expected): train one with learning.train.train")
    info = json.loads((path / RUN_FILE).read_text())
    if info.get("format") != FORMAT or info.get("version") != VERSION:
        raise ValueError(f"{path / RUN_FILE}: format {info.get('format')!r} version "
                         f"{info.get('version')!r}, expected {FORMAT!r} version {VERSION}: "
                         f"train the model again with this flexff version")
    config = TrainConfig.from_dict(info["config"])
    network = build_network(config.model, len(info["feature_names"]), **config.architecture)
    network.load_state_dict(torch.load(path / WEIGHTS_FILE, map_location="cpu", weights_only=True))
    network.eval()
    return Run(path=path, config=config, network=network,
               feature_scaler=MinMaxScaler.from_dict(info["scalers"]["features"]),
               label_scaler=MinMaxScaler.from_dict(info["scalers"]["labels"]),
               feature_names=info["feature_names"], model_rate_hz=info["model_rate_hz"], info=info)
